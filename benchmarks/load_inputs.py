"""Training-input loading, side by side: how depth maps to inputs, and threads.

``experiments.train.load_inputs`` reads a fabric's PNG frames and maps them to
network inputs before a run trains; on the GPU machines this ran on one core
while the GPU waited. Times it for every ``--mappings`` x ``--workers`` variant:
``jax`` maps each sequence's depth with jax.numpy on JAX's default device (as
before 2026-11-21), ``numpy`` with NumPy on the host (now). Variants take
turns (after one untimed warm-up read, so every timed read finds the files in
the page cache), ``--repeats`` times; the table shows the medians and the
speed-up over the first variant.

  python benchmarks/load_inputs.py --dataset=data/sim --materials=gray_interlock
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax.numpy as jnp
import numpy as np
from absl import app, flags

import model as model_lib
from experiments.pipeline import embedding, files
from experiments.pipeline import training as train_lib

FLAGS = flags.FLAGS
flags.DEFINE_string('dataset', None, 'dataset root (generate_dataset --out)')
flags.DEFINE_list('materials', ['gray_interlock'], 'materials to read')
flags.DEFINE_list('workers', ['1', str(min(16, os.cpu_count() or 1))], 'thread counts')
flags.DEFINE_list('mappings', ['jax', 'numpy'], 'depth mapping backends')
flags.DEFINE_enum('network', 'physnet', ['physnet', 'sdn'], 'frames or clips')
flags.DEFINE_enum('modality', 'depth', list(embedding.MODALITIES), 'depth or rgb')
flags.DEFINE_integer('repeats', 3, 'timed reads per thread count')
flags.DEFINE_string('out', 'out/load_inputs.json', 'JSON result')


_HOST_MAPPING = model_lib.depth_input


def _via_jax(depth, mode='relative'):
  return np.asarray(_HOST_MAPPING(jnp.asarray(depth), mode))


def _read(cfg, mapping: str, workers: int) -> float:
  model_lib.depth_input = _via_jax if mapping == 'jax' else _HOST_MAPPING
  try:
    t0 = time.perf_counter()
    train_lib.load_inputs(cfg, FLAGS.dataset, FLAGS.materials, workers=workers)
    return time.perf_counter() - t0
  finally:
    model_lib.depth_input = _HOST_MAPPING


def main(argv):
  del argv
  cfg = dataclasses.replace(
    train_lib.PRESETS['paper'], network=FLAGS.network, modality=FLAGS.modality
  )
  x, _, _ = train_lib.load_inputs(cfg, FLAGS.dataset, FLAGS.materials)  # warm-up
  variants = [(m, int(w)) for m in FLAGS.mappings for w in FLAGS.workers]
  # jax with a pool is not a variant worth its time: one per mapping is enough
  variants = [v for v in variants if v[0] != 'jax' or v[1] == variants[0][1]]
  times = {v: [] for v in variants}
  for _ in range(FLAGS.repeats):  # interleaved, so drift hits every variant alike
    for v in variants:
      times[v].append(_read(cfg, *v))
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
    FLAGS.out,
    {'dataset': FLAGS.dataset, 'materials': FLAGS.materials, 'items': len(x),
     'item_shape': list(x.shape[1:]), 'cores': os.cpu_count(), 'rows': rows},
  )  # fmt: skip


if __name__ == '__main__':
  flags.mark_flags_as_required(['dataset'])
  app.run(main)
