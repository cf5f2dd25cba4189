"""What each quantity is called and in which unit a person reads it (issue 76).

The search works in scales (bending as a multiple of the fabric's measured
rigidity, area weight in kg/m^2); a lab reports bending rigidity in uN m
(the scale times ``physsim.reference_rigidity``), area weight in g/m^2 and
Peirce's bending length in mm. ``estimate.json`` keeps the search's own
scales, labelled; the tables (``report``) and their notes print these. A
result without a known fabric keeps the scale (``SCALE_NAMES``).
"""

from __future__ import annotations

import physsim

# What the table calls each quantity (short enough for ``report.WIDTH``).
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
