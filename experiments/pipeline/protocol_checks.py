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
from experiments.pipeline.carried_errors import FACTOR

# Coverage of a protocol joint's intervals (fan settings each with an
# anemometer, a scale and a bending length; the air coefficient free),
# measured on protocol sets of another physics (``experiments.air_protocol
# --install``): ``{"checks": [...]}``, one per number of fan settings. Not
# recalibrated tables: the intervals as printed, and how often they held.
PROTOCOL_CHECKS_FILE = os.path.join(os.path.dirname(__file__), 'protocol_checks.json')


def check_of(recordings: int, path: str = PROTOCOL_CHECKS_FILE) -> dict | None:
  """The shipped check of protocol joints of ``recordings`` fan settings, or
  None where none was measured."""
  if not os.path.isfile(path):
    return None
  checks = read_calibration(path).get('checks', [])
  return next((c for c in checks if c['recordings'] == recordings), None)


def with_check(shipped: dict | None, check: dict) -> dict:
  """The shipped file's content with ``check`` in place of the one of its
  number of recordings (the others kept)."""
  kept = [c for c in (shipped or {}).get('checks', [])
          if c['recordings'] != check['recordings']]  # fmt: skip
  return {'checks': sorted([*kept, check], key=lambda c: c['recordings'])}


def protocol_note(config, recordings: int, path: str = PROTOCOL_CHECKS_FILE):
  """The shipped protocol check's note for a protocol joint of ``recordings``
  with ``config`` (its readings: an area weight, a bending length, the air
  free; each recording's wind read), or None where the check does not cover
  it: another number of recordings, a likelihood setting, fabric or size it
  was not measured with, or a reading more than twice as certain or
  uncertain as its sets' (or a bending length of another error law).

  The note quotes how often its intervals, as printed (not recalibrated),
  held the truth on those sets (``'measured'``), and names the quantities it
  did not measure. A protocol joint keeps its shared discrepancy, as the
  check's sets had it (``'shared_discrepancy'``)."""
  check = check_of(recordings, path)
  m = config.measured
  given = m.area_weight_sd > 0 and m.bending_length_sd > 0 and m.air_free
  if not given or check is None or differing_fields(config, check):
    return None
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
