"""The shipped tables and the protocol sets on recordings of another physics,
pooled over several check seeds.

One run of the paper-size check on ``physsim.mismatch.WORLD`` is 56
recordings (4 pairs per fabric); at 56, a 50% interval's coverage has a
binomial standard error of 7 points, and the seeds' truths differ enough that
one seed's 90% coverage can read 84% and another's 98% for the same tables.
This script adds up the counts of several such runs, each with its own seed
(new truths, cameras, gusts), so that a coverage is read to 3-4 points:

  for s in 2 3 4; do   # the searches: GPU, 6.5-8 minutes a seed on one H200
    python -m experiments.calibrate --preset=paper --check --physics=mismatched \
        --seed=$s --pairs=4 --workdir=/tmp/chk$s --time_limit=545
    # its packed/ (calibration.pack_runs) copied to out/chk_mm_cpu_s$s, then (CPU,
    # a minute; the same numbers as the device's own analysis):
    python -m experiments.calibrate --preset=paper --check --physics=mismatched \
        --seed=$s --pairs=4 --analyse_only --workdir=out/chk_mm_cpu_s$s
    # the protocol sets: an overhang recording of each sheet's fabric and truth
    # (CPU, 3.5 minutes a seed)
    python -m benchmarks.overhang_depth --seed=$s \
        --packed=out/chk_mm_cpu_s$s/packed --out=out/od_s$s
  done
  # seed 1 is BENCHMARKS.md's [C19] (analysed the same way) and [C22]'s seed-1 run
  python -m benchmarks.pooled_check \
      --checks=out/chk_mm_cpu_s1/check.json,...,out/chk_mm_cpu_s4/check.json \
      --protocol_sets=out/od_s1/summary.json,...,out/od_s4/summary.json \
      --out=out/pooled_check

The shipped calibration file keeps each seed's check (the device's
``check.json``, whose video cells are what the estimates printed) and an
estimate quotes them pooled (``calibration_tables.quoted_checks``):

  python -c "import json; from experiments.pipeline import calibration_tables; \
    from experiments.studies import calibration_check as c; \
    [calibration_tables.record_check(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE, \
      c.check_record(json.load(open(f'/tmp/chk{s}/check.json')))) for s in (2, 3, 4)]"

and the pool of those checks fabric by fabric, which an estimate of one
fabric quotes beside them (``calibration_tables.fabric_check``: "This fabric alone ...";
the shipped one is benchmarks/results/pooled_check_h200/pooled_check.json's):

  python -c "import json; from experiments.pipeline import calibration_tables; \
    calibration_tables.record_fabric_checks(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE, \
      json.load(open('out/pooled_check/pooled_check.json'))['checks'])"

Nothing is fitted here. The counts are exact (each check's coverage times
its recordings); a check's 95% intervals (Wilson's) count recordings as
independent, which for bending and area weight makes them too narrow: a pair's
two recordings share both. The protocol sets keep each set, so theirs resample
whole pairs (``pair_interval``). A protocol set's bending interval is compared with the
prior's central 90% (0.9 of the box's log range: bending is log-uniform in
it).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import bo  # noqa: E402
import physsim  # noqa: E402
from experiments.pipeline import calibration_tables, cli, files, posterior  # noqa: E402

FIELDS = ('bending_scale', 'wind_speed', 'area_weight', 'load_ratio')
SET_FIELDS = ('bending_scale', 'wind_speed', 'area_weight')
SET_MODES = ('sheet, anemometer', 'sheet, anemometer, overhang')
LEVELS = (50, 90)


@dataclasses.dataclass(frozen=True)
class Args:
  """What to pool.

  Attributes:
    checks: ``check.json`` files of ``experiments.calibrate --check``, one per
      seed, of one physics and one shipped calibration.
    protocol_sets: ``summary.json`` files of ``benchmarks.overhang_depth
      --packed``, one per seed, of one reader's law and set-up ranges.
    out: folder for ``pooled_check.json``, ``pooled_check.md`` and the figure.
  """

  checks: tuple[str, ...] = ()
  protocol_sets: tuple[str, ...] = ()
  out: str = 'out/pooled_check'


PRESETS = {'default': Args()}


def _one_of_each(paths, seeds, what: str) -> None:
  if len(set(seeds)) != len(seeds):
    raise ValueError(f'{what}: two files of one seed ({", ".join(paths)}): {seeds}')


def _same(paths, values, what: str) -> None:
  if len({json.dumps(v, sort_keys=True) for v in values}) > 1:
    raise ValueError(
      f'{what} differs between {paths[0]} and '
      + next(p for p, v in zip(paths, values, strict=True) if v != values[0])
    )


def _held(k: int, n: int) -> dict:
  lo, hi = bo.calibration.binomial_interval(k, n)
  return {'held': k / n, 'count': k, 'ci': [lo, hi]}


def _by_material(cells: list[dict]) -> dict:
  """One mode's per-fabric coverage of several checks added up (counts: each
  check's fraction times its fabric's recordings); {} where a check has none."""
  if not all('by_material' in c for c in cells):
    return {}
  out = {}
  for m in sorted({m for c in cells for m in c['by_material']}):
    mine = [c['by_material'][m] for c in cells if m in c['by_material']]
    n = sum(int(x['n']) for x in mine)
    out[m] = {'n': n}
    for q in FIELDS:
      out[m][q] = {
        f'held_{lv}': _held(
          sum(int(round(x[q][f'interval_{lv}'] * x['n'])) for x in mine), n
        )
        for lv in LEVELS
      }
  return out


def pool_checks(paths: list[str]) -> dict:
  """Per mode and quantity, the checks' counts added up: how often the 50%
  and 90% intervals held (with Wilson's 95% interval and each seed's own),
  the mean error of the point and of the range centre (recording-weighted).

  Raises:
    ValueError: a file missing or unreadable, two of one seed, or checks of
      different physics, calibration or search settings.
  """
  docs = [physsim.dataset.read_json(p) for p in paths]
  for p, d in zip(paths, docs, strict=True):
    if 'modes' not in d or 'n' not in d:
      raise ValueError(f'{p}: not a check.json of experiments.calibrate --check')
  _one_of_each(paths, [d['seed'] for d in docs], '--checks')
  _same(paths, [d['physics'] for d in docs], 'physics')
  _same(paths, [d['shipped']['setting'] for d in docs], 'the shipped calibration')
  _same(
    paths,
    [{k: v for k, v in d['config']['estimate'].items() if k != 'calibration'}
     for d in docs],
    'the estimate settings',
  )  # fmt: skip
  modes = [m for m in docs[0]['modes'] if all(m in d['modes'] for d in docs)]
  ns = [int(d['n']) for d in docs]
  n = sum(ns)
  out = {}
  for mode in modes:
    pooled = calibration_tables.pooled_cells([d['modes'][mode] for d in docs], ns)
    out[mode] = {}
    for q in FIELDS:
      cells = [d['modes'][mode][q] for d in docs]
      err = 'point_error_factor' if q == 'bending_scale' else 'point_error_pct'
      centre = 'centre_error_factor' if q == 'bending_scale' else 'centre_error_pct'
      row = {}
      for lv in LEVELS:  # the pooled fraction times n: the count over all recordings
        row[f'held_{lv}'] = _held(int(round(pooled[q][f'interval_{lv}'] * n)), n)
        row[f'held_{lv}']['per_seed'] = [c[f'interval_{lv}'] for c in cells]
      row['point_error'] = pooled[q][err]
      row['centre_error'] = pooled[q][centre]
      row['point_error_per_seed'] = [c[err] for c in cells]
      if all('confident_misses' in c for c in cells):  # counts: they add up
        row['confident_misses'] = sum(int(c['confident_misses']) for c in cells)
        row['confident_misses_expected'] = float(
          sum(c['confident_misses_expected'] for c in cells)
        )
      out[mode][q] = row
    fabrics = _by_material([d['modes'][mode] for d in docs]) if mode == 'video' else {}
    if fabrics:  # the video's alone: every mode's would make the file too big
      out[mode]['by_material'] = fabrics
  return {
    'files': list(paths), 'seeds': [d['seed'] for d in docs], 'n': n,
    'physics': docs[0]['physics'], 'calibration': docs[0]['shipped']['setting'],
    'modes': out,
  }  # fmt: skip


def _error(f: str, point: float, truth: float) -> float:
  """The error ``f`` is judged by (``posterior.ERROR_LOSS``: bending's factor,
  else percent)."""
  return float(bo.calibration.error(point, truth, posterior.ERROR_LOSS[f]))


def _narrowing(s: dict, cell: dict) -> float:
  """The bending's 90% interval against the prior's central 90% (0.9 of the
  box's log range)."""
  b0, b1 = physsim.search_space(s['material']).bending_scale
  lo, hi = cell['interval_90']
  return 0.9 * math.log(b1 / b0) / max(math.log(hi / lo), 1e-12)


def pair_interval(held, pairs, level: float = 0.95, draws: int = 4000,
                  seed: int = 0) -> list[float]:  # fmt: skip
  """A coverage's ``level`` interval resampling whole pairs (a percentile
  bootstrap over clusters): ``held[i]`` whether set ``i``'s interval held,
  ``pairs[i]`` its pair (sets sharing a truth). Where a pair's two hold or
  miss together, it is as wide as Wilson's on half as many sets."""
  held = np.asarray(held, np.float64)
  _, which = np.unique(np.asarray(pairs), return_inverse=True)
  k = np.bincount(which, weights=held)
  m = np.bincount(which).astype(np.float64)
  rng = np.random.default_rng(seed)
  pick = rng.integers(0, len(k), (draws, len(k)))
  cov = k[pick].sum(axis=1) / m[pick].sum(axis=1)
  a = (1.0 - level) / 2.0
  return [float(np.quantile(cov, a)), float(np.quantile(cov, 1.0 - a))]


def _by_fabric(sets: list[dict], cell, errors: np.ndarray) -> dict:
  """Per fabric, area weight's mean percent error (``errors``, one per set)
  against the search box's centre's on the same truths, the box's width
  (high over low) and how often the 90% interval held: the error follows the
  box."""
  out = {}
  materials = np.array([s['material'] for s in sets])
  for material in sorted(set(materials)):
    mine = [s for s in sets if s['material'] == material]
    lo, hi = physsim.search_space(material).area_weight
    truth = np.array([s['truth']['area_weight'] for s in mine])
    centre = bo.calibration.error((lo + hi) / 2, truth, 'relative')
    out[material] = {
      'sets': len(mine),
      'mean_pct': float(np.mean(errors[materials == material])),
      'centre_pct': float(np.mean(centre)),
      'box_ratio': hi / lo,
      'held_90': float(np.mean([bool(cell(s, 'area_weight')['held_90']) for s in mine])),
    }  # fmt: skip
  return out


def pool_sets(paths: list[str]) -> dict:
  """The protocol sets of several ``overhang_depth`` runs as one: per mode,
  the bending's median factor error and narrowing, area weight's and wind's
  mean percent error, and how often each interval held, as printed (else the
  raw posterior's, as the run kept).

  Raises:
    ValueError: a file missing, without protocol sets, two of one seed, or
      runs of another reader's law or set-up ranges.
  """
  docs = [physsim.dataset.read_json(p) for p in paths]
  for p, d in zip(paths, docs, strict=True):
    if not d.get('sets'):
      raise ValueError(f'{p}: no protocol sets (an overhang_depth run with --packed)')
  _one_of_each(paths, [d['args']['seed'] for d in docs], '--protocol_sets')
  _same(paths, [[d['dof'], d['floor']] for d in docs], "the reader's law")
  _same(paths, [d['args']['setups'] for d in docs], 'the set-up ranges')
  sets = [{**s, 'seed_of_run': d['args']['seed']} for d in docs for s in d['sets']]
  out = {}
  for mode in SET_MODES:
    mine = [s for s in sets if mode in s['joint']]
    if not mine:
      continue
    how = 'printed' if all('printed' in s['joint'][mode] for s in mine) else 'raw'

    def cell(s, f, mode=mode, how=how):
      return s['joint'][mode][how][f]

    n = len(mine)
    row = {'sets': n, 'how': how}
    # a pair's two recordings share a truth (bending and area weight)
    pairs = [
      f'{s["seed_of_run"]}:{s["material"]}:{s["truth"]["bending_scale"]:.9g}:'
      f'{s["truth"]["area_weight"]:.9g}'
      for s in mine
    ]
    # each set's error: bending's factor, the others' percent
    errs = {
      f: np.array([_error(f, cell(s, f)['point'], s['truth'][f]) for s in mine])
      for f in SET_FIELDS
    }
    row['bending_median_factor'] = float(np.median(errs['bending_scale']))
    row['bending_narrowing_90_median'] = float(
      np.median([_narrowing(s, cell(s, 'bending_scale')) for s in mine])
    )
    for f, key in (
      ('area_weight', 'area_weight_mean_pct'),
      ('wind_speed', 'wind_mean_pct'),
    ):
      row[key] = float(np.mean(errs[f]))
    for f in SET_FIELDS:
      for lv in LEVELS:
        k = sum(bool(cell(s, f)[f'held_{lv}']) for s in mine)
        row[f'{f}_held_{lv}'] = _held(k, n)
        row[f'{f}_held_{lv}']['ci_pairs'] = pair_interval(
          [bool(cell(s, f)[f'held_{lv}']) for s in mine], pairs
        )
        row[f'{f}_held_{lv}']['per_seed'] = [
          float(np.mean([bool(cell(x, f)[f'held_{lv}']) for x in d['sets']
                         if mode in x['joint']]))
          for d in docs
        ]  # fmt: skip
    row['area_weight_by_fabric'] = _by_fabric(mine, cell, errs['area_weight'])
    wind = np.array([s['truth']['wind_speed'] for s in mine])
    err = errs['area_weight']
    row['area_weight_by_wind'] = {
      f'{lo}-{lo + 1} m/s': float(err[(wind >= lo) & (wind < lo + 1)].mean())
      for lo in range(1, 6)
      if ((wind >= lo) & (wind < lo + 1)).any()
    }
    out[mode] = row
  return {
    'files': list(paths), 'seeds': [d['args']['seed'] for d in docs],
    'law': {'dof': docs[0]['dof'], 'floor': docs[0]['floor']},
    'setups': docs[0]['args']['setups'], 'modes': out,
  }  # fmt: skip


def _pct(h: dict, key: str = 'ci') -> str:
  lo, hi = h[key]
  return f'{100 * h["held"]:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}]'


def _seeds(h: dict) -> str:
  v = [100 * x for x in h['per_seed']]
  return f'{min(v):.0f}-{max(v):.0f}%'


def _checks_table(checks: dict) -> list[str]:
  """The pooled checks' coverage per mode and quantity, the confident wind
  misses, and the video's coverage by fabric."""
  lines = [
    f'Shipped tables on {checks["n"]} recordings of the {checks["physics"]} '
    f'physics (seeds {", ".join(map(str, checks["seeds"]))}; {checks["calibration"]}); '
    "brackets: 95% intervals counting recordings as independent (a pair's two "
    "share bending and area weight); seeds: the range of the seeds' own",
    '',
    '| mode | quantity | 50% held | seeds | 90% held | seeds | mean error: point | range centre |',
    '|---|---|---|---|---|---|---|---|',
  ]
  for mode, by in checks['modes'].items():
    for q, r in by.items():
      if q == 'by_material':
        continue
      fmt = (lambda v: f'x{v:.2f}') if q == 'bending_scale' else (lambda v: f'{v:.1f}%')
      lines.append(
        f'| {mode} | {q} | {_pct(r["held_50"])} | {_seeds(r["held_50"])} | '
        f'{_pct(r["held_90"])} | {_seeds(r["held_90"])} | {fmt(r["point_error"])} | '
        f'{fmt(r["centre_error"])} |'
      )
  conf = [(m, by['wind_speed']) for m, by in checks['modes'].items()
          if 'confident_misses' in by.get('wind_speed', {})]  # fmt: skip
  if conf:
    lines += [
      '',
      'Wind points more than 25% off with the truth outside the 90% interval, '
      'per mode, beside how many the posteriors themselves expect (their mass '
      'there, summed; calibrated intervals expect some): '
      + '; '.join(
        f'{m} {r["confident_misses"]} ({r["confident_misses_expected"]:.1f})'
        for m, r in conf
      ),
    ]
  video = checks['modes'].get('video', {}).get('by_material')
  if video:
    lines += [
      '',
      'By fabric, the video alone: how often the 90% intervals held '
      "(brackets: 95% intervals; a fabric's recordings are few, and a pair's two "
      'share bending and area weight)',
      '',
      '| fabric | n | ' + ' | '.join(FIELDS) + ' |',
      '|---|---|' + '---|' * len(FIELDS),
    ]
    for m, r in video.items():
      cells = ' | '.join(_pct(r[q]['held_90']) for q in FIELDS)
      lines.append(f'| {m} | {r["n"]} | {cells} |')
  return lines


def _sets_table(sets: dict) -> list[str]:
  """The protocol sets per mode, and area weight by fabric and by wind."""
  lines = [
    '',
    f"Protocol sets (seeds {', '.join(map(str, sets['seeds']))}; the reader's t of "
    f'{sets["law"]["dof"]:g}, set-ups "{sets["setups"]}"); brackets: 95% intervals '
    'resampling whole pairs (a pair shares its truth)',
    '',
    "| sets | n | bending factor (median) | its 90% vs the prior's | area weight | wind "
    '| bending 90% / 50% held | wind | area weight |',
    '|---|---|---|---|---|---|---|---|---|',
  ]
  for mode, r in sets['modes'].items():
    held = ' | '.join(
      f'{_pct(r[f"{f}_held_90"], "ci_pairs")} / {_pct(r[f"{f}_held_50"], "ci_pairs")}'
      for f in SET_FIELDS
    )
    lines.append(
      f'| {mode} ({r["how"]}) | {r["sets"]} | x{r["bending_median_factor"]:.2f} | '
      f'x{r["bending_narrowing_90_median"]:.1f} narrower | '
      f'{r["area_weight_mean_pct"]:.1f}% | {r["wind_mean_pct"]:.1f}% | {held} |'
    )
  last = list(sets['modes'])[-1]
  lines += [
    '',
    f"Area weight by fabric ({last}): mean error, the box centre's on the same "
    'truths, the box (high / low), 90% held',
    '',
    '| fabric | sets | area weight | box centre | box | 90% held |',
    '|---|---|---|---|---|---|',
  ]
  for material, a in sets['modes'][last]['area_weight_by_fabric'].items():
    lines.append(
      f'| {material} | {a["sets"]} | {a["mean_pct"]:.1f}% | {a["centre_pct"]:.1f}% | '
      f'x{a["box_ratio"]:.2f} | {100 * a["held_90"]:.0f}% |'
    )
  lines += [
    '',
    'Area weight by the true wind: '
    + ', '.join(
      f'{band} {v:.1f}%'
      for band, v in sets['modes'][last]['area_weight_by_wind'].items()
    ),
  ]
  return lines


def table(checks: dict | None, sets: dict | None) -> str:
  lines = _checks_table(checks) if checks else []
  if sets:
    lines += _sets_table(sets)  # its first line blank, as after the checks'
  return '\n'.join(lines)


def plot(checks: dict | None, sets: dict | None, path: str) -> None:
  """Coverage at 50% and 90%: each seed (dots) and the pool (diamond, 95%
  interval) for the check's modes with an anemometer and the protocol sets."""
  rows = []
  if checks:
    for mode in ('video', 'known wind', 'known wind, bending length'):
      for q in FIELDS[:3]:
        if mode in checks['modes']:
          rows.append((f'{mode}: {q}', checks['modes'][mode][q], 'held_'))
  if sets and SET_MODES[1] in sets['modes']:
    for f in SET_FIELDS:
      rows.append((f'protocol set: {f}', sets['modes'][SET_MODES[1]], f'{f}_held_'))
  if not rows:
    return
  fig, ax = plt.subplots(1, 2, figsize=(12, 0.35 * len(rows) + 1.5), sharey=True)
  y = np.arange(len(rows))
  for a, lv in zip(ax, LEVELS, strict=True):
    for i, (_, r, pre) in enumerate(rows):
      h = r[f'{pre}{lv}']
      lo, hi = h['ci']
      a.plot([lo, hi], [i, i], 'k-', lw=1.2)
      a.plot(h['held'], i, 'D', color='C0', ms=6)
      a.plot(h['per_seed'], [i] * len(h['per_seed']), 'o', color='C1', ms=3, alpha=0.8)
    a.axvline(lv / 100, color='k', ls='--', lw=0.8)
    a.axvspan(*((0.40, 0.60) if lv == 50 else (0.85, 0.95)), color='C2', alpha=0.12)
    a.set_xlim(*((0.2, 0.8) if lv == 50 else (0.7, 1.0)))
    a.set_xlabel(f'how often the {lv}% interval held the truth')
  ax[0].set_yticks(y, [name for name, _, _ in rows], fontsize=8)
  ax[0].invert_yaxis()
  fig.suptitle(
    'Another physics, pooled over seeds: the pool (diamond, its 95% interval) and '
    "each seed's (dots); shaded: issue 39's targets", fontsize=10,
  )  # fmt: skip
  fig.tight_layout()
  files.savefig(fig, path, dpi=100)
  plt.close(fig)


def main(args: Args) -> None:
  if not args.checks and not args.protocol_sets:
    raise ValueError('give --checks and/or --protocol_sets (files to pool)')
  checks = pool_checks(list(args.checks)) if args.checks else None
  sets = pool_sets(list(args.protocol_sets)) if args.protocol_sets else None
  text = table(checks, sets)
  print(text)
  os.makedirs(args.out, exist_ok=True)
  files.write_json(os.path.join(args.out, 'pooled_check.json'),
                   {'checks': checks, 'protocol_sets': sets})  # fmt: skip
  files.write_text(os.path.join(args.out, 'pooled_check.md'), text + '\n')
  plot(checks, sets, os.path.join(args.out, 'pooled_check.png'))


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
