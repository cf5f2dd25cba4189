"""The likelihood's model-discrepancy term, fitted on recordings of another physics.

For each model error ``e`` (``bo.posterior``: scatter of the log distance the
simulator does not make, added to its own in quadrature), the paper-size
calibration's tables are fitted again on its own-physics recordings with the
likelihood at ``e``, then read, with nothing fitted, on recordings of
``physsim.mismatch.WORLD``. Both come from searches already run, so each ``e``
is an analysis only (no simulation):

  for e in 0 0.5 1 2; do
    python -m experiments.calibrate --preset=paper --analyse_only --model_error=$e \
        --workdir=/tmp/me/cal_$e        # its packed/: the 210-recording run's
    python -m experiments.calibrate --preset=paper --check --physics=mismatched \
        --seed=1 --pairs=4 --analyse_only --model_error=$e \
        --calibration=/tmp/me/cal_$e/calibration.json \
        --workdir=/tmp/me/chk_$e        # its packed/: the mismatched check's
  done
  python -m benchmarks.model_error --errors=0,0.5,1,2 --root=/tmp/me

With more check seeds (``benchmarks.pooled_check``'s runs), each seed's check
at each ``e`` in ``chk_<e>_s<seed>`` (the same check command with that seed,
its packed runs, and ``--workdir=/tmp/me/chk_<e>_s<seed>``) is pooled in:

  python -m benchmarks.model_error --errors=0,0.5,1 --seeds=2,3,4 --root=/tmp/me

The term is chosen as a calibration's sharpness is, by the interval score
(Gneiting & Raftery: narrow, but holding the truth), here on the mismatched
recordings, where it matters: the smallest ``e`` whose mean score is within
``tolerance`` of the best (a larger term widens every estimate's intervals, so
it has to earn its place). This script prints, per ``e``, coverage and
interval scores on both, and that choice.
"""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np

from experiments.pipeline import cli, files, report

FIELDS = ('bending_scale', 'wind_speed', 'area_weight', 'load_ratio')
MODES = ('video', 'known wind', 'joint pair, known winds')


@dataclasses.dataclass(frozen=True)
class Args:
  """The comparison.

  Attributes:
    errors: the model errors analysed (``cal_<e>`` and ``chk_<e>`` under root).
    root: the folder holding each error's calibration and check workdirs.
    seeds: further check seeds, read from ``chk_<e>_s<seed>`` and pooled with
      ``chk_<e>`` (each cell the recordings' mean): a 50% coverage on one
      seed's 56 recordings is known to +-7 points.
    tolerance: relative margin over the best mean interval score within which
      the smallest model error is chosen.
    out: JSON path.
  """

  errors: tuple[str, ...] = ('0', '0.5', '1', '2')
  root: str = '/tmp/me'
  seeds: tuple[str, ...] = ()
  tolerance: float = 0.01
  out: str = 'out/benchmarks/model_error.json'


PRESETS = {'default': Args()}


def _cells(summary: dict) -> dict:
  return {
    f: {k: summary[f][k] for k in ('interval_50', 'interval_90', 'interval_score_90')}
    | (
      {'width_ratio': summary[f]['width_ratio']} if 'width_ratio' in summary[f] else {}
    )
    for f in FIELDS
  }


def _pooled(checks: list[dict]) -> dict:
  """Checks of one calibration on several seeds as one: ``n`` added up and
  every numeric cell of every mode the recordings' mean."""
  ns = [k['n'] for k in checks]
  modes = [m for m in checks[0]['modes'] if all(m in k['modes'] for k in checks)]
  return {
    'n': sum(ns),
    'modes': {
      m: report.pooled_cells([k['modes'][m] for k in checks], ns) for m in modes
    },
  }


def row(root: str, error: str, seeds: tuple[str, ...] = ()) -> dict:
  """One model error's numbers: held out on its own physics (cross-fitted),
  and on the mismatched recordings per mode (``seeds``' checks pooled in)."""
  cal = os.path.join(root, f'cal_{error}', 'calibration.json')
  chks = [os.path.join(root, f'chk_{error}', 'check.json')] + [
    os.path.join(root, f'chk_{error}_s{s}', 'check.json') for s in seeds
  ]
  for p in (cal, *chks):
    if not os.path.isfile(p):
      raise ValueError(f'{p}: missing (run the commands in the module doc)')
  with open(cal) as f:
    c = json.load(f)
  ks = []
  for p in chks:
    with open(p) as f:
      ks.append(json.load(f))
  if float(c.get('model_error', 0.0)) != float(error):
    raise ValueError(f'{cal}: made with model error {c.get("model_error", 0.0)}')
  for p, x in zip(chks, ks, strict=True):
    made = float(x.get('config', {}).get('estimate', {}).get('model_error', error))
    if made != float(error):
      raise ValueError(f'{p}: made with model error {made}')
  if len({x.get('seed') for x in ks}) != len(ks):
    raise ValueError(f'{", ".join(chks)}: two checks of one seed')
  k = _pooled(ks)
  mm = {m: _cells(k['modes'][m]) for m in MODES if m in k['modes']}
  return {
    'model_error': float(error),
    'own': _cells(c['held_out']['video']),
    'mismatched': mm,
    'mismatched_score': float(
      np.mean([v[f]['interval_score_90'] for v in mm.values() for f in FIELDS])
    ),
    'n_own': c['n'],
    'n_mismatched': k['n'],
  }


def table(rows: list[dict]) -> str:
  head = (
    '| model error | own physics, video: 90% held (bending, wind, area weight, load '
    'ratio) | its wind 90% width / prior | mismatched, video: 50% / 90% held | '
    'mismatched, known wind: 90% held | mean 90% interval score, mismatched (3 modes) |'
  )
  lines = [head, '|---|---|---|---|---|---|']
  pct = lambda v: f'{100 * v:.0f}%'
  for r in rows:
    own, v = r['own'], r['mismatched']['video']
    kw = r['mismatched'].get('known wind', {})
    lines.append(
      f'| {r["model_error"]:g} | '
      + ', '.join(pct(own[f]['interval_90']) for f in FIELDS)
      + f' | {own["wind_speed"].get("width_ratio", float("nan")):.2f} | '
      + ', '.join(
        f'{pct(v[f]["interval_50"])}/{pct(v[f]["interval_90"])}' for f in FIELDS
      )
      + ' | '
      + (', '.join(pct(kw[f]['interval_90']) for f in FIELDS) if kw else '-')
      + f' | {r["mismatched_score"]:.4f} |'
    )
  return '\n'.join(lines)


def choose(rows: list[dict], tolerance: float) -> float:
  """The smallest model error whose mean interval score on the mismatched
  recordings is within ``tolerance`` (relative) of the best one's."""
  best = min(r['mismatched_score'] for r in rows)
  return min(
    r['model_error'] for r in rows if r['mismatched_score'] <= best * (1 + tolerance)
  )


def main(args: Args) -> None:
  rows = [row(args.root, e, args.seeds) for e in args.errors]
  chosen = choose(rows, args.tolerance)
  print(table(rows))
  print(
    f'\nchosen: model error {chosen:g} (the smallest within '
    f'{100 * args.tolerance:g}% of the best mean interval score on the mismatched '
    'recordings)'
  )
  os.makedirs(os.path.dirname(args.out) or '.', exist_ok=True)
  files.write_json(args.out, {'rows': rows, 'chosen': chosen})


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
