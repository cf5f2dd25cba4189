"""The shipped calibration held out: its tables on recordings they never saw.

``check`` estimates new recordings (another seed, with the estimate's
defaults; another network where the study has them) and reads each posterior
at the shipped tables' CDF levels with their weights, as an estimate reads
it; nothing is fitted. ``check_record`` is what the calibration file keeps of
it (estimates quote it beside the calibration's own coverage); ``printed``
reads what the estimates themselves printed.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

import bo
import physsim
from experiments.pipeline import calibration_tables, distributed, files, layout
from experiments.pipeline import objective as objective_lib
from experiments.pipeline import recording as recording_lib
from experiments.studies.calibration_analysis import (
  CONFIDENT_MISS_PCT,
  coverage_of,
  summarise,
)
from experiments.studies.calibration_config import (
  FIELDS,
  LEVELS,
  MODE_OF_READING,
  Config,
  check_config,
  estimate_record,
  network_of,
  network_seeds,
  study_configs,
)
from experiments.studies.calibration_report import error_text, pair_text, plot_ranks
from experiments.studies.calibration_runs import (
  recorded_networks,
  saved_runs,
  simulate_and_estimate,
)
from experiments.studies.calibration_scores import posteriors

CHECK_FILE = 'check.json'


def check_analysis(config: Config, runs: list[dict], shipped: dict) -> dict:
  """How often a calibration's intervals hold the truth on ``runs``, recordings
  it never saw: per mode, each recording's posterior formed from its saved GP
  at the calibration's likelihood and sharpness and read at its CDF levels
  with its weights, as an estimate reads it. Nothing is fitted here.

  Returns:
    ``{mode: summarise(...)}``, each coverage with its 95% binomial interval
    (``'interval_50_ci'``, ``'interval_90_ci'``), and per fabric
    (``'by_material'``: its recordings and how often their intervals held).

  Raises:
    ValueError: the calibration has no tables, or for other quantities.
  """
  rc = shipped.get('recalibration')
  if not rc or tuple(rc['fields']) != FIELDS:
    raise ValueError(f'the calibration has no recalibration tables for {FIELDS}')
  space = physsim.search_space(config.material)
  scores = posteriors(
    config, runs, shipped['likelihood'], float(shipped['sharpness']),
    model_error=float(shipped.get('model_error', 0.0)),
  )  # fmt: skip
  out = {}
  for mode, v in scores.items():
    if mode not in rc['modes'] or not v:
      continue
    levels = np.asarray(rc['modes'][mode])
    w = rc.get('weights', {}).get(mode, {})
    s = summarise([{**x, 'levels': levels, 'weights': w} for x in v], space)
    seeds = network_seeds(config)
    read = [{**x, 'levels': levels, 'weights': w} for x in v]
    held = lambda rows: {  # noqa: E731
      'n': len(rows),
      **coverage_of(summarise(rows, space, bayes=False)),
    }
    s['per_network'] = {}
    for k, seed in enumerate(seeds):
      mine = [x for x in read if network_of(config, x['seq']) == k]
      if mine:
        s['per_network'][str(seed)] = held(mine)
    # how often each fabric's intervals held
    s['by_material'] = {
      m: held([x for x in read if x['material'] == m])
      for m in sorted({x['material'] for x in v})
    }
    ranks = np.stack([x['rank'] for x in v])  # (n, fields)
    for i, f in enumerate(FIELDS):
      r = bo.calibration.unwarp(ranks[:, i], levels[:, i])
      hist, _ = np.histogram(r, bins=10, range=(0, 1))
      s[f]['recalibrated_rank_histogram'] = hist.tolist()
      for lv in LEVELS:
        k = round(s[f][f'interval_{lv}'] * s['n'])
        s[f][f'interval_{lv}_ci'] = list(bo.calibration.binomial_interval(k, s['n']))
    out[mode] = s
  return out


# estimate.json's error keys, per field
_ERROR_KEY = {'bending_scale': 'bending_factor', 'wind_speed': 'wind_speed_pct',
              'area_weight': 'area_weight_pct', 'load_ratio': 'load_ratio_pct'}  # fmt: skip


def printed(runs: list[dict]) -> dict:
  """What the estimates themselves printed (the video alone, or with the
  reading they were given): how often their
  50% and 90% intervals held the truth (with 95% binomial intervals), their
  points' mean errors beside the range centre's, and how many of them applied
  the shipped tables (an estimate whose settings differ does not).

  Raises:
    ValueError: no runs, or an estimate without intervals (``--point=argmin``).
  """
  if not runs:
    raise ValueError('no finished estimates to check')
  rows = []
  for r in runs:
    path = os.path.join(r['workdir'], layout.ESTIMATE_FILE)
    e = recording_lib.read_json(path)
    if 'covered' not in e or 'interval_50' not in e['covered']['wind_speed']:
      raise ValueError(f'{path}: no credible intervals with a truth to check')
    rows.append(e)
  note = lambda e: e.get('calibration') or {}
  out = {
    **_printed_cells(rows),
    'recalibrated': sum(
      bool(note(e).get('matches') and note(e).get('recalibrated')) for e in rows
    ),
  }
  out['confident_misses'] = [
    {
      'recording': e.get('recording', ''),
      'material': e.get('material'),
      'wind_error_pct': e['errors']['estimate']['wind_speed_pct'],
      'interval_90': e['estimate']['wind_speed']['interval_90'],
      'truth': e['truth']['wind_speed'],
    }
    for e in rows
    if e['errors']['estimate']['wind_speed_pct'] > CONFIDENT_MISS_PCT
    and not e['covered']['wind_speed']['interval_90']
  ]  # fmt: skip
  mats = sorted({e.get('material') for e in rows} - {None})
  if len(mats) > 1:
    out['per_material'] = {
      m: _printed_cells([e for e in rows if e.get('material') == m]) for m in mats
    }
  return out


def _printed_cells(rows: list[dict]) -> dict:
  """``printed``'s numbers for some estimates' ``estimate.json`` rows."""
  n = len(rows)
  out = {'n': n}
  for f in FIELDS:
    cell = {}
    for lv in LEVELS:
      k = sum(bool(e['covered'][f][f'interval_{lv}']) for e in rows)
      cell[f'interval_{lv}'] = k / n
      cell[f'interval_{lv}_ci'] = list(bo.calibration.binomial_interval(k, n))
    for who in ('estimate', 'range_centre'):
      cell[f'{who}_error'] = float(
        np.mean([e['errors'][who][_ERROR_KEY[f]] for e in rows])
      )
    out[f] = cell
  return out


def checked_file(config: Config) -> str:
  """The calibration file ``check`` checks with ``config``: the estimate's
  own (``--calibration``), else the one shipped for its settings."""
  return calibration_tables.calibration_file(study_configs(config)[3])


def check(
  config: Config, workdir: str, shipped_file: str | None = None,
  analyse_only: bool = False,
) -> dict:  # fmt: skip
  """Checks a calibration on recordings it never saw: ``shipped_file``, else
  ``config.estimate.scoring.calibration``, else the one shipped for its distance.

  Makes and estimates ``2 * config.pairs`` new recordings as the study does,
  with ``config.seed`` other than the calibration's (so the truths, recordings
  and searches are all new; network seeds other than the calibration's train
  networks it never saw) and the estimate's own defaults (the Bayes point;
  that calibration's tables applied where the settings match), then
  reports how often the intervals hold the truth: those the estimates printed
  (video alone, or with ``config.check_reading`` the mode of that reading)
  and every mode's, read from the saved GPs with the calibration's
  sharpness, levels and weights (``check_analysis``; with a reading only its
  mode, as the searches were steered by it). Writes ``check.json``,
  ``check.md`` and ``check_ranks.png`` in ``workdir``.

  Raises:
    ValueError: no calibration there, or ``config.seed`` is its own.
  """
  config, path, shipped = _checked(config, shipped_file)
  t0 = time.time()
  os.makedirs(workdir, exist_ok=True)
  if analyse_only:
    runs = saved_runs(workdir)
  else:
    runs = simulate_and_estimate(
      config, workdir, point='bayes', reading=config.check_reading
    )
  if not distributed.is_main():
    return {}
  mode = MODE_OF_READING[config.check_reading]
  modes = check_analysis(config, runs, shipped)
  if config.check_reading != 'none':
    modes = {m: v for m, v in modes.items() if m == mode}
  held = shipped.get('held_out', {})
  network = recorded_networks(workdir)
  theirs = set(shipped.get('network', {}).get('seeds', [0]))
  out = {
    'material': config.material,
    'seed': config.seed,
    'physics': config.physics,
    'n': len(runs),
    'network': network,
    # the checked networks the calibration never saw (its seeds: 0 if unrecorded)
    'held_out_networks': sorted(set(network_seeds(config)) - theirs),
    'shipped_file': path,
    'shipped': {
      **{k: shipped.get(k) for k in ('setting', 'n', 'likelihood', 'sharpness')},
      'held_out': {m: coverage_of(v) for m, v in held.items()},
    },
    # packed runs (an analysis elsewhere) keep no estimate.json to read
    'printed': printed(runs) if all(r.get('workdir') for r in runs) else None,
    'printed_mode': mode,
    'modes': modes,
    'config': estimate_record(config, config.estimate),
    'seconds': time.time() - t0,
  }
  _write(out, workdir)
  return out


def _checked(config: Config, shipped_file: str | None) -> tuple[Config, str, dict]:
  """The check's config (its estimates apply the tables being checked), the
  calibration file's path and its contents.

  Raises:
    ValueError: no calibration there, or ``config.seed`` is its own.
  """
  check_config(config)
  path = shipped_file or checked_file(config)
  if not os.path.isfile(path):
    raise ValueError(f'{path}: no calibration to check (experiments/calibrate.py)')
  # the estimates apply the tables being checked
  config = dataclasses.replace(
    config, estimate=config.estimate.replace(calibration=path)
  )
  shipped = recording_lib.read_json(path)
  if shipped.get('config', {}).get('seed') == config.seed:
    raise ValueError(
      f"seed {config.seed} is the calibration's own ({path}): its recordings "
      'are not held out; pass another --seed'
    )
  return config, path, shipped


def _write(out: dict, workdir: str) -> None:
  """Writes a check's ``check.json``, ``check.md`` and ``check_ranks.png``, and
  prints its table."""
  files.write_json(os.path.join(workdir, CHECK_FILE), out)
  text = check_table(out)
  files.write_text(os.path.join(workdir, 'check.md'), text + '\n')
  plot_ranks(
    out['modes'], os.path.join(workdir, 'check_ranks.png'),
    key='recalibrated_rank_histogram', xlabel='rank, recalibrated',
  )  # fmt: skip
  print(text)


def check_record(out: dict) -> dict:
  """What a calibration file keeps of a check (``check``'s ``out``, e.g. read
  from its ``check.json``), for estimates to quote beside the calibration's
  own coverage: the recordings' physics, seed and count, and per mode and
  quantity how often the 50% and 90% intervals held the truth (those the
  estimates printed as the video's, read from their own files)."""
  modes = {m: coverage_of(v) for m, v in out['modes'].items()}
  printed_mode = out.get('printed_mode', 'video')
  if out.get('printed'):
    modes[printed_mode] = {
      f: {c: out['printed'][f][c] for c in ('interval_50', 'interval_90')}
      for f in FIELDS
    }
  return {
    'physics': out.get('physics', 'own'),
    'seed': out['seed'],
    # the mode whose searches were steered by a reading (else 'video')
    'searched': printed_mode,
    'n': out['n'],
    'setting': out['shipped']['setting'],
    'coverage': modes,
  }


def _pct_ci(cell: dict, lv: int) -> str:
  lo, hi = cell[f'interval_{lv}_ci']
  return f'{100 * cell[f"interval_{lv}"]:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}]'


def _seeds(out: dict) -> str:
  """The checked networks' seeds, those the calibration never saw marked."""
  distance = out['config'].get('estimate', {}).get('distance', 'energy')
  if distance not in objective_lib.EMBEDDING_DISTANCES:
    return 'none'
  seeds = (out.get('network') or {}).get('seeds') or [out['config']['network_seed']]
  held = set(out.get('held_out_networks', []))
  return ', '.join(f'{s}{" (held out)" if s in held else ""}' for s in seeds)


def check_table(out: dict) -> str:
  """Markdown: per mode and quantity, how often the 50% and 90% intervals held
  the truth on the new recordings (95% binomial intervals in brackets), how
  often the prior's own central intervals held these truths (what an interval
  that knows nothing scores here: the luck of the draw), what the
  calibration's own cross-fitted coverage promised, and the mean error of the
  point beside the range centre's; the estimates' printed intervals first;
  then the 90% intervals network by network."""
  sh, pr = out['shipped'], out['printed']
  lines = [
    f'Calibration checked: {sh["setting"]} (sharpness {sh["sharpness"]:g}, '
    f'{sh["n"]} calibration recordings) on {out["n"]} recordings it never saw '
    f'(seed {out["seed"]}; {out.get("physics", "own")} physics; networks '
    f'{_seeds(out)})'
    + (
      f'; {pr["recalibrated"]} of {pr["n"]} estimates applied its tables'
      if pr
      else ' (read from packed posteriors: what the estimates printed is not here)'
    )
    + '. Brackets: 95% binomial intervals. '
    "The prior's own: how often the prior's central 50%/90% intervals held "
    'the same truths.',
    '',
    '| mode | quantity | 50% hold the truth | 90% hold the truth | '
    "the prior's own | promised (cross-fitted) | mean error: point | range centre |",
    '|---|---|---|---|---|---|---|---|',
  ]
  lines += _mode_rows(out)
  lines += _miss_lines(out)
  mode = out.get('printed_mode', 'video')
  lines += _material_lines(pr, mode)
  lines += _network_lines(out['modes'].get(mode, {}), mode)
  return '\n'.join(lines)


def _prior_cell(cell: dict) -> str:
  """How often the prior's own 50% / 90% intervals held the truths."""
  if 'prior_interval_90' not in cell:
    return '-'
  return (
    f'{100 * cell["prior_interval_50"]:.0f}% / {100 * cell["prior_interval_90"]:.0f}%'
  )


def _mode_rows(out: dict) -> list[str]:
  """``check_table``'s rows: the estimates' printed intervals (where read),
  then every mode's read from the saved posteriors."""
  sh, pr = out['shipped'], out['printed']
  promised = lambda m, f: (
    pair_text(sh['held_out'][m][f]) if f in sh['held_out'].get(m, {}) else '-'
  )
  mode = out.get('printed_mode', 'video')
  video = out['modes'].get(mode, {})
  lines = []
  for f in FIELDS if pr else ():
    c = pr[f]
    lines.append(
      f'| {mode}, as printed | {f} | {_pct_ci(c, 50)} | {_pct_ci(c, 90)} | '
      f'{_prior_cell(video.get(f, {}))} | {promised(mode, f)} | '
      f'{error_text(f, c["estimate_error"])} | {error_text(f, c["range_centre_error"])} |'
    )
  for mode, s in out['modes'].items():
    for f in FIELDS:
      c = s[f]
      key = 'factor' if f == 'bending_scale' else 'pct'
      lines.append(
        f'| {mode} | {f} | {_pct_ci(c, 50)} | {_pct_ci(c, 90)} | {_prior_cell(c)} | '
        f'{promised(mode, f)} | {error_text(f, c["point_error_" + key])} | '
        f'{error_text(f, c["centre_error_" + key])} |'
      )
  return lines


def _miss_lines(out: dict) -> list[str]:
  """The confident wind misses, as printed and per mode as read again."""
  pr, lines = out['printed'], []
  if pr and 'confident_misses' in pr:
    misses = pr['confident_misses']
    lines += [
      '',
      f'Wind off by more than {CONFIDENT_MISS_PCT:g}% with the truth outside its 90% '
      f'interval, as printed: {len(misses)} of {pr["n"]}'
      + ''.join(
        f'; {m["material"]} ({os.path.basename(m["recording"].rstrip("/"))}): '
        f'{m["wind_error_pct"]:.1f}% off, [{m["interval_90"][0]:.2f}, '
        f'{m["interval_90"][1]:.2f}] against {m["truth"]:.2f} m/s'
        for m in misses
      ),
    ]
  conf = [
    (m, s['wind_speed']) for m, s in out['modes'].items()
    if 'confident_misses' in s.get('wind_speed', {})
  ]  # fmt: skip
  if conf:
    lines += [
      '',
      f'Wind off by more than {CONFIDENT_MISS_PCT:g}% outside its 90% interval, '
      'each mode read again from the saved posteriors, beside how many the '
      'posteriors themselves expect (calibrated intervals expect some): '
      + '; '.join(
        f'{m} {c["confident_misses"]} ({c["confident_misses_expected"]:.1f})'
        for m, c in conf
      ),
    ]
  return lines


def _material_lines(pr: dict | None, mode: str) -> list[str]:
  """The printed intervals fabric by fabric (a check of several)."""
  per = (pr or {}).get('per_material')
  if not per:
    return []
  lines = [
    '',
    f'{mode.capitalize()}, as printed, fabric by fabric (50% / 90% intervals '
    'that held the truth; each pair shares bending and area weight):',
    '',
    '| fabric | recordings | ' + ' | '.join(FIELDS) + ' | mean error: wind |',
    '|---|---:|' + '---|' * (len(FIELDS) + 1),
  ]
  for m, c in per.items():
    lines.append(
      f'| {m} | {c["n"]} | ' + ' | '.join(pair_text(c[f]) for f in FIELDS)
      + f' | {error_text("wind_speed", c["wind_speed"]["estimate_error"])} |'
    )  # fmt: skip
  return lines


def _network_lines(video: dict, mode: str) -> list[str]:
  """The printed mode's intervals network by network (several networks)."""
  nets = video.get('per_network', {})
  if len(nets) <= 1:
    return []
  lines = [
    '',
    f'{mode.capitalize()}, network by network (50% / 90% intervals that held '
    'the truth):',
    '',
    '| network seed | recordings | ' + ' | '.join(FIELDS) + ' |',
    '|---|---:|' + '---|' * len(FIELDS),
  ]
  for seed, c in nets.items():
    lines.append(
      f'| {seed} | {c["n"]} | ' + ' | '.join(pair_text(c[f]) for f in FIELDS) + ' |'
    )
  return lines
