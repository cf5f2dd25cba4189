"""One recording's estimate time after compile, for a few settings.

Each setting runs the same estimate 1 + ``--repeats`` times in one process: the
first pays the compiles (MJX, renderer, network, GP buffers), the others are
timed (the table shows their median run; all are in the JSON). Searches are
not bitwise repeatable on a GPU, so runs of one setting may differ in length.
Prints a table and writes JSON.

  python benchmarks/estimate_latency.py --recording=/tmp/eval/fabrics/gray_interlock/0000 \
      --material=gray_interlock --model=/tmp/t1/physnet_depth/simulation/gray_interlock \
      --out=out/estimate_latency.json
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import time

from absl import app, flags, logging

from experiments import estimate as est
from experiments import files

# name -> (EstimateConfig overrides, estimate() keywords); names without
# commas, as --settings is a list.
SETTINGS = {
  'default': ({}, {}),  # q=4, n_init=8, GP on the CPU
  'gp_on_gpu': ({}, dict(gp_on_cpu=False)),  # the GP on JAX's default device
  'q8_init8': (dict(q=8, n_init=8), {}),  # the design in one batch
  'q8': (dict(q=8, n_init=16), {}),
  'warmup0.5': (dict(warmup=0.5), {}),
  'q8_warmup0.5': (dict(q=8, n_init=16, warmup=0.5), {}),
}

FLAGS = flags.FLAGS
flags.DEFINE_string('recording', None, 'a dataset sequence folder')
flags.DEFINE_string('material', 'gray_interlock', 'its fabric')
flags.DEFINE_string('model', None, 'its trained network')
flags.DEFINE_string('out', 'out/estimate_latency.json', 'JSON result')
flags.DEFINE_list('settings', list(SETTINGS), 'which settings')
flags.DEFINE_enum('preset', 'default', list(est.PRESETS), 'base estimate settings')
flags.DEFINE_string('backend', 'auto', "'auto', 'mjx' or 'c'")
flags.DEFINE_integer(
  'repeats',
  1,
  'timed runs after the compile run (the table shows their median; a '
  "timed run can still compile shapes the first run's search did not reach)",
)


def main(argv):
  del argv
  logging.set_verbosity(logging.WARNING)  # orbax logs every checkpoint at INFO
  net = est.load_embedding(FLAGS.model)
  rows = []
  unknown = sorted(set(FLAGS.settings) - set(SETTINGS))
  if unknown:
    raise app.UsageError(f'unknown --settings {unknown}; known: {list(SETTINGS)}')
  for name in FLAGS.settings:
    overrides, kwargs = SETTINGS[name]
    config = dataclasses.replace(
      est.PRESETS[FLAGS.preset], material=FLAGS.material, backend=FLAGS.backend,
      **overrides,
    )  # fmt: skip
    rec = est.load_recording(
      FLAGS.recording, fps=config.fps, size=net.image_size, frames=config.frames,
      rgb=net.modality == 'rgb',
    )  # fmt: skip
    runs = []
    for _ in range(1 + FLAGS.repeats):  # the first run compiles
      with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r = est.estimate(config, rec, FLAGS.model, tmp, progress=False, **kwargs)
        runs.append({
          'seconds': time.perf_counter() - t0,
          'objective_s': r['seconds_in_objective'],
          'evaluations': r['evaluations'],
          'iterations': r['iterations'],
          'errors': r.get('errors', {}).get('estimate'),
        })  # fmt: skip
    timed = sorted(runs[1:], key=lambda x: x['seconds'])
    median = timed[(len(timed) - 1) // 2]  # a run that happened (lower median)
    row = {
      'setting': name,
      'overrides': {**overrides, **kwargs},
      'first_s': runs[0]['seconds'],
      'after_compile_s': median['seconds'],
      'objective_s': median['objective_s'],
      'evaluations': median['evaluations'],
      'iterations': median['iterations'],
      'errors': median['errors'],
      'timed_runs': runs[1:],
    }
    rows.append(row)
    print(json.dumps(row), flush=True)
  base = rows[0]['after_compile_s']
  print(
    f'| setting | first run s | after compile s | vs {rows[0]["setting"]} | '
    'in objective s | outside s | evals | iterations |'
  )
  print('|---|---:|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    t = r['after_compile_s']
    print(
      f'| {r["setting"]} | {r["first_s"]:.1f} | {t:.1f} | {t / base:.2f}x | '
      f'{r["objective_s"]:.1f} | {t - r["objective_s"]:.1f} | {r["evaluations"]} | '
      f'{r["iterations"]} |'
    )
  os.makedirs(os.path.dirname(os.path.abspath(FLAGS.out)), exist_ok=True)
  files.write_json(
    FLAGS.out,
    {'recording': FLAGS.recording, 'preset': FLAGS.preset, 'backend': FLAGS.backend,
     'rows': rows},
  )  # fmt: skip


if __name__ == '__main__':
  flags.mark_flags_as_required(['recording', 'model'])
  app.run(main)
