"""Is a simulated batch the same to the bit when it is run again?

MuJoCo Warp sums forces and constraint rows with atomics, whose order a GPU
does not fix: two runs of one sweep on one H200, same inputs and keys, gave
recordings 43 mm of mean depth apart (docs/scaling.md). Warp has an opt-in
deterministic mode for its atomics (``wp.config.deterministic``), which must be
set before MuJoCo Warp's kernels are built; with MuJoCo Warp 4.0 (warp-lang
1.19) it refuses to build one of them (``_qLD_acc`` reads an array it updates
atomically: benchmarks/results/warp_determinism_h200/det.log), so on a GPU
recordings are reproducible in distribution only. This runs one batch of the
evaluation recipe's sheet (33 x 33 vertices, 1/480 s, 30% gusts, 60 frames at
24 fps after a 1 s warm-up) ``--repeats`` times in one process, with the mode
given, and reports whether the runs agree to the bit, how far apart they end,
and what a run costs. Prints a table and writes JSON.

  # GPU; one process per mode, each with its own kernel cache (a kernel built
  # without the mode must not be reused with it):
  XDG_CACHE_HOME=/tmp/c_off python -m benchmarks.warp_determinism --mode=off
  XDG_CACHE_HOME=/tmp/c_det python -m benchmarks.warp_determinism --mode=run_to_run
  python -m benchmarks.warp_determinism --preset=smoke   # CPU, MuJoCo C: the plumbing
"""

from __future__ import annotations

import dataclasses
import sys
import time

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, files

MODES = ('off', 'run_to_run')


@dataclasses.dataclass(frozen=True)
class Args:
  """One batch, simulated again and again.

  Attributes:
    mode: Warp's atomics: 'off' (its default, not guaranteed) or
      'run_to_run' (``wp.DeterministicMode.RUN_TO_RUN``).
    backend: 'warp' (the question), or 'c' (MuJoCo C, deterministic: a
      check of this script).
    worlds: worlds in the batch.
    cloth_resolution: vertices a side.
    frames: recorded frames.
    fps: frame rate, Hz.
    timestep: simulation step, seconds.
    warmup: seconds simulated before the first frame.
    gust_intensity: RMS relative wind fluctuation.
    repeats: runs of the batch (the first compiles).
    out: JSON path.
  """

  mode: str = cli.choice('off', MODES)
  backend: str = cli.choice('warp', ('warp', 'c'))
  worlds: int = 32
  cloth_resolution: int = 33
  frames: int = 60
  fps: float = 24.0
  timestep: float = 1 / 480
  warmup: float = 1.0
  gust_intensity: float = 0.3
  repeats: int = 3
  out: str = 'out/benchmarks/warp_determinism.json'


PRESETS = {
  'default': Args(),
  'smoke': Args(
    backend='c',
    worlds=2,
    cloth_resolution=6,
    frames=3,
    fps=20.0,
    timestep=0.002,
    warmup=0.1,
    repeats=2,
  ),  # fmt: skip
}


def set_mode(mode: str) -> None:
  """Warp's atomics for kernels built from now on; refused once MuJoCo Warp's
  modules are loaded (their kernels would keep the mode they were built in)."""
  loaded = [m for m in sys.modules if m.endswith('mujoco_warp') or '.mujoco_warp.' in m]
  if loaded:
    raise ValueError(f'--mode={mode}: MuJoCo Warp is already imported ({loaded[0]})')
  import warp as wp

  wp.config.deterministic = (
    wp.DeterministicMode.RUN_TO_RUN
    if mode == 'run_to_run'
    else wp.DeterministicMode.NOT_GUARANTEED
  )


def _refusal(message: str) -> str:
  """The kernel Warp's deterministic mode refused, and why, from its error."""
  text = ' '.join(message.split())
  start = text.find('Error while parsing function')
  end = text.find('Fix:', start)
  return (
    text[start : end if end > 0 else start + 400].strip() if start >= 0 else text[:400]
  )


def main(args: Args) -> None:
  if args.worlds < 1 or args.repeats < 2 or args.frames < 1:
    raise ValueError('need --worlds >= 1, --frames >= 1 and --repeats >= 2')
  if args.backend == 'c' and args.mode != 'off':
    raise ValueError(
      f'--mode={args.mode} is a mode of Warp: give it with --backend=warp'
    )
  if args.backend == 'warp':
    set_mode(args.mode)
  mesh = physsim.square(args.cloth_resolution)
  physics = physsim.MISMATCHES['own']
  config = physsim.config_for_mesh(
    mesh, args.fps, args.timestep, scaled_edges=True, **physics.sim_fields()
  )
  model = physsim.build(mesh, 'gray_interlock', config)
  space = physsim.search_space('gray_interlock')
  p = physsim.params.sample(np.random.default_rng(0), args.worlds, space)
  runs, seconds = [], []
  for _ in range(args.repeats):
    t0 = time.perf_counter()
    try:
      out = physsim.simulate(
        model, p, frames=args.frames, fps=args.fps, warmup=args.warmup,
        wind=physics.wind(args.gust_intensity), key=jax.random.key(1),
        backend=args.backend,
      )  # fmt: skip
    except Exception as e:  # noqa: BLE001 - only Warp's refusal is a result
      if 'WarpDeterminismError' not in str(e):
        raise
      refused = _refusal(str(e))
      files.write_json(
        args.out, {'config': dataclasses.asdict(args), 'refused': refused}
      )
      print(f"--mode={args.mode}: Warp's deterministic mode cannot build MuJoCo "
            f'Warp: {refused} (wrote {args.out})')  # fmt: skip
      return
    seconds.append(time.perf_counter() - t0)
    runs.append(out)
  first = runs[0]
  apart = [float(np.abs(r.positions - first.positions).max()) for r in runs[1:]]
  end_apart = [
    float(np.linalg.norm(r.positions[:, -1] - first.positions[:, -1], axis=-1).mean())
    for r in runs[1:]
  ]
  result = {
    'config': dataclasses.asdict(args),
    'device': jax.devices()[0].device_kind,
    'identical': all(np.array_equal(r.positions, first.positions) for r in runs[1:]),
    'max_apart_m': max(apart),
    'mean_last_frame_apart_m': max(end_apart),
    'valid': int(first.valid.sum()),
    'seconds': seconds,
    'world_frames_per_s_after_first': (
      args.worlds * args.frames * (args.repeats - 1) / sum(seconds[1:])
    ),
  }
  files.write_json(args.out, result)
  print(f'{args.worlds} worlds, {args.cloth_resolution}x{args.cloth_resolution}, '
        f'{args.frames} frames, {args.backend} on {result["device"]}')  # fmt: skip
  print(
    '| mode | identical | max apart (mm) | last frame, mean (mm) | first run (s) | later (s) |'
  )
  print('|---|---|---|---|---|---|')
  print(
    f'| {args.mode} | {result["identical"]} | {1000 * result["max_apart_m"]:.3g} | '
    f'{1000 * result["mean_last_frame_apart_m"]:.3g} | {seconds[0]:.1f} | '
    f'{np.mean(seconds[1:]):.2f} |'
  )
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
