"""The protocol study's simulated overhangs against the heavy elastica.

An overhang candidate is the textile cantilever test (ASTM D1388): its droop
is set by the bending length (D / (w g))^(1/3) over the overhang. Each
simulated overhang's tip is checked against the exact heavy elastica of its
nominal rigidity (``physsim.cantilever``, float64): how far the simulator's
discretised strip is from the physics the study's bound assumes it shows
(``benchmarks/overhang_mesh.py`` follows the gap as the mesh is refined).
"""

from __future__ import annotations

import physsim
from experiments.studies import protocol_candidates
from physsim import cantilever


def elastica_check(
  overhang: float, bending: float, area_weight: float, reach: float, d0: float
) -> dict:
  """A simulated overhang's tip (``reach`` over the ``overhang``) against the
  heavy elastica of its nominal rigidity D = ``bending`` x ``d0``
  (``physsim.cantilever``): its bending length, both reaches, and the rigidity
  whose elastica reaches as far as the simulation, over D. The last two are
  None for an overhang of more than ``cantilever.MAX_RATIO`` bending lengths
  (hanging straight down), the ratio also beyond the elastica's range."""
  c = float(physsim.params.bending_length(bending, area_weight, d0))
  row = {
    'bending': bending, 'bending_length_cm': float(100 * c),
    'overhang_over_c': float(overhang / c), 'elastica_reach': None,
    'simulated_reach': float(reach), 'rigidity_ratio': None,
  }  # fmt: skip
  if overhang / c > cantilever.MAX_RATIO:
    return row
  row['elastica_reach'] = float(cantilever.tip(overhang / c)[0][0])
  try:
    found = cantilever.bending_length(overhang, reach * overhang)
    row['rigidity_ratio'] = float((found / c) ** 3)
  except ValueError:  # a reach beyond what the elastica's range covers
    pass
  return row


def against_elastica(rows: list[dict], material: str) -> list[dict]:
  """``elastica_check`` of each simulated overhang (slope rows: its clip's mean
  tip reach is ``summary[2]``), those within the elastica's range."""
  d0 = physsim.reference_rigidity(physsim.fabric(material).material)
  out = []
  for r in rows:
    size = protocol_candidates.parse(r['candidate']).size
    row = elastica_check(size, r['bending'], r['area_weight'], r['summary'][2], d0)
    if row['elastica_reach'] is not None:
      out.append({'candidate': r['candidate'], **row})
  return out
