"""The posterior's figure (``posterior.png``): marginals over the prior, and pairs.

Drawing only: ``posterior.plot`` reads the draws into physical values and
their summaries (``posterior.summarise``'s, what the table prints); this
module lays them out, one row of marginals (bending, wind, area weight, load
ratio) over the prior's, one of pairs (wind x area weight with the load
ratio's iso-lines: the ridge the video measures; bending x wind; bending x
area weight) and a key. A person reads the figure beside the table, so it
draws in the table's units where it is given them (issue 76: ``units.in_units``,
bending rigidity in uN m, area weight in g/m^2), else in the search's scales.
"""

from __future__ import annotations

import numpy as np

import physsim
from experiments.pipeline import files
from experiments.pipeline.measurements import FIELDS

LABELS = {
  'bending_scale': 'bending (x measured)',
  'wind_speed': 'wind speed (m/s)',
  'area_weight': 'area weight (kg/m$^2$)',
  'load_ratio': r'load ratio $\rho v^2/(w g)$',
}
NAMES = (*FIELDS, 'load_ratio')  # the marginals, left to right
PAIRS = ((1, 2), (0, 1), (0, 2))  # of FIELDS, (x, y), left to right
KEY = (
  'grey: prior (the search box, times any\nmeasured wind or area weight)\n'
  'blue: posterior given the video\n'
  "white dashes: the load ratio's median\nand 90% interval (iso-lines)\n"
  'white x: the point; black line: the point\nwhere it is not the median\n'
  'red: truth (simulated recordings)'
)


def draw(post: dict, prior: dict, stats: dict, truth: dict | None, bounds,
         log_scaled, point: str = 'median', title: str = '',
         units: tuple[dict, dict] | None = None):  # fmt: skip
  """The figure (matplotlib, not saved) of posterior draws over the prior's.

  Args:
    post, prior: ``{name: (S,) values}`` per name of ``NAMES``, in the
      search's scales (bending scale, m/s, kg/m^2).
    stats: ``{name: summary}`` per name (``posterior._stats``'s: median,
      50% and 90% intervals and ``point``'s value where it has one), the same.
    truth: ``{name: value}`` per name, or None; the same.
    bounds: (3, 2) the search box per field; the same.
    log_scaled: the names drawn on a log scale.
    point: the summary's key of the point marked ('median' or 'bayes').
    title: above the figure ('': none).
    units: ``(names, factors)`` from the search's scales to the units drawn
      in (``units.in_units``: the table's); None: the search's own (``LABELS``).
  """
  labels, k = _units(units)
  post, prior, truth = _scaled(post, k), _scaled(prior, k), _scaled(truth, k)
  stats = {name: _scaled_summary(stats[name], k[name]) for name in NAMES}
  bounds = np.asarray(bounds) * np.array([k[f] for f in FIELDS])[:, None]
  plt = files.pyplot()
  fig, axes = plt.subplots(2, 4, figsize=(17, 7.4), layout='constrained')
  for j, (ax, name) in enumerate(zip(axes[0], NAMES, strict=True)):
    _marginal(ax, post[name], prior[name], stats[name], truth, name, name in log_scaled,
              point, labels[name])  # fmt: skip
    if j == 0:  # above the panel: the histogram's bars stay in view
      ax.legend(fontsize=7, loc='lower left', bbox_to_anchor=(0, 1.02), ncol=3,
                frameon=False)  # fmt: skip
  for ax, (i, j) in zip(axes[1], PAIRS, strict=False):
    _pair(ax, post, stats, truth, bounds, FIELDS[i], FIELDS[j], point, labels, k)
  axes[1, 3].axis('off')
  axes[1, 3].text(0.0, 0.9, KEY, va='top', fontsize=9)
  if title:
    fig.suptitle(title)
  return fig


def _units(units: tuple[dict, dict] | None) -> tuple[dict, dict]:
  """(axis labels, factors) per name of ``NAMES``: the fields' names and
  factors of ``units`` (``draw``'s), the load ratio's its own (a ratio has no
  unit: its formula names it); without ``units`` ``LABELS`` and 1."""
  if units is None:
    return LABELS, dict.fromkeys(NAMES, 1.0)
  names, factors = units
  return (
    {**LABELS, **{f: names[f] for f in FIELDS}},
    {name: float(factors.get(name, 1.0)) for name in NAMES},
  )


def _scaled(values: dict | None, k: dict) -> dict | None:
  """``{name: value}`` (values or arrays) times each name's factor ``k``."""
  return None if values is None else {name: k[name] * values[name] for name in NAMES}


def _scaled_summary(s: dict, k: float) -> dict:
  """A summary with its values (median, point, intervals) times ``k``; its
  ratios (narrowing, weight) as they are."""
  out = dict(s)
  for key in ('median', 'bayes', 'std'):
    if key in s:
      out[key] = k * s[key]
  for key in ('interval_50', 'interval_90'):
    out[key] = [k * v for v in s[key]]
  return out


def _marginal(ax, x, px, s: dict, truth: dict | None, name: str, log: bool,
              point: str, label: str) -> None:  # fmt: skip
  """One marginal: the draws ``x`` over the prior's ``px`` (probability per
  bin, bins equal in the plotted scale: a log-uniform prior is flat on a log
  axis), the summary ``s``'s median and intervals, the point where it is not
  the median, the truth."""
  lo, hi = np.quantile(np.concatenate([x, px]), [0.001, 0.999])
  bins = np.geomspace(lo, hi, 40) if log else np.linspace(lo, hi, 40)
  ax.hist(px, bins=bins, weights=np.full(len(px), 1 / len(px)), color='0.85',
          label='prior')  # fmt: skip
  ax.hist(x, bins=bins, weights=np.full(len(x), 1 / len(x)), alpha=0.75,
          color='C0', label='posterior')  # fmt: skip
  for level, ls in ((90, ':'), (50, '--')):
    for v in s[f'interval_{level}']:
      ax.axvline(v, color='C0', ls=ls, lw=1)
  ax.axvline(s['median'], color='C0', lw=1.5, label='median; 50%, 90%')
  if point != 'median' and point in s:
    ax.axvline(s[point], color='k', lw=1.5, label='point')
  if truth is not None:
    ax.axvline(truth[name], color='r', lw=1.5, label='truth')
  ax.set(xlabel=label, yticks=[], xscale='log' if log else 'linear')


def _edges(x: np.ndarray, bounds, log: bool) -> np.ndarray:
  """A pair's bin edges along one field: the draws ``x``'s range padded and
  clipped to the box's ``bounds``, equal bins in the plotted scale."""
  lo, hi = np.quantile(x, [0.005, 0.995])
  blo, bhi = bounds
  if log:
    pad = (np.log(hi) - np.log(lo)) * 0.15
    return np.geomspace(max(blo, lo * np.exp(-pad)), min(bhi, hi * np.exp(pad)), 41)
  pad = (hi - lo) * 0.15 + 1e-9
  return np.linspace(max(blo, lo - pad), min(bhi, hi + pad), 41)


def _pair(ax, post: dict, stats: dict, truth: dict | None, bounds, x: str, y: str,
          point: str, labels: dict, k: dict) -> None:  # fmt: skip
  """One pair's 2-D histogram of the draws (bending on a log axis), the
  truth and the point (``point``, else the median); wind x area weight with
  the load ratio's iso-lines at its median and 90% interval (``k``: the
  factors the values were drawn in, ``_units``)."""
  i, j = FIELDS.index(x), FIELDS.index(y)
  ex, ey = _edges(post[x], bounds[i], i == 0), _edges(post[y], bounds[j], j == 0)
  ax.hist2d(post[x], post[y], bins=[ex, ey], cmap='viridis')
  if (x, y) == ('wind_speed', 'area_weight'):  # w = rho v^2 / (g r)
    v = np.linspace(ex[0], ex[-1], 100)
    lr = stats['load_ratio']
    for r in (lr['interval_90'][0], lr['median'], lr['interval_90'][1]):
      vs, rs = v / k[x], r / k['load_ratio']  # in the search's scales
      w = physsim.params.AIR_DENSITY * vs**2 / (physsim.params.GRAVITY * rs)
      ax.plot(v, k[y] * w, 'w--', lw=0.8)
    ax.set_ylim(ey[0], ey[-1])
  if truth is not None:
    ax.plot(truth[x], truth[y], 'r+', ms=14, mew=2)
  key = point if point in stats[x] else 'median'
  ax.plot(stats[x][key], stats[y][key], 'wx', ms=10, mew=2)
  ax.set(xlabel=labels[x], ylabel=labels[y])
  if i == 0:
    ax.set_xscale('log')
