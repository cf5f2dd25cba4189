"""Where the estimate's GP should run: the same BO search with its GP on the CPU
and on JAX's default device (a GPU), side by side in one process.

Times every ``Minimizer.ask`` (GP fit + q-point proposal) of a short search on a
cheap quadratic, and the final ``minimizer_samples`` (the estimate's
uncertainty), twice per device: the first pays the compiles.

  python -m benchmarks.gp_placement --out=out/gp_placement.json
"""

from __future__ import annotations

import dataclasses
import json
import time

import jax
import numpy as np

import bo
from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The GP placement benchmark.

  Attributes:
    q: points per proposal (the estimate default).
    n_init: initial design.
    n_iter: proposals.
    out: JSON result.
  """

  q: int = 4
  n_init: int = 8
  n_iter: int = 6
  out: str = 'out/benchmarks/gp_placement.json'


PRESETS = {'default': Args(), 'smoke': Args(n_init=4, n_iter=2)}

BOUNDS = np.array([[-1.0, 1.0]] * 3)


def _search(args: Args, device, seed: int) -> dict:
  opt = bo.Minimizer(
    BOUNDS, n_init=args.n_init, n_iter=args.n_iter, q=args.q, seed=seed,
    device=device, stop_rel_change=None,
  )  # fmt: skip
  state, ask_s = opt.start(), 0.0
  while not opt.done(state):
    t = time.perf_counter()
    x, state = opt.ask(state)
    ask_s += time.perf_counter() - t
    state = opt.tell(state, x, np.sum((np.asarray(x) - 0.3) ** 2, axis=1))
  t = time.perf_counter()
  with jax.default_device(device or jax.devices()[0]):
    bo.minimizer_samples(state.X, state.Y, BOUNDS, jax.random.key(seed))
  return {'ask_s': ask_s, 'samples_s': time.perf_counter() - t}


def main(args: Args) -> None:
  rows = []
  for name, device in (('cpu', jax.devices('cpu')[0]), ('default', None)):
    for run in range(2):
      row = {'gp_device': name, 'run': run, **_search(args, device, run)}
      row['device'] = str(device or jax.devices()[0])
      rows.append(row)
      print(json.dumps(row), flush=True)
  print('| GP on | device | run | asks s (all proposals) | minimizer_samples s |')
  print('|---|---|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["gp_device"]} | {r["device"]} | {r["run"]} | {r["ask_s"]:.2f} | '
      f'{r["samples_s"]:.2f} |'
    )
  files.write_json(
    args.out,
    {'q': args.q, 'n_init': args.n_init, 'n_iter': args.n_iter, 'rows': rows},
  )
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
