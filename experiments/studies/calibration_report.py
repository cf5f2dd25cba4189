"""The calibration study's report: ``calibration.json``'s record, its markdown
table and the figures (rank histograms, the sharpness sweep)."""

from __future__ import annotations

import functools
import math

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import bo  # noqa: E402
from experiments.pipeline import carried_errors, files  # noqa: E402
from experiments.studies.calibration_analysis import coverage_of  # noqa: E402
from experiments.studies.calibration_config import (  # noqa: E402
  FIELDS,
  MODES,
  Config,
  estimate_record,
  intake_errors,
  length_sd_range,
  study_configs,
  study_materials,
  uses_networks,
)
from experiments.studies.calibration_scores import LOG_FIELDS  # noqa: E402


def result(config: Config, analysis: dict, seconds: float = 0.0,
           network: dict | None = None) -> dict:  # fmt: skip
  """What ``calibration.json`` holds: the chosen likelihood setting, its
  recalibration tables (what estimates apply), the cross-fitted coverage
  with them (what estimates quote), the coverage without them, and the
  networks (``networks_record``: estimates apply the tables only with a
  network of their recipe; None: not recorded, not checked)."""
  form, c = 'gibbs', analysis['best_sharpness']['gibbs']
  chosen = analysis['sweep'][form][c]
  held, raw = analysis['cross_validated'][form], chosen['uncalibrated']
  mats = study_materials(config)
  return {
    'material': mats[0],
    **({'materials': list(mats)} if len(mats) > 1 else {}),
    'size': config.size,
    'n': held['video'].get('n', 0),
    'setting': f'{form} likelihood, sharpness {c:g}, '
    + (f'model error {e:g}, ' if (e := config.estimate.scoring.model_error) else '')
    + (f'{len(mats)} fabrics' if len(mats) > 1 else mats[0])
    + f', {config.size} size, '
    + _networks_text(config)
    + (f', recordings of {config.physics} physics' if config.physics != 'own' else '')
    + _camera_text(config)
    + (', levels centred on the median' if config.centred_levels else ''),
    'likelihood': form,
    'sharpness': c,
    'model_error': config.estimate.scoring.model_error,
    'coverage': coverage_of(held['video']),
    'coverage_uncalibrated': coverage_of(raw['video']),
    'recalibration': {
      'probs': list(bo.calibration.PROBS),
      'fields': list(FIELDS),
      'modes': chosen['recalibration'],
      'weights': chosen['weights'],
      'n_calibration_recordings': raw['video'].get('n', 0),
      'measured_sd': config.measured_sd,
      'length_sd': config.length_sd,
      'length_sd_spread': config.length_sd_spread,
      'length_sd_range': list(length_sd_range(config)),
      'length_dof': config.length_dof,
    },
    'held_out': held,
    'held_out_uncalibrated': raw,
    **({'network': network} if network else {}),
    'analysis': analysis,
    # the settings the searches ran with (the demo's cloth and clock), which
    # an estimate must share for these tables to apply
    'config': estimate_record(config, study_configs(config)[3]),
    'seconds': seconds,
  }


def _camera_text(config: Config) -> str:
  """The camera error the study's estimates carried and its recordings'
  cameras had (``told_pose``), for ``calibration.json``'s setting; '' for
  cameras known exactly."""
  sd = carried_errors.camera_of(config.estimate.flat())
  if not any(sd):
    return ''
  words = carried_errors.table_words((*sd, config.camera_sd_spread))
  if config.rig_runs:
    return (
      ", taken in through the intake from a user's rig (benchmarks.windy_rig), "
      f"each estimate carrying its intake's claim (claims {words})"
    )
  if config.camera_errors:
    return (
      f', cameras off as {len(intake_errors(tuple(config.camera_errors)))} measured '
      f"intakes erred, each estimate carrying its intake's claim (claims {words})"
    )
  each = ', each recording its own' if config.camera_sd_spread else ''
  return f', cameras off by {words} (1 sd{each})'


def _networks_text(config: Config) -> str:
  """The study's networks in words, for ``calibration.json``'s setting."""
  if not uses_networks(config):
    return f'{config.estimate.scoring.distance} distance, no network'
  n = config.networks
  return f'network{"s" if n > 1 else ""} of {config.sequences} training sequences' + (
    f' ({n} seeds)' if n > 1 else ''
  )


def pair_text(cell: dict) -> str:
  """A quantity's 50% / 90% coverage, in percent."""
  return f'{100 * cell["interval_50"]:.0f}% / {100 * cell["interval_90"]:.0f}%'


def error_text(f: str, v: float) -> str:
  """A mean error as the tables print it: bending a factor, the rest percent."""
  return f'x{v:.2f}' if f == 'bending_scale' else f'{v:.1f}%'


def _cell(s: dict, raw: dict, f: str) -> str:
  if not s:
    return '- | - | - | - | - | - | - | - | -'
  fmt = functools.partial(error_text, f)
  key = 'factor' if f == 'bending_scale' else 'pct'
  err = (f'{fmt(s[f].get("point_error_" + key, float("nan")))} (weight '
         f'{s[f].get("weight", float("nan")):.2f}) | {fmt(s[f]["median_error_" + key])} | '
         f'{fmt(raw[f]["median_error_" + key])} | '
         f'{fmt(s[f].get("prior_point_error_" + key, float("nan")))} | '
         f'{fmt(s[f]["centre_error_" + key])}')  # fmt: skip
  width = raw[f].get('width_ratio')
  width = '-' if width is None else f'{width:.2f}'
  return f'{pair_text(s[f])} | {pair_text(raw[f])} | {err} | {raw[f]["rank_chi2"]:.1f} | {width}'


def table(out: dict) -> str:
  """Markdown: per mode and field, coverage of the 50% / 90% intervals with
  the recalibration and without; the mean error (percent; bending as the
  factor exp|log(est / true)|) of the estimate's point (the least-error point
  moved towards the prior's own by the weight, cross-fitted), of the
  recalibrated and the uncalibrated median, of the prior's own point and of
  the range centre; the uncalibrated ranks' chi^2 (9 dof; above 21.7
  rejects uniform ranks at 1%); and the median width of the posterior's 90%
  intervals over the prior's (at or above ``bo.calibration.UNINFORMED``, the
  video does not inform the quantity and its nominal levels are kept)."""
  rc = out['recalibration']
  lines = [
    f'{"Rig" if out.get("config", {}).get("rig_runs") else "Simulated"} '
    f'recordings: {out["n"]} ({out["setting"]}); each read with the '
    f'sharpness and levels chosen on the other {out["analysis"]["folds"] - 1} of '
    f'{out["analysis"]["folds"]} folds (by pairs); the shipped tables use all '
    f'{rc["n_calibration_recordings"]}',
    '',
    '| mode | parameter | 50% / 90% hold the truth, recalibrated (held out) | '
    'uncalibrated | mean error: point (weight) | recalibrated median | '
    "uncalibrated median | prior's point | range centre | rank chi^2 | "
    'width / prior |',
    '|---|---|---|---|---|---|---|---|---|---|---|',
  ]
  for mode, s in out['held_out'].items():
    for f in FIELDS:
      lines.append(
        f'| {mode} | {f} | {_cell(s, out["held_out_uncalibrated"][mode], f)} |'
      )
  lines += _half_width_line(out['held_out'].get('video', {}))
  a = out['analysis']
  lines += ['', 'sharpness chosen on all recordings (best recalibrated interval '
            'score): ' + ', '.join(f'{k} {v:g}' for k, v in a['best_sharpness'].items())
            + '; per fold (gibbs): '
            + ', '.join(f'{v:g}' for v in a['fold_sharpness']['gibbs'])
            + '; the sharpest never under-covering uncalibrated: '
            + ', '.join(f'{k} {v:g}' for k, v in
                        a['sharpest_never_under_covering'].items())]  # fmt: skip
  lines += network_lines(out.get('network'), a)
  lines += _material_lines(a)
  lines += _group_lines(
    a.get('cross_validated_by_camera_error', {}).get('gibbs'),
    'camera error',
    "recordings by the camera error each carried (the mean of its shift's and "
    "tilt's place in their ranges), video alone, held out",
  )
  lines += _group_lines(
    a.get('cross_validated_by_wind', {}).get('gibbs'),
    'true wind',
    'recordings by where their wind lies in its prior (thirds of its range), '
    'video alone, held out',
  )
  return '\n'.join(lines)


def _half_width_line(video: dict) -> list[str]:
  """The video's held-out 50% intervals' median half-width over their median,
  per field (none in files from before it was measured)."""
  widths = {
    f: video[f]['half_width_50'] for f in FIELDS if 'half_width_50' in video.get(f, {})
  }
  if not widths:
    return []
  words = [
    f'{f} x{math.exp(w):.2f}' if f in LOG_FIELDS else f'{f} {100 * w:.1f}%'
    for f, w in widths.items()
  ]
  return ['', "the video's 50% intervals, held out: median half-width "
          + ', '.join(words) + ' of the median (a factor for a log-scaled one)']  # fmt: skip


def _material_lines(analysis: dict) -> list[str]:
  """Per fabric of a study of several: its recordings' held-out coverage
  (video alone, read with the pooled tables of the other folds) and its
  point's mean error beside the range centre's."""
  return _group_lines(
    analysis.get('cross_validated_by_material', {}).get('gibbs'),
    'fabric',
    "each fabric's recordings, video alone, held out",
  )


def _group_lines(by: dict | None, name: str, title: str) -> list[str]:
  """A table of groups of recordings (``by``: group -> summary): each group's
  held-out coverage and its point's mean error beside the range centre's."""
  if not by:
    return []
  lines = ['', f"{title} (50% / 90% hold the truth; the point's mean error, range "
           "centre's in brackets):", '',
           f'| {name} | n | ' + ' | '.join(FIELDS) + ' |',
           '|---' * (len(FIELDS) + 2) + '|']  # fmt: skip
  for m, sm in by.items():
    if not sm:
      continue
    cells = []
    for f in FIELDS:
      key = 'factor' if f == 'bending_scale' else 'pct'
      err = sm[f].get(f'point_error_{key}', sm[f][f'median_error_{key}'])
      cells.append(
        f'{pair_text(sm[f])}; {error_text(f, err)} ({error_text(f, sm[f][f"centre_error_{key}"])})'
      )
    lines.append(f'| {m} | {sm["n"]} | ' + ' | '.join(cells) + ' |')
  return lines


def network_lines(network: dict | None, analysis: dict) -> list[str]:
  """The networks' seeds and triplet accuracies, and (one fold per network)
  each fold's video coverage, recalibrated on the other networks."""
  if not network:
    return []
  seeds, acc = network['seeds'], network['triplet_accuracy']
  lines = ['', 'networks (seed: held-out triplet accuracy): ' + ', '.join(
    f'{s}: {"-" if a is None else f"{100 * a:.0f}%"}'
    for s, a in zip(seeds, acc, strict=True)
  )]  # fmt: skip
  folds = analysis.get('cross_validated_by_fold', {}).get('gibbs')
  if folds and len(folds) == len(seeds):
    lines += ['', "each network's recordings, read with the tables of the others "
              '(video alone; 50% / 90% hold the truth):', '',
              '| network seed | ' + ' | '.join(FIELDS) + ' |',
              '|---' * (len(FIELDS) + 1) + '|']  # fmt: skip
    for seed, cov in zip(seeds, folds, strict=True):
      cells = ' | '.join(pair_text(cov[f]) if f in cov else '-' for f in FIELDS)
      lines.append(f'| {seed} | {cells} |')
  return lines


def plot_ranks(
  held: dict, path: str, key: str = 'rank_histogram', xlabel: str = 'rank of the truth'
) -> None:
  """Rank histograms of the truth (``key`` of each summary: among the posterior's
  draws, or under the recalibrated distribution; uniform: calibrated)."""
  fig, axes = plt.subplots(len(MODES), len(FIELDS), figsize=(14, 2.4 * len(MODES)),
                           layout='constrained', squeeze=False)  # fmt: skip
  for r, mode in enumerate(MODES):
    for c, f in enumerate(FIELDS):
      ax = axes[r, c]
      s = held.get(mode, {})
      if not s:
        ax.axis('off')
        continue
      h = s[f][key]
      ax.bar(np.arange(10) / 10 + 0.05, h, width=0.09, color='C0')
      ax.axhline(s['n'] / 10, color='k', lw=1, ls='--')
      ax.set(xlim=(0, 1), title=f'{mode}: {f}', xlabel=xlabel)
      ax.title.set_fontsize(8)
  files.savefig(fig, path, dpi=80)
  plt.close(fig)


def plot_sweep(analysis: dict, path: str) -> None:
  """Against the sharpness, per likelihood, over every recording (video
  alone): the uncalibrated intervals' coverage (top) and the recalibrated
  intervals' score (bottom; the chosen sharpness has the lowest mean)."""
  forms = list(analysis['sweep'])
  fig, axes = plt.subplots(2, len(forms), figsize=(6 * len(forms), 7),
                           layout='constrained', squeeze=False)  # fmt: skip
  for k, form in enumerate(forms):
    by_c = analysis['sweep'][form]
    cs = sorted(by_c)
    top, bottom = axes[0, k], axes[1, k]
    for i, f in enumerate(FIELDS):
      for lv, ls in ((50, '--'), (90, '-')):
        y = [by_c[c]['uncalibrated']['video'].get(f, {}).get(f'interval_{lv}', np.nan)
             for c in cs]  # fmt: skip
        top.plot(cs, y, ls, color=f'C{i}', label=f'{f} {lv}%' if lv == 90 else None)
        y = [by_c[c]['recalibrated_in_sample']['video'].get(f, {})
             .get(f'interval_score_{lv}', np.nan) for c in cs]  # fmt: skip
        bottom.plot(cs, y, ls, color=f'C{i}', label=f'{f} {lv}%' if lv == 90 else None)
    for lv in (0.5, 0.9):
      top.axhline(lv, color='k', lw=0.8)
    for ax in (top, bottom):
      ax.axvline(analysis['best_sharpness'][form], color='r', lw=1)
      ax.set(xscale='log', xlabel='sharpness')
      ax.legend(fontsize=7)
    top.set(ylabel='coverage (solid 90%, dashed 50%)',
            title=f'{form} likelihood, uncalibrated')  # fmt: skip
    bottom.set(ylabel='interval score / prior extent (lower: better)',
               title='recalibrated (red: chosen)')  # fmt: skip
  files.savefig(fig, path, dpi=80)
  plt.close(fig)
