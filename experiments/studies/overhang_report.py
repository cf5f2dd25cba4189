"""What a run of the overhang set-ups reports: its summary (the readings'
errors and coverage, the law fitted to them, the protocol sets' joint
estimates), its figures, the compact results file kept in the tree and the
table printed.
"""

from __future__ import annotations

import matplotlib
import numpy as np
import scipy.stats

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from experiments.pipeline import files  # noqa: E402
from experiments.pipeline import posterior as posterior_lib  # noqa: E402
from experiments.studies.overhang_law import (  # noqa: E402
  SHORT_C,
  by_length,
  fitted_law,
  held,
)
from physsim import cantilever  # noqa: E402


def summary(rows: list[dict], sets: list[dict], dof: float) -> dict:
  """A run's numbers: the readings' errors and how often their intervals
  (a t of ``dof``) held c, the law fitted to them, the same by bending
  length, and per protocol set and reading ('raw', 'printed') the joint
  estimates' errors, narrowing and coverage."""
  ok = [r for r in rows if 'c_hat' in r]
  err = np.array([r['error'] for r in ok])
  out = {
    'setups': len(rows),
    'refused': len(rows) - len(ok),
    'c_mean_abs_error': float(np.mean(np.abs(err))) if len(ok) else None,
    'c_median_abs_error': float(np.median(np.abs(err))) if len(ok) else None,
    'c_bias': float(np.mean(err)) if len(ok) else None,
    'c_held_90': held(ok, 0.9, dof) if len(ok) else None,
    'c_held_50': held(ok, 0.5, dof) if len(ok) else None,
    'fitted_law': dict(zip(('dof', 'floor'), fitted_law(ok), strict=True))
    if len(ok)
    else None,
    'by_length': by_length(rows, dof),
  }
  for mode in sets[0]['joint'] if sets else ():
    for how in ('raw', 'printed'):
      m = [s['joint'][mode][how] for s in sets if how in s['joint'].get(mode, {})]
      if not m:
        continue
      out[f'{mode} ({how})'] = {
        'sets': len(m),
        'bending_median_factor': float(np.median([x['bending_scale']['error'] for x in m])),
        'bending_narrowing_90_median': float(
          np.median([x['bending_scale']['narrowing_90'] for x in m])
        ),
        'area_weight_mean_pct': 100 * float(np.mean([x['area_weight']['error'] for x in m])),
        'wind_mean_pct': 100 * float(np.mean([x['wind_speed']['error'] for x in m])),
        **{
          f'{f}_held_{lv}': float(np.mean([x[f][f'held_{lv}'] for x in m]))
          for f in posterior_lib.FIELDS for lv in (90, 50)
        },
      }  # fmt: skip
  return out


def plot(rows: list[dict], example: dict | None, path: str) -> None:
  """The readings' errors with their 90% intervals against c, beside one
  set-up's strip pixels with the fitted and the true elastica
  (``example``; none for a re-read, which keeps no pixels)."""
  ok = [r for r in rows if 'c_hat' in r]
  # a re-read (``--readings``) keeps no pixels: the errors alone
  fig, ax = (
    plt.subplots(1, 2, figsize=(11, 4.2))
    if example
    else plt.subplots(1, 1, figsize=(6, 4.2))
  )
  ax = ax if example else [None, ax]
  if example is not None:
    prof = np.asarray(example['profile'])
    ax[0].plot(100 * prof[:, 0], -100 * prof[:, 1], '.', ms=1.5, alpha=0.4,
               label='strip pixels (five frames, median)')  # fmt: skip
    r = example['read']
    line = cantilever.shape(r['ratio']) * r['overhang']
    ax[0].plot(100 * line[:, 0], -100 * line[:, 1], 'r-', lw=1.5,
               label=f'fitted elastica, c = {100 * r["bending_length"]:.2f} cm')  # fmt: skip
    true = cantilever.shape(example['setup']['strip']['overhang'] / example['c'])
    true = true * example['setup']['strip']['overhang']
    ax[0].plot(100 * true[:, 0], -100 * true[:, 1], 'k--', lw=1,
               label=f'truth, c = {100 * example["c"]:.2f} cm')  # fmt: skip
    ax[0].axhline(0, color='0.6', lw=0.8)
    ax[0].axvline(0, color='0.6', lw=0.8)
    ax[0].set_aspect('equal')
    ax[0].set_xlabel('out from the edge (cm)')
    ax[0].set_ylabel('height above the table (cm)')
    ax[0].legend(fontsize=7, loc='lower left')
    ax[0].set_title('one set-up: what the reader sees and fits', fontsize=9)
  c = np.array([r['c'] for r in ok])
  e = np.array([r['error'] for r in ok])
  sd = np.array([r['scale'] / r['c_hat'] for r in ok])
  k = np.array([scipy.stats.t.ppf(0.95, r['dof']) for r in ok])
  ax[1].errorbar(100 * c, 100 * e, yerr=100 * k * sd, fmt='o', ms=3, lw=0.8)
  ax[1].axhline(0, color='k', lw=0.8)
  ax[1].set_xlabel('true bending length c (cm)')
  ax[1].set_ylabel('error of c (%), with its 90% interval')
  ax[1].set_title(f'{len(ok)} set-ups the reader was not fitted to', fontsize=9)
  fig.tight_layout()
  files.savefig(fig, path, dpi=110)
  plt.close(fig)


def plot_sets(sets: list[dict], path: str) -> None:
  """The protocol sets as printed (else raw): per set the truth against the
  point and its 90% interval, bending (log) and area weight, with the sheet
  and anemometer alone beside the sheet, anemometer and overhang; an interval
  that misses the truth in red."""
  modes = ('sheet, anemometer', 'sheet, anemometer, overhang')
  fig, ax = plt.subplots(1, 3, figsize=(13, 4.2))
  panels = [(ax[0], modes[0], 'bending_scale'), (ax[1], modes[1], 'bending_scale'),
            (ax[2], modes[1], 'area_weight')]  # fmt: skip
  for a, mode, f in panels:
    mine = [s for s in sets if mode in s['joint']]
    rows = [s['joint'][mode] for s in mine]
    how = 'printed' if rows and 'printed' in rows[0] else 'raw'
    truth = np.array([s['truth'][f] for s in mine])
    point = np.array([r[how][f]['point'] for r in rows])
    lo, hi = (np.array([r[how][f]['interval_90'][k] for r in rows]) for k in (0, 1))
    held = np.array([r[how][f]['held_90'] for r in rows])
    for mask, colour in ((held, 'C0'), (~held, 'C3')):
      a.errorbar(truth[mask], point[mask],
                 yerr=[point[mask] - lo[mask], hi[mask] - point[mask]],
                 fmt='o', ms=3, lw=0.7, color=colour)  # fmt: skip
    span = [min(truth.min(), lo.min()), max(truth.max(), hi.max())]
    a.plot(span, span, 'k--', lw=0.8)
    if f == 'bending_scale':
      a.set_xscale('log')
      a.set_yscale('log')
    name = (
      'bending (x its reference)' if f == 'bending_scale' else 'area weight (kg/m^2)'
    )
    a.set_xlabel(f'true {name}')
    a.set_ylabel(f'point and 90% interval ({how})')
    a.set_title(f'{mode}: {int(held.sum())} of {len(held)} intervals hold', fontsize=9)
  fig.tight_layout()
  files.savefig(fig, path, dpi=100)
  plt.close(fig)


_ROW_KEYS = ('c', 'c_hat', 'sd', 'dof', 'error', 'z', 'told_overhang', 'refused')


def compact(out: dict) -> dict:
  """What a results file keeps of a run (``summary.json``, a few tens of
  KB): the summary, each reading with its fit's spread (so that it can be
  read again under another law: ``--readings``), and each protocol set as
  printed (the raw reading's summary stays; ``plot_sets`` draws it); the
  readings to 7 digits (their
  errors are differences of nearby numbers), the rest to 4."""

  def r4(x, digits=4):
    if isinstance(x, float):
      return float(f'{x:.{digits}g}')
    if isinstance(x, dict):
      return {k: r4(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
      return [r4(v, digits) for v in x]
    return x

  rows = []
  for r in out['rows']:
    row = {k: r[k] for k in _ROW_KEYS if k in r}
    if 'read' in r:
      row['read'] = {'fit_sd': r['read']['fit_sd']}
    rows.append(r4(row, 7))
  # per set and field: the point, its 90% interval and which intervals held
  # (its error and narrowing follow from them and the summary)
  cell = lambda c: {k: c[k] for k in ('point', 'interval_90', 'held_90', 'held_50')}
  sets = [
    {**{k: s[k] for k in ('seq', 'material', 'truth')},
     'joint': {m: {h: {f: cell(c) for f, c in v.items()} for h, v in by.items()
                   if h == 'printed' or len(by) == 1}
               for m, by in s['joint'].items()}}
    for s in out['sets']
  ]  # fmt: skip
  keep = ('args', 'floor', 'dof', 'summary')
  return {**r4({k: out[k] for k in keep}), 'rows': rows, 'sets': r4(sets)}


def table(out: dict) -> str:
  """A run's summary as printed: the readings' table (BENCHMARKS cites it),
  the bending lengths by group and each protocol set's line."""
  s = out['summary']
  lines = [
    '| set-ups | refused | c mean error | median | bias | 90% held | 50% held | law (dof, floor) | fitted here |',
    '|---|---|---|---|---|---|---|---|---|',
    f'| {s["setups"]} | {s["refused"]} | {100 * s["c_mean_abs_error"]:.1f}% | '
    f'{100 * s["c_median_abs_error"]:.1f}% | {100 * s["c_bias"]:+.1f}% | '
    f'{100 * s["c_held_90"]:.0f}% | {100 * s["c_held_50"]:.0f}% | '
    f'{out["dof"]:g}, {100 * out["floor"]:.1f}% | '
    f'{s["fitted_law"]["dof"]:g}, {100 * s["fitted_law"]["floor"]:.1f}% |',
  ]
  for name, g in s.get('by_length', {}).items():
    if g['readings']:
      lines.append(
        f'{name} bending lengths ({"<" if name == "short" else ">="} '
        f'{100 * SHORT_C:g} cm): {g["readings"]} readings, mean error '
        f'{100 * g["mean_abs_error"]:.1f}%, 90% / 50% held {100 * g["held_90"]:.0f}% / '
        f'{100 * g["held_50"]:.0f}%'
      )
  for mode in [k for k in s if k.startswith('sheet')]:
    m = s[mode]
    lines += [
      '',
      f'{mode} ({m["sets"]} sets): bending median factor x{m["bending_median_factor"]:.3f}, '
      f'its 90% interval x{m["bending_narrowing_90_median"]:.1f} narrower than the prior\'s '
      f'(median); area weight {m["area_weight_mean_pct"]:.1f}%, wind {m["wind_mean_pct"]:.1f}%',
      '  held 90% / 50%: ' + ', '.join(
        f'{f} {100 * m[f"{f}_held_90"]:.0f}% / {100 * m[f"{f}_held_50"]:.0f}%'
        for f in posterior_lib.FIELDS
      ),
    ]  # fmt: skip
  return '\n'.join(lines)
