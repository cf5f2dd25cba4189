"""The overhang reader's error law scored on set-ups whose truth is known:
each reading's error in the scales of a Student's t (``with_law``), how often
its intervals hold c (``held``), the law that fits them best (``fitted_law``;
``physsim.overhang_depth``'s ``DOF`` and ``FLOOR`` were fitted so) and the
same for short and long bending lengths apart (``by_length``).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.stats

from physsim import overhang_depth


def with_law(row: dict, floor: float, dof: float) -> dict:
  """``row`` (a reading, or a refusal: unchanged) with its standard
  deviation, t scale and law under ``floor`` and ``dof``
  (``overhang_depth.reading_sd``), and ``z``, its error in scales."""
  if 'c_hat' not in row:
    return row
  if 'read' not in row:
    raise ValueError(
      "a reading without the reader's fit (an abridged results file): run "
      'the set-ups again'
    )
  fit_sd, c_hat = row['read']['fit_sd'], row['c_hat']
  sd = overhang_depth.reading_sd(fit_sd, c_hat, floor, dof)
  scale = math.hypot(fit_sd, floor * c_hat)
  miss = c_hat - row['c']
  z = miss / scale if scale > 0 else math.copysign(math.inf, miss) if miss else 0.0
  return {**row, 'sd': sd, 'scale': scale, 'dof': dof, 'z': z}


def held(rows: list[dict], level: float, dof: float) -> float:
  """How often the rows' central ``level`` intervals (t of ``dof``, each
  row's scale) hold c."""
  z = np.array([r['z'] for r in rows if 'c_hat' in r])
  return float(np.mean(np.abs(z) <= scipy.stats.t.ppf((1 + level) / 2, dof)))


FIT_LEVELS = (0.25, 0.5, 0.75, 0.9)
FIT_DOFS = (2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 20.0)


def fitted_law(rows: list[dict]) -> tuple[float, float]:
  """(dof, floor) whose t intervals at ``FIT_LEVELS`` hold c closest to
  their levels on ``rows`` (least squares; floors on a 0.1% grid): the
  reader's law, fitted on its calibration set-ups."""
  best = None
  for dof in FIT_DOFS:
    for floor in np.arange(0.0, 0.0401, 0.001):
      law = [with_law(r, float(floor), dof) for r in rows]
      loss = sum((held(law, lv, dof) - lv) ** 2 for lv in FIT_LEVELS)
      if best is None or loss < best[0] - 1e-12:
        best = (loss, dof, round(float(floor), 4))
  return best[1], best[2]


# Bending lengths below this (soft fabrics, overhangs of 1.3-2.3 cm) are
# reported apart: before the reader kept the ruler's overhang, their intervals
# held the truth less often than they said (docs/studies/protocol.md, "Limits").
SHORT_C = 0.009  # m


def by_length(rows: list[dict], dof: float) -> dict:
  """The readings' errors and coverage for bending lengths under and over
  ``SHORT_C`` (a law can hold on average and not for a subgroup)."""
  ok = [r for r in rows if 'c_hat' in r]
  groups = {
    'short': [r for r in ok if r['c'] < SHORT_C],
    'long': [r for r in ok if r['c'] >= SHORT_C],
  }
  out = {}
  for name, part in groups.items():
    out[name] = {
      'readings': len(part),
      'mean_abs_error': float(np.mean([abs(r['error']) for r in part])) if part else None,
      'held_90': held(part, 0.9, dof) if part else None,
      'held_50': held(part, 0.5, dof) if part else None,
    }  # fmt: skip
  return out
