"""MuJoCo C on several cores: the rollout's worker threads against worker processes.

``physsim.rollout`` runs the C backend's worlds in threads (MuJoCo releases
the GIL while it steps), so that a library user's plain script needs no
``__main__`` guard. This measures what that costs against the processes it
replaced, side by side in one run on the same worlds: threads through the real
path (``simulate(backend='c', workers=N)``), processes as spawned workers each
simulating its share of the worlds with one thread. Prints a table and writes
JSON.

  python -m benchmarks.c_threads --out=out/benchmarks/c_threads.json
  python -m benchmarks.c_threads --preset=smoke
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import multiprocessing
import os
import time

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, files
from physsim import rollout as sim


@dataclasses.dataclass(frozen=True)
class Args:
  """Threads against processes for the C backend.

  Attributes:
    workers: threads (or processes) per run, comma-separated (0: all cores).
    worlds: worlds simulated per run (split over the workers).
    cloth_resolution: vertices a side.
    seconds: simulated seconds per world (at 20 frames/s, no warm-up).
    repeats: timed runs of each, after one untimed run (the best is kept).
    out: JSON path.
  """

  workers: str = '1,2,0'
  worlds: int = 8
  cloth_resolution: int = 25
  seconds: float = 1.0
  repeats: int = 2
  out: str = 'out/benchmarks/c_threads.json'


PRESETS = {
  'default': Args(),
  'smoke': Args(workers='1,2', worlds=2, cloth_resolution=6, seconds=0.1, repeats=1),
}


def _worker_counts(text: str) -> list[int]:
  try:
    counts = [int(x) or (os.cpu_count() or 1) for x in text.split(',')]
  except ValueError:
    counts = []
  if not counts or min(counts) < 1:
    raise ValueError(f'--workers={text}: need comma-separated counts >= 0')
  return counts


def _params(n: int):
  rng = np.random.default_rng(0)
  return physsim.params.sample(rng, n, physsim.search_space('gray_interlock'))


def _simulate(model, p, frames, workers):
  return sim.simulate(
    model, p, frames=frames, fps=20.0, warmup=0.0, backend='c', workers=workers,
    wind=physsim.Wind(gust_intensity=0.2), key=jax.random.key(1),
  )  # fmt: skip


def _process_share(job):
  """One worker process: its share of the worlds, on one thread."""
  resolution, indices, n, frames = job
  model = physsim.build(physsim.square(resolution), 'gray_interlock')
  p = jax.tree.map(lambda a: np.asarray(a)[indices], _params(n))
  keys = jax.random.split(jax.random.key(1), n)[np.asarray(indices)]
  out = sim.simulate(
    model, p, frames=frames, fps=20.0, warmup=0.0, backend='c', workers=1,
    wind=physsim.Wind(gust_intensity=0.2), key=keys,
  )  # fmt: skip
  return indices, out.positions


def _best(fn, repeats: int) -> float:
  fn()  # start-up: thread copies, process interpreters
  times = []
  for _ in range(repeats):
    t0 = time.perf_counter()
    fn()
    times.append(time.perf_counter() - t0)
  return min(times)


def main(args: Args) -> None:
  counts = _worker_counts(args.workers)
  if args.worlds < 1 or args.repeats < 1 or not args.seconds > 0:
    raise ValueError('need --worlds >= 1, --repeats >= 1 and --seconds > 0')
  frames = max(1, round(args.seconds * 20))
  model = physsim.build(physsim.square(args.cloth_resolution), 'gray_interlock')
  p = _params(args.worlds)
  substeps = round(0.05 / model.config.timestep)
  steps = args.worlds * frames * substeps
  reference = _simulate(model, p, frames, 1).positions
  rows = []
  for n in counts:
    threads = _best(lambda n=n: _simulate(model, p, frames, n), args.repeats)
    shares = [list(range(i, args.worlds, n)) for i in range(min(n, args.worlds))]
    ctx = multiprocessing.get_context('spawn')
    with (
      sim.cpu_only_children(),
      concurrent.futures.ProcessPoolExecutor(len(shares), mp_context=ctx) as pool,
    ):
      jobs = [(args.cloth_resolution, s, args.worlds, frames) for s in shares]
      run = lambda pool=pool, jobs=jobs: list(pool.map(_process_share, jobs))
      procs = _best(run, args.repeats)
      gathered = np.empty_like(reference)
      for indices, pos in run():
        gathered[indices] = pos
    rows.append({
      'workers': n,
      'threads_s': threads,
      'processes_s': procs,
      'threads_world_steps_per_s': steps / threads,
      'processes_world_steps_per_s': steps / procs,
      'threads_over_processes': procs / threads,
      'same_positions': bool(np.array_equal(gathered, reference)),
    })  # fmt: skip
  result = {'config': dataclasses.asdict(args), 'cores': os.cpu_count(), 'rows': rows}
  files.write_json(args.out, result)
  print(f'{args.worlds} worlds, {args.cloth_resolution}x{args.cloth_resolution}, '
        f'{frames} frames, {os.cpu_count()} cores')  # fmt: skip
  print('| workers | threads (s) | processes (s) | threads speed / processes | same |')
  print('|---|---|---|---|---|')
  for r in rows:
    print(
      f'| {r["workers"]} | {r["threads_s"]:.2f} | {r["processes_s"]:.2f} | '
      f'{r["threads_over_processes"]:.2f} | {r["same_positions"]} |'
    )
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
