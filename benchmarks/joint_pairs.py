"""Area weight from two fan settings, each with an anemometer reading.

Makes ``--pairs`` pairs of real-like recordings of one fabric (the
``generate_dataset --preset=eval`` recipe at the network's image size; a pair
shares bending and area weight and draws two winds, as
``experiments.calibrate`` draws its pairs), gives each recording a simulated
anemometer reading (``posterior.simulated_reading``, ``--reading_sd``) and
estimates each pair jointly (``search.estimate_joint``: each recording's own
search steered by its reading, then the joint posterior). Prints, over the
recordings, the mean error of area weight, wind and the load ratio estimated
from one recording with its reading (each joint's ``alone``) and from the pair
jointly, beside the range centre's; writes JSON. A GPU at paper size:

  python benchmarks/joint_pairs.py --model=out/table1/physnet_depth/simulation/gray_interlock \\
      --workdir=/tmp/pairs --pairs=6
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np
from absl import app, flags, logging

import physsim
from experiments.pipeline import cli, datasets, embedding, files, objective, search
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import recording as recording_lib
from experiments.studies import calibration

FLAGS = flags.FLAGS
flags.DEFINE_string('model', None, "the fabric's trained network", required=True)
flags.DEFINE_string('workdir', None, 'recordings and estimates go here', required=True)
flags.DEFINE_string('material', 'gray_interlock', 'the fabric')
flags.DEFINE_integer('pairs', 6, 'pairs of recordings')
flags.DEFINE_integer('seed', 0, 'truths, readings and searches')
flags.DEFINE_float('reading_sd', 0.02, "the anemometer's relative standard error")
flags.DEFINE_enum('preset', 'default', list(objective.PRESETS), 'estimate settings')
flags.DEFINE_string('backend', '', "simulator (empty: the preset's)")
flags.DEFINE_bool('smoke', False, 'CPU-sized recordings (checks the script)')
NAMES = ('wind_speed', 'area_weight', 'load_ratio')
FLAG_NAMES = ('model', 'material', 'pairs', 'seed', 'reading_sd', 'preset', 'backend')


def _recordings(workdir: str, size: int) -> list[dict]:
  """The pairs' recordings (made or resumed), pair-major, with their truths."""
  study = calibration.Config(
    material=FLAGS.material, pairs=FLAGS.pairs, seed=FLAGS.seed
  )
  truths = calibration.truths(study)
  cfg = datasets.PRESETS['smoke' if FLAGS.smoke else 'eval']
  cfg = dataclasses.replace(
    cfg, materials=(FLAGS.material,), sequences=2 * FLAGS.pairs, resolution=size,
    batch_size=min(2 * FLAGS.pairs, 64), seed=6000 + FLAGS.seed,
    **({'backend': FLAGS.backend} if FLAGS.backend else {}),
  )  # fmt: skip
  root = os.path.join(workdir, 'recordings')
  datasets.run(cfg, root, params={FLAGS.material: truths})
  index = physsim.dataset.open_dataset(root)
  rows = {int(r['seq_id']): r for r in index.filter(material=FLAGS.material).rows}
  out = []
  for p in range(FLAGS.pairs):
    pair = [rows.get(2 * p), rows.get(2 * p + 1)]
    if all(r is not None and r['valid'] for r in pair):  # a pair needs both
      out.append([{'seq': int(r['seq_id']), 'path': index.path(r)} for r in pair])
    else:
      print(f'pair {p}: a recording was not kept (camera coverage); left out')
  return out


def _error(est: float, truth: float) -> float:
  return float(100 * abs(est / truth - 1))


def main(argv):
  del argv
  logging.set_verbosity(logging.WARNING)  # orbax logs every restore at INFO
  cli.host_devices()  # as the scripts: one CPU device per core (GP searches)
  net = embedding.load_embedding(FLAGS.model)
  config = objective.PRESETS[FLAGS.preset]
  config = dataclasses.replace(
    config, material=FLAGS.material,
    **({'backend': FLAGS.backend} if FLAGS.backend else {}),
  )  # fmt: skip
  centre = physsim.search_space(FLAGS.material).center()
  guess = {
    'wind_speed': float(centre.wind_speed), 'area_weight': float(centre.area_weight),
    'load_ratio': float(physsim.load_ratio(centre.wind_speed, centre.area_weight)),
  }  # fmt: skip
  rows = []
  for pair in _recordings(FLAGS.workdir, net.image_size[0]):
    recs, winds = [], []
    for r in pair:
      rec = recording_lib.load_recording(
        r['path'], fps=config.fps, size=net.image_size, frames=config.frames
      )
      m = posterior_lib.simulated_reading(
        'wind_speed', rec.truth, FLAGS.reading_sd, FLAGS.seed, r['seq']
      )
      recs.append(rec)
      winds.append((m.wind_speed, m.wind_speed_sd))
    wd = os.path.join(FLAGS.workdir, f'pair_{pair[0]["seq"] // 2:02d}')
    out = search.estimate_joint(config, recs, FLAGS.model, wd, winds)
    for k, rec in enumerate(recs):
      t = dict(rec.truth)
      t['load_ratio'] = float(physsim.load_ratio(t['wind_speed'], t['area_weight']))
      alone = out['recordings'][k]['alone']
      joint = {
        'wind_speed': out['recordings'][k]['wind_speed'],
        'area_weight': out['area_weight'],
        'load_ratio': out['recordings'][k]['load_ratio'],
      }
      one = {n: alone[n]['value'] for n in NAMES[:2]}
      one['load_ratio'] = physsim.load_ratio(one['wind_speed'], one['area_weight'])
      rows.append({
        'seq': pair[k]['seq'],
        'truth': t,
        'reading': list(winds[k]),
        'alone': {n: _error(one[n], t[n]) for n in NAMES},
        'joint': {n: _error(joint[n]['bayes'], t[n]) for n in NAMES},
        'joint_median': {n: _error(joint[n]['median'], t[n]) for n in NAMES},
        'centre': {n: _error(guess[n], t[n]) for n in NAMES},
        'joint_covered_90': {
          n: bool(joint[n]['interval_90'][0] <= t[n] <= joint[n]['interval_90'][1])
          for n in NAMES
        },
      })  # fmt: skip
  if not rows:
    raise SystemExit('no pair of recordings was kept')
  summary = {
    who: {n: float(np.mean([r[who][n] for r in rows])) for n in NAMES}
    for who in ('alone', 'joint', 'joint_median', 'centre')
  }
  summary['joint_covered_90'] = {
    n: float(np.mean([r['joint_covered_90'][n] for r in rows])) for n in NAMES
  }
  print(f'{len(rows)} recordings in {len(rows) // 2} pairs, {FLAGS.material}, '
        f'readings with {100 * FLAGS.reading_sd:g}% error; mean errors')  # fmt: skip
  print('| estimate | wind | area weight | load ratio |')
  print('|---|---|---|---|')
  labels = {'alone': 'one recording and its reading', 'joint': 'the pair, jointly',
            'joint_median': 'the pair, posterior median', 'centre': 'range centre'}  # fmt: skip
  for who, label in labels.items():
    s = summary[who]
    print(f'| {label} | ' + ' | '.join(f'{s[n]:.1f}%' for n in NAMES) + ' |')
  cov = summary['joint_covered_90']
  print('joint 90% intervals held the truth: '
        + ', '.join(f'{n} {100 * cov[n]:.0f}%' for n in NAMES))  # fmt: skip
  files.write_json(
    os.path.join(FLAGS.workdir, 'joint_pairs.json'),
    {
      'rows': rows,
      'summary': summary,
      'flags': {k: FLAGS[k].value for k in FLAG_NAMES},
    },
  )


if __name__ == '__main__':
  app.run(main)
