"""The shipped protocol check, and the note of a protocol joint it covers.

A protocol joint (two to four fan settings, each with an anemometer, a
scale and a bending length; the air coefficient free) has no recalibrated
tables: its intervals are printed as the posterior gives them, and how often
they held the truth was measured on protocol sets of another physics
(``experiments.air_protocol --install``). An estimate like those sets quotes
that measurement (``setup.calibration``); any other protocol joint is told
what keeps the nearest check from it (``protocol_miss``), and its intervals
are printed as indicative.
"""

from __future__ import annotations

import os

from experiments.pipeline.calibration_tables import differing_fields, read_calibration
from experiments.pipeline.carried_errors import (
  CAMERA_FIELDS,
  FACTOR,
  camera_difference,
  camera_gap,
  camera_of,
  law_words,
  recordings_gap,
  table_of,
)

# Coverage of a protocol joint's intervals (fan settings each with an
# anemometer, a scale and a bending length; the air coefficient free),
# measured on protocol sets of another physics (``experiments.air_protocol
# --install``): ``{"checks": [...]}``, one per number of fan settings, camera
# error and strip reading law (``with_check``). Not recalibrated tables: the
# intervals as printed, and how often they held.
PROTOCOL_CHECKS_FILE = os.path.join(os.path.dirname(__file__), 'protocol_checks.json')


def checks_of(recordings: int, path: str = PROTOCOL_CHECKS_FILE) -> list[dict]:
  """The shipped checks of protocol joints of ``recordings`` fan settings
  (one per camera error they were measured with; ``carried_errors.table_of``)."""
  return [c for c in checks_of_any(path) if c['recordings'] == recordings]


def check_of(
  recordings: int, path: str = PROTOCOL_CHECKS_FILE, camera=(0.0, 0.0, 0.0)
) -> dict | None:
  """The shipped check of protocol joints of ``recordings`` fan settings
  measured with ``camera`` (metres, degrees, spread: ``table_of``; default
  exact cameras), or None where none was measured."""
  want = tuple(float(x) for x in camera)
  return next((c for c in checks_of(recordings, path) if table_of(c) == want), None)


def length_law(check: dict) -> tuple[float, float, float]:
  """The bending-length readings a check's sets had: (lowest, highest
  relative sd, t law's degrees of freedom; 0 Gaussian). A check of one sd
  holds readings within a factor of two of it (``FACTOR``); one drawn over a
  range (``length_sd_range``) holds that range."""
  dof = float(check.get('length_dof', 0.0))
  if 'length_sd_range' in check:
    lo, hi = check['length_sd_range']
    return float(lo), float(hi), dof
  rel = check['readings']['bending_length']
  return rel / FACTOR, rel * FACTOR, dof


def with_check(shipped: dict | None, check: dict) -> dict:
  """The shipped file's content with ``check`` in place of the one of its
  number of recordings, camera error and bending-length readings (the
  others kept)."""
  key = lambda c: (c['recordings'], table_of(c), length_law(c))  # noqa: E731
  kept = [c for c in (shipped or {}).get('checks', []) if key(c) != key(check)]
  return {'checks': sorted([*kept, check], key=key)}


def reading_range(check: dict, name: str) -> tuple[float, float]:
  """The relative errors of reading ``name`` that ``check`` holds: a bending
  length's law's range (``length_law``), else a factor of two either way of
  the one its sets had."""
  if name == 'bending_length':
    return length_law(check)[:2]
  rel = check['readings'][name]
  return rel / FACTOR, FACTOR * rel


def _covers_readings(check: dict, m) -> bool:
  """Whether ``check``'s sets had readings like ``m``'s (``Measured``): each
  within a factor of two of theirs, a bending length within its range and
  of its error law."""
  return not _reading_misses(check, m)


def _reading_misses(check: dict, m) -> list[str]:
  """The readings of ``m`` unlike ``check``'s sets', each in words: its
  relative sd outside what the sets had (a factor of two of theirs, a
  bending length's range), or a bending length of another error law."""
  dof = length_law(check)[2]
  out = []
  for name in check['readings']:
    value, sd = (getattr(m, name), getattr(m, f'{name}_sd'))
    a, b = reading_range(check, name)
    if not (value > 0 and a * (1 - 1e-9) <= sd / value <= b * (1 + 1e-9)):
      mine = f'{100 * sd / value:.2g}%' if value > 0 else 'none'
      out.append(
        f'{name.replace("_", " ")} reading {mine} (checked: '
        f'{100 * a:.2g}-{100 * b:.2g}%)'
      )
  if m.bending_length_dof != dof:
    out.append(
      f'bending length error law ({law_words(m.bending_length_dof)}; checked: '
      f'{law_words(dof)})'
    )
  return out


def readings_words(check: dict) -> dict[str, str]:
  """Each reading of ``check``'s sets as its note prints it: its relative sd
  (a bending length's range where drawn over one, and a t law's degrees of
  freedom)."""
  out = {k: f'{100 * v:.2g}%' for k, v in check['readings'].items()}
  lo, hi, dof = length_law(check)
  if 'length_sd_range' in check:
    out['bending_length'] = f'{100 * lo:.2g}-{100 * hi:.2g}%'
  if dof:
    out['bending_length'] += f" (Student's t, {dof:g} degrees of freedom)"
  return out


def protocol_note(config, recordings: int, path: str = PROTOCOL_CHECKS_FILE):
  """The shipped protocol check's note for a protocol joint of ``recordings``
  with ``config`` (its readings: an area weight, a bending length, the air
  free; each recording's wind read), or None where the check does not cover
  it: another number of recordings, a likelihood setting, fabric, size or
  camera error it was not measured with, or readings unlike its sets'
  (``_covers_readings``: a check per camera error and bending-length
  readings; of those that cover it, the one whose sets' camera errors were
  most like its own: ``carried_errors.recordings_gap``).

  The note quotes how often its intervals, as printed (not recalibrated),
  held the truth on those sets (``'measured'``), and names the quantities it
  did not measure. A protocol joint keeps its shared discrepancy, as the
  check's sets had it (``'shared_discrepancy'``)."""
  m = config.measured
  mine = camera_of(config.flat())
  if not is_protocol(m):
    return None
  covering = sorted(  # those measured with its camera error and readings like
    (  # its, those whose sets' camera errors were most like its own first
      c for c in checks_of(recordings, path)
      if not differing_fields(config, c) and _covers_readings(c, m)
    ),
    key=lambda c: recordings_gap(table_of(c), mine),
  )  # fmt: skip
  if not covering:
    return None
  check = covering[0]
  return {
    'matches': True, 'mode': check['mode'], 'measured': True,
    'shared_discrepancy': True, 'setting': check['setting'],
    'physics': check['physics'], 'coverage': check['coverage'],
    'unmeasured': check.get('unmeasured', []),
    'readings': readings_words(check),
  }  # fmt: skip


def is_protocol(measured) -> bool:
  """Whether an estimate's readings are a protocol's (an area weight and a
  bending length read, the air coefficient free): what a protocol check is
  measured for."""
  return (
    measured.area_weight_sd > 0 and measured.bending_length_sd > 0 and measured.air_free
  )


def protocol_miss(config, recordings: int, path: str = PROTOCOL_CHECKS_FILE):
  """The note of a protocol joint of ``recordings`` with ``config`` that no
  shipped check covers (``protocol_note`` is None): the nearest check (the
  fewest differences, then the nearest number of fan settings, then the nearest
  camera error) and what keeps it from this joint, each in words
  (``'matches': False``); None where it is no protocol joint or nothing is
  shipped."""
  checks = checks_of_any(path)
  if not is_protocol(config.measured) or not checks:
    return None
  counts = sorted({c['recordings'] for c in checks})
  mine = camera_of(config.flat())
  levels = [table_of(c) for c in checks]

  def misses(check):
    names = differing_fields(config, check)
    out = [] if check['recordings'] == recordings else [
      f'{recordings} fan settings (protocol checks of '
      f'{", ".join(map(str, counts))})'
    ]  # fmt: skip
    out += [n.replace('_', ' ') for n in names if n not in CAMERA_FIELDS]
    if set(names) & set(CAMERA_FIELDS):
      out.append(camera_difference(mine, levels, 'protocol checks'))
    return out + _reading_misses(check, config.measured)

  differs, nearest = min(
    ((misses(c), c) for c in checks),
    key=lambda mc: (
      len(mc[0]),
      abs(mc[1]['recordings'] - recordings),
      camera_gap(table_of(mc[1])[:2], mine),
    ),
  )  # fmt: skip
  return {
    'matches': False, 'n': nearest['n'],
    'setting': f'{nearest["mode"]} ({nearest["setting"]})',
    'likelihood': nearest['likelihood'], 'sharpness': nearest['sharpness'],
    'differs': differs,
  }  # fmt: skip


def checks_of_any(path: str = PROTOCOL_CHECKS_FILE) -> list[dict]:
  """Every shipped protocol check, of any number of fan settings."""
  return read_calibration(path).get('checks', []) if os.path.isfile(path) else []
