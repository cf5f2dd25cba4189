"""What an estimate reports: summaries, errors against a known truth, tables, figures.

Figures: ``plot_trace`` (the paper's Figure 3: PSD and each parameter per
iteration) and ``plot_montage`` (the recording beside the simulation at the
estimate, on one depth colour scale with frame times).
"""

from __future__ import annotations

import textwrap

import numpy as np

import model as model_lib
import physsim
from experiments.pipeline import files, measurements
from experiments.pipeline import objective as obj_lib

LABELS = {
  'bending_scale': 'bending (x measured)',
  'wind_speed': 'wind speed (m/s)',
  'area_weight': 'area weight (kg/m$^2$)',
}
SHORT = measurements.SHORT


_RETRIEVAL_MEANING = (
  'near 1: the video barely constrains that parameter; trust its interval, '
  'not its value'
)


def stats(value, samples: np.ndarray) -> dict:
  """A value with the median, 90% interval and spread of ``samples``."""
  return {
    'value': float(np.asarray(value).ravel()[0]),
    'posterior_median': float(np.median(samples)),
    'interval_90': [
      float(np.quantile(samples, 0.05)),
      float(np.quantile(samples, 0.95)),
    ],
    'std': float(samples.std()),
  }


def summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  """Per parameter, ``stats`` of the best point and of (S, 3) physical samples."""
  return {n: stats(best[i], samples_phys[:, i]) for i, n in enumerate(best._fields)}


def load_ratio_summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  """rho v^2 / (w g) of the best candidate and of the samples: the
  combination of wind and area weight a sheet's shape constrains best."""
  i, j = (
    physsim.Params._fields.index('wind_speed'),
    physsim.Params._fields.index('area_weight'),
  )
  ratio = physsim.load_ratio(samples_phys[:, i], samples_phys[:, j])
  return stats(physsim.load_ratio(best.wind_speed, best.area_weight), ratio)


def errors(best: physsim.Params, truth: dict, space: physsim.SearchSpace,
           air: float | None = None) -> dict:  # fmt: skip
  """Percent errors of wind and area weight, the bending factor, the percent
  error of the load ratio c rho v^2 / (w g) (what a sheet's shape constrains
  best; c the air coefficient, 1 where not estimated), and the same for the
  trivial estimate (the centre of the search range). With ``air`` (the
  estimate's c) and a truth that knows its own, c's factor too."""
  centre = space.center()
  true_ratio = with_load_ratio(truth)['load_ratio']

  def one(p, c):
    b = float(np.asarray(p.bending_scale).ravel()[0])
    ratio = c * float(physsim.load_ratio(p.wind_speed, p.area_weight))
    pct = lambda k: 100 * abs(float(getattr(p, k)) - truth[k]) / truth[k]
    out = {
      'wind_speed_pct': pct('wind_speed'),
      'area_weight_pct': pct('area_weight'),
      'bending_factor': float(np.exp(abs(np.log(b / truth['bending_scale'])))),  # >= 1
      'load_ratio_pct': 100 * abs(ratio - true_ratio) / true_ratio,
    }
    if air is not None and 'air_coefficient' in truth:
      out['air_factor'] = float(np.exp(abs(np.log(c / truth['air_coefficient']))))
    return out

  mid = float(np.sqrt(np.prod(measurements.AIR_RANGE)))  # the prior's centre
  return {
    'estimate': one(best, 1.0 if air is None else air),
    'range_centre': one(centre, 1.0 if air is None else mid),
  }


def mean_error(values, name: str) -> float:
  """The mean of one ``errors`` measure over recordings: geometric for the
  bending factor (a factor), arithmetic for the percent errors."""
  if name == 'bending_factor':
    return float(np.exp(np.mean(np.log(values))))
  return float(np.mean(values))


def with_load_ratio(truth: dict) -> dict:
  """A truth (wind speed, area weight, ...) with its load ratio beside it:
  the load the sheet feels, c rho v^2 / (w g), c its air coefficient where the
  truth knows it (else ArcSim's 1)."""
  ratio = physsim.load_ratio(truth['wind_speed'], truth['area_weight'])
  return {**truth, 'load_ratio': float(truth.get('air_coefficient', 1.0) * ratio)}


def covered(result: dict, truth: dict) -> dict:
  """Per parameter and the load ratio: does each credible interval hold the truth?"""
  out = {}
  rows = dict(result['estimate'], load_ratio=result.get('load_ratio', {}))
  true = with_load_ratio(truth)
  for name, e in rows.items():
    if name not in true:  # an air coefficient the truth does not know
      continue
    out[name] = {
      k: bool(e[k][0] <= true[name] <= e[k][1]) for k in e if k.startswith('interval_')
    }
  return out


WIDTH = 100  # columns the printed table and its notes fit in
# The Bayes point and the median further apart than this get a note.
MEDIAN_NOTE_SHARE = 0.1
# What the table calls each quantity (short enough for WIDTH).
# What a person reads, in the units a lab reports (issue 76): bending as its
# rigidity in uN m (the search's scale times the fabric's reference rigidity,
# ``physsim.reference_rigidity``), area weight in g/m^2; ``estimate.json``
# keeps the search's own scales, labelled. A result without a known fabric
# keeps the scale (``SCALE_NAMES``).
ROW_NAMES = {
  'bending_scale': 'bending rigidity (uN m)',
  'wind_speed': 'wind (m/s)',
  'area_weight': 'area weight (g/m^2)',
  'load_ratio': 'load ratio',
  'air_coefficient': 'air coefficient (x ArcSim)',
}
SCALE_NAMES = {**ROW_NAMES, 'bending_scale': 'bending (x)'}
LENGTH_NAME = 'bending length (mm)'


def in_units(material: str | None) -> tuple[dict, dict]:
  """(row names, factors): what each quantity's row is called and the factor
  from the search's scale to the unit it is printed in, for ``material``'s
  results (None or unknown: bending stays a scale)."""
  factors = {'bending_scale': 1.0, 'wind_speed': 1.0, 'area_weight': 1e3,
             'load_ratio': 1.0, 'air_coefficient': 1.0}  # fmt: skip
  if material not in physsim.FABRICS:
    return SCALE_NAMES, factors
  factors['bending_scale'] = 1e6 * physsim.reference_rigidity(material)
  return ROW_NAMES, factors


def length_mm(bending_scale: float, area_weight: float, material: str | None):
  """Peirce's bending length of a point, mm (None: no known fabric)."""
  if material not in physsim.FABRICS:
    return None
  d0 = physsim.reference_rigidity(material)
  return 1e3 * float(physsim.params.bending_length(bending_scale, area_weight, d0))


_ERROR_NAMES = {
  'wind_speed_pct': ('wind', '%'),
  'area_weight_pct': ('area weight', '%'),
  'bending_factor': ('bending', 'x'),
  'load_ratio_pct': ('load ratio', '%'),
  'air_factor': ('air coefficient', 'x'),
}


def _markdown(head: list[str], rows: list[list[str]]) -> list[str]:
  """A markdown table whose columns are padded to their widest cell, so that
  it reads as a table in a terminal too."""
  widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
  line = lambda cells: (
    '| ' + ' | '.join(c.ljust(w) for c, w in zip(cells, widths, strict=True)) + ' |'
  )
  return [line(head), '|' + '|'.join('-' * (w + 2) for w in widths) + '|'] + [
    line(r) for r in rows
  ]


def notes(*paragraphs: str, width: int = WIDTH) -> list[str]:
  """Notes under a table, each wrapped to ``width`` columns."""
  return [
    line
    for p in paragraphs
    if p
    for line in textwrap.wrap(p, width, subsequent_indent='  ')
  ]


def _error_cell(key: str, v: float) -> str:
  """An error of ``errors``' ``key`` as a table prints it: a factor for
  bending, else percent."""
  return f'x{v:.2f}' if _ERROR_NAMES[key][1] == 'x' else f'{v:.1f}%'


def errors_table(errors: dict) -> list[str]:
  """The point's errors against the truth beside the range centre's, as a small
  table (percent; a factor for bending)."""
  rows = []
  for key, (name, _) in _ERROR_NAMES.items():
    if key not in errors['estimate']:
      continue
    rows.append(
      [name, _error_cell(key, errors['estimate'][key]),
       _error_cell(key, errors['range_centre'][key])]
    )  # fmt: skip
  return _markdown(['error against the truth', 'point', 'range centre'], rows)


def distances_table(results: dict[str, dict]) -> str:
  """Estimates of one recording by several distances, side by side: per
  quantity each one's point and 90% interval, the truth beside them, and
  each point's error against it (percent; a factor for bending)."""
  names = list(results)
  first = results[names[0]]
  truth = with_load_ratio(first['truth']) if first.get('truth') else {}
  label, unit = in_units(first.get('material'))
  rows = []
  for q in [*physsim.Params._fields, 'load_ratio']:
    k = unit[q]
    cells = [label[q]] + ([f'{k * truth[q]:.3g}'] if truth else [])
    for n in names:
      r = results[n]
      e = r['load_ratio'] if q == 'load_ratio' else r['estimate'][q]
      lo, hi = e['interval_90']
      cell = f'{k * e["value"]:.3g} [{k * lo:.3g}, {k * hi:.3g}]'
      if truth and 'errors' in r:
        key = 'bending_factor' if q == 'bending_scale' else f'{q}_pct'
        cell += f' ({_error_cell(key, r["errors"]["estimate"][key])})'
      cells.append(cell)
    rows.append(cells)
  head = ['quantity'] + (['true'] if truth else []) + names
  lines = _markdown(head, rows) + notes(
    'each: the point, [its 90% interval]'
    + (" and (the point's error against the truth)" if truth else '')
    + '; percent, a factor for bending.'
  )
  return '\n'.join(lines)


def report_table(result: dict) -> str:
  """An estimate for a person, in at most ``WIDTH`` columns: per quantity the
  point, its 50% and 90% credible intervals and how much narrower the 90% one
  is than the prior's (posterior), or the GP's interval (the paper's argmin);
  with ground truth the truth beside them and a small table of the point's
  errors against the range centre's; notes wrapped under it."""
  retrieval = result.get('network_retrieval_vs_chance', {})
  truth = result.get('truth')
  posterior = result.get('point', 'argmin') != 'argmin'
  head = ['quantity'] + (['true'] if truth else [])
  if posterior:
    head += ['point', '50% interval', '90% interval', 'narrower']
  else:
    head += ['point (argmin)', 'GP 90% interval']
  head += ['retrieval'] if retrieval else []
  true = with_load_ratio(truth) if truth else {}
  material = result.get('material')
  label, unit = in_units(material)
  rows = []
  air = ['air_coefficient'] if 'air_coefficient' in result['estimate'] else []
  for name in [*physsim.Params._fields, 'load_ratio', *air]:
    e = result['load_ratio'] if name == 'load_ratio' else result['estimate'][name]
    k = unit[name]
    iv = lambda key, e=e, k=k: f'[{k * e[key][0]:.3g}, {k * e[key][1]:.3g}]'
    cells = [label[name]] + (
      [f'{k * true[name]:.3g}' if name in true else '-'] if truth else []
    )
    cells += [f'{k * e["value"]:.3g}']
    if posterior:
      cells += [iv('interval_50'), iv('interval_90'), f'x{e["narrowing_90"]:.1f}']
    else:
      cells += [iv('interval_90')]
    if retrieval:
      cells += [f'{retrieval[name]:.2f}' if name in retrieval else '-']
    rows.append(cells)
  est = result['estimate']
  length = length_mm(
    est['bending_scale']['value'], est['area_weight']['value'], material
  )
  if length is not None:  # the point's, as a lab reads it; no interval of its own
    true_length = (
      [f'{length_mm(truth["bending_scale"], truth["area_weight"], material):.3g}']
      if truth
      else []
    )
    rows.append([LENGTH_NAME, *true_length, f'{length:.3g}',
                 *['-'] * (len(head) - 2 - len(true_length))])  # fmt: skip
  lines = _markdown(head, rows)
  if truth:
    lines += [''] + errors_table(result['errors'])
  lines.append('')
  point = {
    'bayes': 'the value with the least expected error (wind and load ratio: '
    'the posterior median)',
    'median': 'the posterior median',
  }
  lines += notes(
    "load ratio: rho v^2 / (w g), wind pressure over weight, what the sheet's "
    'shape measures best'
    + (
      " (times the fabric's air coefficient c: the pressure it feels); air "
      'coefficient: the normal wind pressure on this fabric over an ArcSim '
      "sheet's, read from the wind reading and the load the video sees."
      if air
      else '.'
    )
    + (
      ' bending length: (rigidity / (area weight x g))^(1/3) of the point; no '
      'interval of its own (not calibrated).'
      if length is not None
      else ''
    ),
    f'point: {point.get(result.get("point"), "the best simulation (not calibrated)")}; '
    "narrower: the prior's 90% width over the interval's (x1.0: the recording "
    "told nothing about it, the interval is the prior's)"
    + _readings_in_prior(result)
    + '.'
    if posterior
    else "GP 90% interval: the Gaussian process's, not calibrated.",
    calibration_line(result.get('calibration')) if posterior else '',
    median_line(result) if result.get('point') == 'bayes' else '',
    'search box: ' + '; '.join(result['search_box_widened']) + '.'
    if result.get('search_box_widened')
    else '',
    fit_line(result.get('fit_check'), result.get('config', {}).get('measured', {})),
    'retrieval: how well the network tells each quantity apart between held-out '
    f'simulations, 1 = chance ({_RETRIEVAL_MEANING}).'
    if retrieval
    else '',
  )
  return '\n'.join(lines)


# The readings an estimate's prior can hold, as its table's note names them.
_READING_WORDS = {'wind_speed': 'the wind reading', 'area_weight': 'the weighed area weight',
                  'bending_length': "the strip's bending length"}  # fmt: skip


def _readings_in_prior(result: dict) -> str:
  """'; the prior holds ...' for the readings an estimate was given (its
  narrowing is then the recording's over them), else ''."""
  measured = (result.get('config') or {}).get('measured') or {}
  given = [w for k, w in _READING_WORDS.items() if measured.get(f'{k}_sd', 0) > 0]
  if not given:
    return ''
  return (
    '; the prior holds ' + ' and '.join(given) + ': narrower is what the video added'
  )


def median_line(result: dict, share: float = MEDIAN_NOTE_SHARE) -> str:
  """A note naming each quantity whose Bayes point (least expected percent
  error over the prior's whole range) is more than ``share`` from its
  posterior median: where the posterior is wide and skewed the point leans to
  the prior's middle, and a reader with, say, a strong fan should see both."""
  far = []
  label, unit = in_units(result.get('material'))
  for name in physsim.Params._fields:
    e, k = result['estimate'][name], unit[name]
    if 'median' in e and abs(e['median'] / e['value'] - 1) > share:
      far.append(f'{label[name]} {k * e["median"]:.3g} (point {k * e["value"]:.3g})')
  if not far:
    return ''
  return (
    'posterior median where it differs from the point by more than '
    f'{100 * share:.0f}%: ' + ', '.join(far) + '; the point leans to the '
    "prior's middle where the posterior is wide."
  )


def joint_table(joint: dict) -> str:
  """A joint estimate for a person, in at most ``WIDTH`` columns: shared
  bending and area weight and each recording's wind and load ratio (point,
  90% interval, narrowing), each beside the same recording estimated alone."""
  label, unit = in_units(joint.get('material'))
  iv = lambda e, k=1.0: (
    f'[{k * e["interval_90"][0]:.3g}, {k * e["interval_90"][1]:.3g}]'
  )
  rows = []
  air = ('air_coefficient',) if 'air_coefficient' in joint else ()
  for name in ('bending_scale', 'area_weight', *air):
    e, k = joint[name], unit[name]
    rows.append([f'{label[name]}, shared', f'{k * e["median"]:.3g}', iv(e, k),
                 f'x{e["narrowing_90"]:.1f}', '-', '-'])  # fmt: skip
  for i, r in enumerate(joint['recordings']):
    for name in ('wind_speed', 'load_ratio'):
      e, a = r[name], r['alone'].get(name)
      rows.append([
        f'{label[name]}, rec. {i}', f'{e["median"]:.3g}', iv(e),
        f'x{e["narrowing_90"]:.1f}', f'{a["value"]:.3g}' if a else '-',
        iv(a) if a else '-',
      ])  # fmt: skip
  head = ['quantity', 'point', '90% interval', 'narrower', 'alone', 'alone 90%']
  lines = _markdown(head, rows)
  shared = ('bending_scale', 'area_weight')
  alone = [
    [f'recording {i}']
    + [
      f'{unit[n] * r["alone"][n]["value"]:.3g} {iv(r["alone"][n], unit[n])}'
      for n in shared
    ]
    for i, r in enumerate(joint['recordings'])
  ]
  lines += [''] + _markdown(['each alone', *(label[n] for n in shared)], alone)
  lines += [''] + notes(
    "point: the joint posterior's median; narrower: the prior's 90% width over "
    "the interval's; alone: the same recording estimated by itself.",
    _set_up_note(joint['recordings']),
    calibration_line(joint.get('calibration')),
  )
  return '\n'.join(lines)


def _set_up_note(recordings: list[dict]) -> str:
  """Which recordings shared a fan setting (one wind) and which carried a
  known mass at the hem, or ''."""
  parts = []
  by: dict[str, list[int]] = {}
  for k, r in enumerate(recordings):
    by.setdefault(r.get('fan', f'#{k}'), []).append(k)
  for fan, ks in by.items():
    if len(ks) > 1:
      parts.append(
        f'recordings {", ".join(map(str, ks))} share fan setting {fan!r} (one wind)'
      )
  parts += [
    f'recording {k} carries {1000 * r["hem_mass"]:g} g at its hem'
    for k, r in enumerate(recordings)
    if r.get('hem_mass')
  ]
  return '; '.join(parts) + '.' if parts else ''


def calibration_line(cal: dict | None) -> str:
  """One line on how often such intervals held the truth in held-out simulations."""
  if not cal:
    return (
      'calibration: not measured for these settings (experiments/calibrate.py); '
      'treat the intervals as indicative.'
    )
  if not cal.get('matches', True):
    return (
      f'calibration: measured for {cal["setting"]}, not for this '
      f'{", ".join(cal.get("differs", ["likelihood"]))}; treat the intervals as '
      'indicative.'
    )
  parts = _coverage_parts(cal['coverage'])
  if cal.get('recalibrated'):
    held = (
      'recordings of networks held out from that'
      if cal.get('networks', 1) > 1
      else 'recordings held out from that'
    )
    line = (
      f'calibration ({cal["mode"]}): intervals read at levels recalibrated on '
      f'{cal["n_calibration_recordings"]} simulated recordings ({cal["setting"]}'
      + ''.join(
        f'; {name.replace("_", " ")} read to {sd}'
        for name, sd in cal.get('readings', {}).items()
      )
      + f'); read so, {held} held the truth in their 90%/50% intervals: {parts}.'
    )
    for c in cal.get('checks', []):
      line += (
        f' On {c["n"]} recordings of {PHYSICS_WORDS.get(c["physics"], c["physics"])}'
        f' they held it in {_coverage_parts(c["coverage"])}.'
      )
      if f := c.get('this_fabric'):
        line += (
          f' This fabric alone ({f["material"].replace("_", " ")}, {f["n"]} of them): '
          f'{_coverage_parts(f["coverage"])}.'
        )
        if f['short']:
          line += (
            f' Its {" and ".join(SHORT.get(q, q) for q in f["short"])} 90% intervals '
            'held the truth less often than promised there: read them as too narrow '
            'for this fabric.'
          )
    if w := cal.get('weaker_network'):
      lo, hi = w['calibrated']
      line += (
        f" This network's held-out triplet accuracy ({100 * w['accuracy']:.0f}%) is "
        f"below the calibration's networks' ({100 * lo:.0f}-{100 * hi:.0f}%): its "
        'intervals may hold the truth less often than that.'
      )
    return line
  return (
    f'calibration ({cal["n"]} held-out simulated recordings, {cal["setting"]}): 90%/50% '
    f'intervals held the truth in {parts} of them.'
  )


# What a check's recordings were, in the estimate's calibration line.
PHYSICS_WORDS = {
  'own': "the estimator's own simulator",
  'mismatched': 'another physics (fan 10 degrees off, other gusts, drag, damped '
  'bending, softer edges)',
}


def _coverage_parts(cov: dict) -> str:
  """'bending 92%/50%, wind ...': each quantity's 90%/50% coverage."""
  order = ('bending_scale', 'wind_speed', 'area_weight', 'load_ratio')
  keys = sorted(cov, key=lambda k: order.index(k) if k in order else len(order))
  return ', '.join(
    f'{SHORT.get(k, k)} {100 * cov[k]["interval_90"]:.0f}%/'
    f'{100 * cov[k]["interval_50"]:.0f}%'
    for k in keys
  )


def retrieval_note(retrieval: dict[str, float]) -> str:
  """One line saying which parameters the network barely tells apart."""
  cells = model_lib.retrieval.describe(retrieval)
  return (
    f'network retrieval on held-out simulations, over chance: {cells} '
    f'({_RETRIEVAL_MEANING})'
  )


# -------------------------------------------------------------------- figures


def iterations_of(n_evals: int, n_init: int, q: int) -> np.ndarray:
  """(n_evals,) the iteration each evaluation belongs to (0: initial design),
  as the console counts them."""
  it = np.zeros(n_evals, np.int64)
  it[n_init:] = 1 + np.arange(max(n_evals - n_init, 0)) // q
  return it


# What each distance's trace calls its score (a shape distance uses no network).
DISTANCE_WORDS = {
  'shape': ("distance of the sheet's mean shape (m$^2$)", 'shape distance'),
  'energy': ('physics similarity distance (PSD)', 'PSD'),
  'centroid': ('physics similarity distance (centroid)', 'PSD'),
  'energy+shape': ('PSD and shape distance, geometric mean', 'distance'),
}


def plot_trace(X_unit, Y, iteration, space, truth, path: str,
               distance: str = 'energy') -> None:  # fmt: skip
  """The distance and each parameter per iteration (the paper's Figure 3).

  Args:
    X_unit: (n, 3) evaluated unit-cube points, in order.
    Y: (n,) their distances (NaN: blew up).
    iteration: (n,) the iteration of each (``iterations_of``).
    space: the search space (axis limits).
    truth: true parameters or None.
    path: PNG path.
    distance: the estimate's distance (``DISTANCE_WORDS``), for the labels.
  """
  long_name, short_name = DISTANCE_WORDS.get(distance, DISTANCE_WORDS['energy'])
  X = np.asarray(physsim.from_unit(X_unit, space))  # (3, n)
  Y = np.asarray(Y, np.float64)
  ok = np.isfinite(Y)
  best = np.fmin.accumulate(np.where(ok, Y, np.inf))
  last_of = {
    int(i): j for j, i in enumerate(iteration)
  }  # last evaluation per iteration
  its = np.array(sorted(last_of))
  jitter = (np.random.default_rng(0).random(len(Y)) - 0.5) * 0.3
  xs = iteration + jitter
  plt = files.pyplot()
  fig, axes = plt.subplots(1, 4, figsize=(17, 3.8), layout='constrained')
  ax = axes[0]
  ax.plot(xs[ok], Y[ok], '.', color='0.55', label='candidate')
  ax.plot(its, best[[last_of[i] for i in its]], '-o', ms=3, color='k',
          label='best so far')  # fmt: skip
  if (~ok).any():
    ax.plot(xs[~ok], np.full((~ok).sum(), np.nanmax(Y) if ok.any() else 1), 'x',
            color='r', label='blew up')  # fmt: skip
  ax.set(xlabel='iteration (0 = initial design)', ylabel=long_name, yscale='log')
  ax.legend(fontsize=8)
  colour = np.log10(np.where(ok, Y, np.nan))
  for i, (ax, name) in enumerate(zip(axes[1:], physsim.Params._fields, strict=True)):
    sc = ax.scatter(xs, X[i], c=colour, s=14, cmap='viridis')
    ax.set(xlabel='iteration (0 = initial design)', ylabel=LABELS[name],
           ylim=space.bounds()[i])  # fmt: skip
    if name == 'bending_scale':
      ax.set_yscale('log')
    if truth is not None:
      ax.axhline(truth[name], color='r', lw=1, label='truth')
      ax.legend(fontsize=8, loc='upper left', bbox_to_anchor=(0, -0.18), frameon=False)
  fig.colorbar(
    sc, ax=axes[1:], label=f'log$_{{10}}$ {short_name} (dark: low)', shrink=0.9
  )
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def plot_montage(
  recorded: np.ndarray, simulated: np.ndarray, fps: float, path: str, n: int = 6,
  sim_label: str = 'simulation at the estimate',
) -> None:  # fmt: skip
  """Rows: the recording and a simulation, ``n`` frames each at the same times,
  depth on one colour scale (white: no return) or colour frames.

  Args:
    recorded: (T, H, W) depth in metres or (T, H, W, 3) uint8 colour.
    simulated: the same for the simulation.
    fps: frame rate of both (for the frame times).
    path: PNG path.
    n: frames shown.
    sim_label: the second row's label.
  """
  idx = np.unique(np.linspace(0, min(len(recorded), len(simulated)) - 1, n).astype(int))
  colour = recorded.ndim == 4
  both = np.concatenate([np.ravel(recorded[idx]), np.ravel(simulated[idx])])
  valid = both[both > 0]
  lo, hi = np.quantile(valid, [0.01, 0.99]) if valid.size else (0.0, 1.0)
  plt = files.pyplot()
  cmap = plt.get_cmap('viridis').with_extremes(bad='white')
  fig, axes = plt.subplots(2, len(idx), figsize=(2.1 * len(idx) + 1.2, 4.6),
                           squeeze=False, layout='constrained')  # fmt: skip
  im = None
  for r, (frames, name) in enumerate(((recorded, 'recording'), (simulated, sim_label))):
    for c, t in enumerate(idx):
      ax = axes[r, c]
      if colour:
        ax.imshow(frames[t])
      else:
        im = ax.imshow(np.ma.masked_equal(frames[t], 0.0), cmap=cmap, vmin=lo, vmax=hi)
      ax.set(xticks=[], yticks=[])
      if r == 0:
        ax.set_title(f't = {t / fps:.2f} s', fontsize=9)
      if c == 0:
        ax.set_ylabel(name, fontsize=9)
  if im is not None:
    fig.colorbar(im, ax=axes, shrink=0.8, label='depth (m); white: no return')
  files.savefig(fig, path, dpi=80)
  plt.close(fig)


def shape_camera_warning(config, aligned: bool) -> str | None:
  """The line ``estimate`` prints when a shape discrepancy (which reads
  centimetres in the simulator's world) trusts a camera that the intake's
  alignment placed there (``aligned``) as exact (no ``camera_sd``); else None."""
  sc = config.scoring
  if (
    sc.distance not in obj_lib.SHAPE_DISTANCES
    or sc.camera_sd_m
    or sc.camera_sd_deg
    or not aligned
  ):
    return None
  return (
    f'warning: --distance={sc.distance} reads where the sheet hangs in the '
    "simulator's world, and the intake placed your camera there by its alignment "
    '(within about 2 cm and 3 degrees on its test); with --camera_sd_m=0 '
    '--camera_sd_deg=0 the posterior trusts that placement exactly. Give its '
    'error, e.g. --camera_sd_m=0.02 --camera_sd_deg=3'
  )


def synthetic_warning(config) -> str | None:
  """The line ``estimate`` prints for the 'synthetic' likelihood (else None):
  it takes the recording's scatter to be the simulator's. On real-like
  recordings simulated with another mesh and gust level its intervals were
  too narrow; with their own (``cloth_resolution``, ``gusts``) they held
  (BENCHMARKS.md)."""
  if config.scoring.likelihood != 'synthetic':
    return None
  return (
    'warning: --likelihood=synthetic trusts the simulator to scatter as your '
    'recording does; on real-like recordings simulated with another mesh and gust '
    'level its 90% intervals held the wind and the load ratio only 50-67% of the '
    "time (the default 'gibbs' 83%), with their own (--cloth_resolution, --gusts) "
    '83-100%: report its intervals only when the simulator matches your set-up'
  )


# One clip reads the load ratio about twice as poorly above STRONG_LOAD_RATIO as
# below GENTLE_LOAD_RATIO, and a longer clip helps only below (the sheet blown
# nearly flat; benchmarks/gust_floor.py at c465b0e, docs/studies/benchmarks.md).
STRONG_LOAD_RATIO = 10.0
GENTLE_LOAD_RATIO = 8.0


def point_of(stats: dict) -> float:
  """A quantity's summary as one number: the posterior median where there is a
  posterior, else the reported value (the paper's argmin protocol)."""
  return float(stats['median'] if 'median' in stats else stats['value'])


def fan_setting_note(load_ratios, material: str) -> str | None:
  """The line ``estimate`` prints when every recording's load ratio (posterior
  medians) is above ``STRONG_LOAD_RATIO``: such fan settings read area weight
  hardly better than its range, while three gentler ones (the wind that gives
  ``GENTLE_LOAD_RATIO`` at the fabric's middle area weight), each with an
  anemometer reading, estimated jointly, read it about twice as well as the
  range (BENCHMARKS.md); else None."""
  ratios = np.atleast_1d(np.asarray(load_ratios, np.float64))
  if not np.all(ratios > STRONG_LOAD_RATIO):
    return None
  w = float(physsim.search_space(material).center().area_weight)
  gentle = float(
    np.sqrt(GENTLE_LOAD_RATIO * w * physsim.params.GRAVITY / physsim.params.AIR_DENSITY)
  )
  seen = ', '.join(f'{r:.0f}' for r in ratios)
  return (
    f'note: load ratio rho v^2/(w g) about {seen}: at fan settings this strong the '
    'sheet is blown nearly flat and a clip reads the area weight hardly better than '
    f'its range; to measure it, record three gentler settings (load ratio under '
    f'{GENTLE_LOAD_RATIO:g}: about {gentle:.1f} m/s or less for {material}), each '
    'with an anemometer reading, and estimate them jointly (--recording=a,b,c '
    '--wind_speeds=...; docs/identifiability.md)'
  )


# Below this narrowing (the prior's 90% width over the posterior's) a
# recording has told little about a fabric parameter.
LITTLE_NARROWING = 1.5


def next_recording_note(shared: dict, config, workdir: str) -> str | None:
  """The one line ``estimate`` prints after every estimate whose bending or
  area weight the recordings left near the prior (``shared``: an estimate's
  ``estimate`` entries, or a joint estimate's shared ones): what to record or
  measure next by the protocol study's bound (docs/studies/protocol.md), and the
  command that ranks candidates with the simulator from this posterior."""
  # narrowing is the video's over the prior with the readings: a parameter a
  # reading measured (the strip's bending length, a scale's area weight) is
  # not left at the prior however little the video added
  measured = {'bending_scale': config.measured.bending_length_sd > 0,
              'area_weight': config.measured.area_weight_sd > 0}  # fmt: skip
  little = [
    name for name in ('bending_scale', 'area_weight')
    if shared.get(name, {}).get('narrowing_90', np.inf) < LITTLE_NARROWING
    and not measured[name]
  ]  # fmt: skip
  if not little:
    return None
  steps = []
  if 'area_weight' in little:
    steps.append(
      'weigh the sheet and measure its sides (--area_weight=... --area_weight_sd=...)'
    )
  if 'bending_scale' in little:
    steps.append(
      'lay a strip of it over a table edge and measure its bending length (the '
      'cantilever test: README, How to record; --bending_length=... '
      '--bending_length_sd=...)'
    )
  told = ' and '.join(n.replace('_scale', '').replace('_', ' ') for n in little)
  return (
    f'next: the recording(s) told little about {told}; ' + '; '.join(steps) + '. '
    f'python -m experiments.plan --workdir={workdir} ranks what to record next '
    'with the simulator'
  )


_READING_UNITS = {'wind_speed': ('wind', 'm/s', 1.0), 'area_weight': ('area weight', 'g/m^2', 1e3),
                  'bending_length': ('bending length', 'mm', 1e3)}  # fmt: skip


def fit_line(check: dict | None, measured: dict) -> str:
  """The fit check (``fit_check``) as a note: how far simulations at the point
  lie from the recording against the gust floor, and each reading the video
  disagrees with, with what would reconcile them. '' without a check."""
  if not check:
    return ''
  parts = []
  p = check.get('predictive')
  if p:
    parts.append(
      f'fit: {p["simulations"]} simulations at the point lie {p["ratio"]:.2g}x the '
      'gust floor from the recording'
      + (
        ' (as close as the gusts allow)'
        if p['fits']
        else ': FARTHER than the gusts allow; no fabric in the box reproduces '
        'this recording with these settings and readings'
      )
    )
  for c in check.get('conflicts', []):
    word, unit, k = _READING_UNITS[c['reading']]
    lo, hi = c['video']
    line = (
      f'the video disagrees with the {word} reading: alone it puts the {word} at '
      f'{k * lo:.3g}-{k * hi:.3g} {unit} (99%), the reading was '
      f'{k * c["value"]:.3g} +- {k * c["sd"]:.2g} {unit}'
    )
    if c['reading'] == 'wind_speed' and measured.get('air_coefficient') != 'free':
      line += (
        '; if both hold, this fabric takes the wind differently from an ArcSim '
        'sheet: estimate its air coefficient (--air_coefficient=free)'
      )
    parts.append(line)
  return '; '.join(parts) + '.' if parts else ''
