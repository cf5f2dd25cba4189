"""Training-input loading, side by side: how depth maps to inputs, and threads.

``experiments.train.load_inputs`` reads a fabric's PNG frames and maps them to
network inputs before a run trains; on the GPU machines this ran on one core
while the GPU waited. Times it for every ``--mappings`` x ``--workers`` variant:
``jax`` maps each sequence's depth with jax.numpy on JAX's default device (as
before 2026-11-21), ``numpy`` with NumPy on the host (now). Variants take
turns (after one untimed warm-up read, so every timed read finds the files in
the page cache), ``--repeats`` times; the table shows the medians and the
speed-up over the first variant.

  python -m benchmarks.load_inputs --dataset=data/sim --materials=gray_interlock
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax.numpy as jnp
import numpy as np

import model as model_lib
from experiments.pipeline import cli, embedding, files
from experiments.pipeline import training as train_lib

MAPPINGS = ('jax', 'numpy')


@dataclasses.dataclass(frozen=True)
class Args:
  """The input-loading benchmark.

  Attributes:
    dataset: dataset root (generate_dataset --out; required).
    materials: materials to read.
    workers: thread counts.
    mappings: depth mapping backends (jax, numpy).
    network: frames or clips.
    modality: depth or rgb.
    repeats: timed reads per thread count.
    out: JSON result.
  """

  dataset: str = cli.required()
  materials: tuple[str, ...] = ('gray_interlock',)
  workers: tuple[int, ...] = (1, min(16, os.cpu_count() or 1))
  mappings: tuple[str, ...] = MAPPINGS
  network: str = cli.choice('physnet', ['physnet', 'sdn'])
  modality: str = cli.choice('depth', embedding.MODALITIES)
  repeats: int = 3
  out: str = 'out/benchmarks/load_inputs.json'


PRESETS = {'default': Args(), 'smoke': Args(repeats=1)}


_HOST_MAPPING = model_lib.depth_input


def _via_jax(depth, mode='relative'):
  return np.asarray(_HOST_MAPPING(jnp.asarray(depth), mode))


def _read(args: Args, cfg, mapping: str, workers: int) -> float:
  model_lib.depth_input = _via_jax if mapping == 'jax' else _HOST_MAPPING
  try:
    t0 = time.perf_counter()
    train_lib.load_inputs(cfg, args.dataset, args.materials, workers=workers)
    return time.perf_counter() - t0
  finally:
    model_lib.depth_input = _HOST_MAPPING


def main(args: Args) -> None:
  bad = [m for m in args.mappings if m not in MAPPINGS]
  if bad or not args.mappings:
    raise ValueError(f'--mappings={",".join(args.mappings)}: need some of {MAPPINGS}')
  if not args.workers or min(args.workers) < 1:
    raise ValueError(f'--workers={",".join(map(str, args.workers))}: need positive')
  cfg = dataclasses.replace(
    train_lib.PRESETS['paper'], network=args.network, modality=args.modality
  )
  x, _, _ = train_lib.load_inputs(cfg, args.dataset, args.materials)  # warm-up
  variants = [(m, int(w)) for m in args.mappings for w in args.workers]
  # jax with a pool is not a variant worth its time: one per mapping is enough
  variants = [v for v in variants if v[0] != 'jax' or v[1] == variants[0][1]]
  times = {v: [] for v in variants}
  for _ in range(args.repeats):  # interleaved, so drift hits every variant alike
    for v in variants:
      times[v].append(_read(args, cfg, *v))
  base = float(np.median(times[variants[0]]))
  rows = [
    {
      'mapping': m,
      'workers': w,
      'seconds_median': float(np.median(t)),
      'seconds': t,
      'items_per_s': len(x) / float(np.median(t)),
      'speedup': base / float(np.median(t)),
    }
    for (m, w), t in times.items()
  ]
  print(f'{len(x)} items of shape {x.shape[1:]}, {os.cpu_count()} cores')
  print('| depth mapping | workers | seconds (median) | items/s | speed-up |')
  print('|---|---:|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["mapping"]} | {r["workers"]} | {r["seconds_median"]:.2f} | '
      f'{r["items_per_s"]:.0f} | {r["speedup"]:.2f}x |'
    )
  files.write_json(
    args.out,
    {'dataset': args.dataset, 'materials': list(args.materials), 'items': len(x),
     'item_shape': list(x.shape[1:]), 'cores': os.cpu_count(), 'rows': rows},
  )  # fmt: skip
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
