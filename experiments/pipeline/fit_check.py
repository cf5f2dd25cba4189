"""Does the estimated fabric reproduce its recording? A posterior predictive check.

Two questions a person asks of an estimate, answered after the posterior:

- ``predictive``: simulations at the estimate's point, differing only in
  their gusts, lie as far from the recording as from each other when the
  simulator can reproduce it (the recording is one more gust draw): their
  mean squared shape distance to the recording over the mean between pairs of
  them (the gust floor) is near 1. Far above it, no fabric of the box makes
  this recording with these settings.
- ``conflicts``: a reading (anemometer, scale, strip) that the video alone
  (the search's likelihood with the box's own prior) puts outside its 99%
  range: which reading or setting the video disagrees with.
"""

from __future__ import annotations

import numpy as np

import bo
import physsim
from experiments.pipeline.measurements import FIELDS, Measured

# Mean distance to the recording over the gust floor beyond which the fit is
# flagged: the recording is one more gust draw when the simulator fits, so
# the ratio scatters about 1 (8 draws: a few tenths); a sensor's noise and
# the point's own uncertainty add a little more.
MISFIT_RATIO = 3.0
VIDEO_LEVEL = 0.99  # the video alone's central range a reading is read against
READING_SDS = 2.0  # ... widened by this many of the reading's own sd


def predictive(scores) -> dict | None:
  """The gust-floor check of ``scores`` (``objective.Scores``): simulations
  at one point that differ only in their gusts, with their shape summaries'
  residuals to the recording (``search.run``'s replicas at the posterior's
  median). None where fewer than three survived or the distance has no
  shape part."""
  ok = np.asarray(scores.valid) & np.isfinite(scores.psd)
  r = np.asarray(scores.residual, np.float64)[ok]
  if len(r) < 3 or not np.any(r):
    return None
  fit = float(np.mean(np.sum(r**2, axis=1)))  # to the recording
  i, j = np.triu_indices(len(r), 1)
  floor = float(np.mean(np.sum((r[i] - r[j]) ** 2, axis=1)))  # between draws
  ratio = fit / floor if floor > 0 else float('inf')
  return {
    'simulations': int(len(r)),
    'distance_m2': fit,
    'gust_floor_m2': floor,
    'ratio': ratio,
    'fits': bool(ratio <= MISFIT_RATIO),
  }


def _weighted_range(values, weights, level: float) -> tuple[float, float]:
  order = np.argsort(values)
  v, cdf = values[order], np.cumsum(weights[order])
  cdf = cdf / cdf[-1]
  a = (1.0 - level) / 2.0
  return float(v[np.searchsorted(cdf, a)]), float(
    v[min(np.searchsorted(cdf, 1.0 - a), len(v) - 1)]
  )


def conflicts(log_lik, grid, space: physsim.SearchSpace, measured: Measured) -> list:
  """Each reading the video alone puts outside its ``VIDEO_LEVEL`` range by
  more than ``READING_SDS`` of the reading's sd: ``{'reading', 'value',
  'sd', 'video': [lo, hi]}``. The video alone: the likelihood on the grid
  with the box's own prior (uniform in the unit cube). With the air
  coefficient free the wind reading is of the true wind, which the video does
  not see apart from the air: not checked."""
  log_lik = np.asarray(log_lik, np.float64)
  if not np.isfinite(log_lik).any():
    return []
  weights = np.exp(
    np.where(np.isfinite(log_lik), log_lik - np.nanmax(log_lik), -np.inf)
  )
  phys = physsim.params.from_unit(bo.posterior.grid_points(grid), space)
  values = dict(zip(FIELDS, (np.ravel(a) for a in phys), strict=True))
  if space.rigidity > 0:
    values['bending_length'] = np.ravel(
      physsim.params.bending_length(
        values['bending_scale'], values['area_weight'], space.rigidity
      )  # fmt: skip
    )
  out = []
  for name in ('wind_speed', 'area_weight', 'bending_length'):
    v, sd = getattr(measured, name), getattr(measured, f'{name}_sd')
    if not sd > 0 or name not in values:
      continue
    if name == 'wind_speed' and measured.air_free:
      continue
    lo, hi = _weighted_range(values[name], weights, VIDEO_LEVEL)
    if v + READING_SDS * sd < lo or v - READING_SDS * sd > hi:
      out.append({'reading': name, 'value': v, 'sd': sd, 'video': [lo, hi]})
  return out
