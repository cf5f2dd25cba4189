"""Which fan settings measure area weight: one-recording errors split by wind.

Reads the ``joint_pairs.json`` files of ``benchmarks/joint_pairs.py`` and
prints, for the recordings whose anemometer reading is at most ``--split``
m/s and for the rest, the mean error (with its standard error) of area weight
and of the load ratio from one recording and its reading, beside the range
centre's area-weight error on the same recordings; the same split by the
true load ratio (``--ratio_split``). The reading is what a user sees when
choosing a setting; the load ratio is what the physics cares about (the sheet
blows flat at high ratios and its mean shape stops following the ratio:
``benchmarks/gust_floor.py``). No simulation: seconds on a CPU.

  python benchmarks/fan_settings.py \\
      --results=benchmarks/results/matched_synthetic_h100/joint_3_shape_synthetic_g0.3_c33.json
"""

from __future__ import annotations

import json

import numpy as np
from absl import app, flags

from experiments.pipeline import files

FLAGS = flags.FLAGS


def strata(rows: list[dict], split: float, ratio_split: float) -> dict:
  """Per stratum: n, and mean and standard error of each one-recording error."""
  reading = np.array([r['reading'][0] for r in rows])
  ratio = np.array([r['truth']['load_ratio'] for r in rows])
  masks = {
    f'reading <= {split:g} m/s': reading <= split,
    f'reading > {split:g} m/s': reading > split,
    f'load ratio <= {ratio_split:g}': ratio <= ratio_split,
    f'load ratio > {ratio_split:g}': ratio > ratio_split,
  }
  cols = {
    'area_weight': [r['alone']['area_weight'] for r in rows],
    'load_ratio': [r['alone']['load_ratio'] for r in rows],
    'centre_area_weight': [r['centre']['area_weight'] for r in rows],
  }
  out = {}
  for name, m in masks.items():
    n = int(m.sum())
    s = {'n': n}
    for col, values in cols.items():
      v = np.asarray(values)[m]
      s[col] = float(v.mean()) if n else float('nan')
      s[f'{col}_se'] = float(v.std(ddof=1) / np.sqrt(n)) if n > 1 else float('nan')
    out[name] = s
  return out


def main(argv):
  del argv
  rows = []
  for path in FLAGS.results:
    try:
      with open(path) as f:
        rows += json.load(f)['rows']
    except (OSError, ValueError, KeyError) as e:
      raise app.UsageError(f'{path}: not a joint_pairs.json ({e})') from e
  out = strata(rows, FLAGS.split, FLAGS.ratio_split)
  print(f'{len(rows)} recordings; one recording and its reading, mean error (SE)')
  print('| recordings | n | area weight | load ratio | range centre: area weight |')
  print('|---|---:|---|---|---|')
  for name, s in out.items():
    print(f"| {name} | {s['n']} | {s['area_weight']:.1f}% ({s['area_weight_se']:.1f}) | "
          f"{s['load_ratio']:.1f}% ({s['load_ratio_se']:.1f}) | "
          f"{s['centre_area_weight']:.1f}% |")  # fmt: skip
  if FLAGS.out:
    files.write_json(FLAGS.out, {'strata': out, 'results': FLAGS.results})


def define_flags() -> None:
  """Defined only when run as a script, so tests can import the helpers."""
  flags.DEFINE_list('results', None, 'joint_pairs.json files', required=True)
  flags.DEFINE_float('split', 3.5, 'gentle fan settings: readings up to this, m/s')
  flags.DEFINE_float('ratio_split', 8.0, 'low load ratios: truths up to this')
  flags.DEFINE_string('out', None, 'JSON path')


if __name__ == '__main__':
  define_flags()
  app.run(main)
