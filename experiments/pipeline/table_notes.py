"""What the notes under an estimate's table say: the words that tell a person
how to read its numbers.

Each function returns a paragraph ('' where it has nothing to say);
``report`` wraps them under its tables. The paragraphs explain the load
ratio, the point and its intervals, how often such intervals held the truth
(``calibration_line``), where the point and the median part
(``median_line``), how well the simulations fit the recording and its
readings (``fit_line``) and what the network's retrieval means.
"""

from __future__ import annotations

import model as model_lib
import physsim
from experiments.pipeline import measurements, units

SHORT = measurements.SHORT
# The Bayes point and the median further apart than this get a note.
MEDIAN_NOTE_SHARE = 0.1

_RETRIEVAL_MEANING = (
  'near 1: the video barely constrains that parameter; trust its interval, '
  'not its value'
)
# What each kind of point is, as the note under the table says it.
_POINT_WORDS = {
  'bayes': 'the value with the least expected error (wind and load ratio: '
  'the posterior median)',
  'median': 'the posterior median',
}
_GP_NOTE = "GP 90% interval: the Gaussian process's, not calibrated."
# The readings an estimate's prior can hold, as its table's note names them.
_READING_WORDS = {'wind_speed': 'the wind reading', 'area_weight': 'the weighed area weight',
                  'bending_length': "the strip's bending length"}  # fmt: skip
# A reading's name, unit and factor from SI, as the fit note prints it.
_READING_UNITS = {'wind_speed': ('wind', 'm/s', 1.0), 'area_weight': ('area weight', 'g/m^2', 1e3),
                  'bending_length': ('bending length', 'mm', 1e3)}  # fmt: skip
# What a check's recordings were, in the estimate's calibration line.
PHYSICS_WORDS = {
  'own': "the estimator's own simulator",
  'mismatched': 'another physics (fan 10 degrees off, other gusts, drag, damped '
  'bending, softer edges)',
  'mismatched_b': 'a second other physics (fan 5 degrees off, finer gusts, less drag, '
  'more damped bending, softer edges)',
}


def estimate_notes(result: dict) -> list[str]:
  """The paragraphs under one estimate's table (``report.report_table``), in
  the order printed."""
  posterior = result.get('point', 'argmin') != 'argmin'
  retrieval = result.get('network_retrieval_vs_chance', {})
  return [
    _load_ratio_note(
      'air_coefficient' in result['estimate'],
      result.get('material') in physsim.FABRICS,  # a bending length row
    ),
    _point_note(result) if posterior else _GP_NOTE,
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
  ]


def _load_ratio_note(air: bool, length: bool) -> str:
  """What the load ratio is (and the air coefficient, where ``air`` was
  estimated), and the bending length row's meaning where it is printed."""
  return (
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
      if length
      else ''
    )
  )


def _point_note(result: dict) -> str:
  """What a posterior's point is and what its 'narrower' column measures."""
  point = _POINT_WORDS.get(result.get('point'), 'the best simulation (not calibrated)')
  return (
    f'point: {point}; '
    "narrower: the prior's 90% width over the interval's (x1.0: the recording "
    "told nothing about it, the interval is the prior's)"
    + _readings_in_prior(result)
    + '.'
  )


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
  label, unit = units.in_units(result.get('material'))
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


def joint_notes(joint: dict) -> list[str]:
  """The paragraphs under a joint estimate's tables (``report.joint_table``)."""
  return [
    "point: the joint posterior's median; narrower: the prior's 90% width over "
    "the interval's; alone: the same recording estimated by itself.",
    _set_up_note(joint['recordings']),
    calibration_line(joint.get('calibration')),
  ]


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
  if cal.get('measured'):
    return _measured_line(cal)
  parts = _coverage_parts(cal['coverage'])
  if cal.get('recalibrated'):
    return _recalibrated_line(cal, parts)
  return (
    f'calibration ({cal["n"]} held-out simulated recordings, {cal["setting"]}): 90%/50% '
    f'intervals held the truth in {parts} of them.'
  )


def _measured_line(cal: dict) -> str:
  """``calibration_line`` of a protocol joint that the shipped protocol
  check covers: its intervals as printed, how often they held the truth on
  that check's sets of another physics, and what it did not measure."""
  readings = ', '.join(
    f'{name.replace("_", " ")} {sd}' for name, sd in cal.get('readings', {}).items()
  )
  physics = PHYSICS_WORDS.get(cal['physics'], cal['physics'])
  word = lambda q: SHORT.get(q, q.replace('_', ' '))  # noqa: E731
  parts = ', '.join(
    f'{word(q)} {100 * c["interval_90"]:.0f}%/{100 * c["interval_50"]:.0f}% of {c["n"]}'
    for q, c in cal['coverage'].items()
  )
  line = (
    f'calibration ({cal["mode"]}; {cal["setting"]}; readings to {readings}): '
    f'measured, not recalibrated: on protocol sets of {physics} its 90%/50% '
    f'intervals held the truth in {parts} sets.'
  )
  if cal.get('unmeasured'):
    names = ', '.join(word(q) for q in cal['unmeasured'])
    line += f' Not measured: {names}; treat those intervals as indicative.'
  return line


def _recalibrated_line(cal: dict, parts: str) -> str:
  """``calibration_line`` of intervals read at recalibrated levels: how often
  held-out recordings' intervals held the truth (``parts``), then each check
  on other physics, and a weaker network's caveat."""
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
    line += _check_sentences(c)
  if w := cal.get('weaker_network'):
    lo, hi = w['calibrated']
    line += (
      f" This network's held-out triplet accuracy ({100 * w['accuracy']:.0f}%) is "
      f"below the calibration's networks' ({100 * lo:.0f}-{100 * hi:.0f}%): its "
      'intervals may hold the truth less often than that.'
    )
  return line


def _check_sentences(c: dict) -> str:
  """' On n recordings of <physics> they held it in ...': one check of the
  calibration, with this fabric's own share of it where it has one."""
  line = (
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
  return line


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


def fit_line(check: dict | None, measured: dict) -> str:
  """The fit check (``fit_check``) as a note: how far simulations at the point
  lie from the recording against the gust floor, and each reading the video
  disagrees with, with what would reconcile them. '' without a check."""
  if not check:
    return ''
  parts = []
  if p := check.get('predictive'):
    parts.append(_predictive_part(p))
  parts += [_conflict_part(c, measured) for c in check.get('conflicts', [])]
  return '; '.join(parts) + '.' if parts else ''


def _predictive_part(p: dict) -> str:
  """How far simulations at the point lie from the recording, against the
  gust floor (``fit_check.predictive``)."""
  return (
    f'fit: {p["simulations"]} simulations at the point lie {p["ratio"]:.2g}x the '
    'gust floor from the recording'
    + (
      ' (as close as the gusts allow)'
      if p['fits']
      else ': FARTHER than the gusts allow; no fabric in the box reproduces '
      'this recording with these settings and readings'
    )
  )


def _conflict_part(c: dict, measured: dict) -> str:
  """A reading the video disagrees with (``fit_check.conflicts``), and for the
  wind one, where the air coefficient was held, what would reconcile them."""
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
  return line
