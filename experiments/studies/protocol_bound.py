"""The protocol study's bound: how much a set of recordings narrows bending
and area weight, and how far another physics would pull them.

A set of recordings of one fabric shares bending and area weight; each fan
setting has its own wind. With the search box as a Gaussian prior in log
space (the box's variance, ``bo.design.log_box_sd``), the Fisher information
of the set (each recording's slopes and noise,
``protocol_slopes.simulate_candidate``) gives the Cramer-Rao posterior widths
of log bending and log area weight, reported as the prior's 90% width over the
posterior's ("narrowing", ``set_narrowing``), in three modes (``MODES``): the
video alone, every wind read by an anemometer, and the area weight weighed.
``set_bias`` is the first-order shift a misfit of the statistics causes.
"""

from __future__ import annotations

import numpy as np

import physsim
from bo import design
from experiments.studies import protocol_camera

# the video alone, every wind read by an anemometer, the area weight weighed
MODES = ('video', 'anemometer', 'scale')


def priors(material: str, reading: float) -> dict[str, float]:
  """Prior standard deviations in log space: the search box's (bending 0.1-10x,
  the fabric's area-weight range, wind 1-6 m/s) and a reading's."""
  space = physsim.search_space(material)
  return {
    'log_bending': design.log_box_sd(*space.bending_scale),
    'log_area_weight': design.log_box_sd(*space.area_weight),
    'log_wind': design.log_box_sd(*space.wind_speed),
    'reading': float(np.log1p(reading)),
  }


def stat_index(stats) -> list[int] | slice:
  """Indices into ``protocol_camera.STATS`` of the statistics ``stats`` names
  (every row: none named); a ValueError naming an unknown or repeated one."""
  known = protocol_camera.STATS
  unknown = [x for x in stats if x not in known]
  if unknown or len(set(stats)) < len(stats):
    raise ValueError(f'--stats={",".join(stats)}: need distinct names of {list(known)}')
  return [known.index(x) for x in stats] if stats else slice(None)


def _assemble(rows, prior, mode, shared, drag_sd):
  """The set's parameters and each recording's slopes on them: (the prior
  sds (n,), per recording (slopes (m, p_k), its parameters' indices))."""
  shared = list(shared) if shared is not None else [False] * len(rows)
  windy = [r['wind'] > 0 for r in rows]
  n_wind = sum(w and not s for w, s in zip(windy, shared, strict=True))
  drag = drag_sd > 0 and any(windy)
  n = 2 + n_wind + int(drag)
  parts = []
  k = 1
  for r, w, s in zip(rows, windy, shared, strict=True):
    slopes = np.array(r['slopes'])
    index = [0, 1]
    if w:
      k += 0 if s else 1
      index.append(k)
      if drag:
        slopes = np.concatenate([slopes, 0.5 * slopes[:, 2:3]], axis=1)
        index.append(n - 1)
    parts.append((slopes, index))
  sd = np.full(n, prior['log_wind'] if mode != 'anemometer' else prior['reading'])
  sd[0] = prior['log_bending']
  sd[1] = prior['reading'] if mode == 'scale' else prior['log_area_weight']
  if drag:
    sd[-1] = drag_sd
  return sd, parts


def _information(rows, prior, mode, shared, drag_sd, stats=()):
  """``_assemble``'s prior sds and parts (each recording's slopes on the
  statistics ``stats`` read, ``stat_index``), and the set's Fisher
  information."""
  sd, parts = _assemble(rows, prior, mode, shared, drag_sd)
  idx = stat_index(stats)
  parts = [(j[idx], i) for j, i in parts]
  infos = [
    design.fisher(j, np.array(r['noise_cov'])[idx][:, idx])
    for (j, _), r in zip(parts, rows, strict=True)
  ]
  return sd, parts, design.combine(infos, [i for _, i in parts], len(sd))


def set_narrowing(rows: list[dict], prior: dict[str, float], mode: str,
                  shared=None, drag_sd: float = 0.0, stats=()) -> dict:  # fmt: skip
  """Narrowing of log bending and log area weight by the recordings ``rows``
  (each ``protocol_slopes.simulate_candidate``'s dict) together, in ``mode``:
  ``'video'``, ``'anemometer'`` (every wind read) or ``'scale'`` (area weight
  read).

  ``shared``: per row, whether it was recorded at the fan setting of the row
  before it (one wind parameter for both). ``drag_sd``: the prior standard
  deviation of the log of the wind force's coefficient, one for every
  recording in the fan: what the simulator's drag law gets wrong about the
  world (0: nothing). The force goes as that coefficient times v^2, and the
  slopes are taken in steady wind with the cloth at rest, so a recording's
  slope in it is half its slope in log wind. ``stats``: the statistics read
  (``stat_index``; all by default)."""
  sd, _, total = _information(rows, prior, mode, shared, drag_sd, stats)
  n = len(sd)
  post = design.widths(sd, total)
  no_video = design.widths(sd, np.zeros((n, n)))
  return {
    'bending': float(prior['log_bending'] / post[0]),
    'area_weight': float(prior['log_area_weight'] / post[1]),
    'bending_sd_log': float(post[0]),
    'area_weight_sd_log': float(post[1]),
    'area_weight_without_video': float(prior['log_area_weight'] / no_video[1]),
  }


def set_bias(rows: list[dict], residuals: list, prior: dict[str, float], mode: str,
             shared=None, drag_sd: float = 0.0, stats=()) -> dict:  # fmt: skip
  """What a fit with the estimator's simulator makes of recordings of another
  physics, to first order: the shift of the posterior mean of (log bending,
  log area weight) that the statistics' misfit ``residuals`` (per row,
  ``protocol_slopes.world_residual``) causes, (F + P)^-1 sum_k J_k^T R_k^-1 r_k,
  beside the posterior's sd (``set_narrowing``'s model of the set, on
  ``stats``)."""
  sd, parts, info = _information(rows, prior, mode, shared, drag_sd, stats)
  idx = stat_index(stats)
  score = np.zeros(len(sd))
  for (j, index), r, res in zip(parts, rows, residuals, strict=True):
    score[index] += j.T @ np.linalg.solve(
      np.array(r['noise_cov'])[idx][:, idx], np.asarray(res, float)[idx]
    )
  cov = np.linalg.inv(info + np.diag(1.0 / sd**2))
  shift = cov @ score
  post = np.sqrt(np.diag(cov))
  return {
    'bending_bias_log': float(shift[0]),
    'area_weight_bias_log': float(shift[1]),
    'area_weight_sd_log': float(post[1]),
    'area_weight_z': float(shift[1] / post[1]),
  }
