"""The shipped protocol check, and the note of a protocol joint it covers.

A protocol joint (two to four fan settings, each with an anemometer, a
scale and a bending length; the air coefficient free) has no recalibrated
tables: its intervals are printed as the posterior gives them, and how often
they held the truth was measured on protocol sets of another physics
(``experiments.air_protocol --install``). An estimate like those sets quotes
that measurement (``setup.calibration``); any other stays with the tables'
note (``calibration_tables``).
"""

from __future__ import annotations

import os

from experiments.pipeline.calibration_tables import differing_fields, read_calibration
from experiments.pipeline.carried_errors import FACTOR, camera_gap, camera_of, table_of

# Coverage of a protocol joint's intervals (fan settings each with an
# anemometer, a scale and a bending length; the air coefficient free),
# measured on protocol sets of another physics (``experiments.air_protocol
# --install``): ``{"checks": [...]}``, one per number of fan settings. Not
# recalibrated tables: the intervals as printed, and how often they held.
PROTOCOL_CHECKS_FILE = os.path.join(os.path.dirname(__file__), 'protocol_checks.json')


def checks_of(recordings: int, path: str = PROTOCOL_CHECKS_FILE) -> list[dict]:
  """The shipped checks of protocol joints of ``recordings`` fan settings
  (one per camera error they were measured with; ``carried_errors.table_of``)."""
  if not os.path.isfile(path):
    return []
  checks = read_calibration(path).get('checks', [])
  return [c for c in checks if c['recordings'] == recordings]


def check_of(
  recordings: int, path: str = PROTOCOL_CHECKS_FILE, camera=(0.0, 0.0, 0.0)
) -> dict | None:
  """The shipped check of protocol joints of ``recordings`` fan settings
  measured with ``camera`` (metres, degrees, spread: ``table_of``; default
  exact cameras), or None where none was measured."""
  want = tuple(float(x) for x in camera)
  return next((c for c in checks_of(recordings, path) if table_of(c) == want), None)


def with_check(shipped: dict | None, check: dict) -> dict:
  """The shipped file's content with ``check`` in place of the one of its
  number of recordings and camera error (the others kept)."""
  key = lambda c: (c['recordings'], table_of(c))  # noqa: E731
  kept = [c for c in (shipped or {}).get('checks', []) if key(c) != key(check)]
  return {'checks': sorted([*kept, check], key=key)}


def protocol_note(config, recordings: int, path: str = PROTOCOL_CHECKS_FILE):
  """The shipped protocol check's note for a protocol joint of ``recordings``
  with ``config`` (its readings: an area weight, a bending length, the air
  free; each recording's wind read), or None where the check does not cover
  it: another number of recordings, a likelihood setting, fabric, size or
  camera error it was not measured with (a check per camera error; the
  nearest that covers it), or a reading more than twice as certain or
  uncertain as its sets' (or a bending length of another error law).

  The note quotes how often its intervals, as printed (not recalibrated),
  held the truth on those sets (``'measured'``), and names the quantities it
  did not measure. A protocol joint keeps its shared discrepancy, as the
  check's sets had it (``'shared_discrepancy'``)."""
  m = config.measured
  given = m.area_weight_sd > 0 and m.bending_length_sd > 0 and m.air_free
  mine = camera_of(config.flat())
  covering = sorted(  # those measured with its camera error, the nearest first
    (c for c in checks_of(recordings, path) if not differing_fields(config, c)),
    key=lambda c: camera_gap(table_of(c)[:2], mine),
  )
  if not given or not covering:
    return None
  check = covering[0]
  for name, rel in check['readings'].items():
    value, sd = (getattr(m, name), getattr(m, f'{name}_sd'))
    if not (value > 0 and rel / FACTOR <= sd / value <= FACTOR * rel):
      return None
  if m.bending_length_dof != check.get('length_dof', 0.0):
    return None
  return {
    'matches': True, 'mode': check['mode'], 'measured': True,
    'shared_discrepancy': True, 'setting': check['setting'],
    'physics': check['physics'], 'coverage': check['coverage'],
    'unmeasured': check.get('unmeasured', []),
    'readings': {k: f'{100 * v:.2g}%' for k, v in check['readings'].items()},
  }  # fmt: skip
