"""Posteriors of (bending, wind, area weight) in physical units: summaries, joints.

The stage after the search: the search (``bo.PosteriorSearch``) works in the
unit cube of the material's search box with the prior of
``measurements.log_prior``; this module turns its draws into physical
summaries (posterior median, 50% and 90% central intervals, the load ratio
rho v^2 / (w g)), places draws within their grid cells by a bending length's
reading, and combines several recordings of one fabric into a joint
posterior (one bending and area weight, one wind per recording).
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from jax.scipy.special import logsumexp

import bo
import physsim
from experiments.pipeline import files, measurements, posterior_figure
from experiments.pipeline.measurements import (
  FIELDS,
  Measured,
  cell_offsets,
  length_term,
  log_prior,
  physical,
  reading_range,
)

LEVELS = (50, 90)
# The error each quantity is judged by (tables, calibrations): bending as a
# factor, the rest in percent. The prior's own point minimises it (the prior
# is known exactly), and a point is moved towards the prior's on its scale.
ERROR_LOSS = {'bending_scale': 'factor', 'wind_speed': 'relative',
              'area_weight': 'relative', 'load_ratio': 'relative',
              'air_coefficient': 'factor'}  # fmt: skip
# The loss a posterior's own point minimises (``bo.calibration.bayes_point``).
# For the wind and the load ratio, which the video measures, the median
# (``'log'``): the percent error's action leans to the low tail of a wide
# posterior, and on recordings of another physics (224, four seeds) and of the
# windy rig the median was the closer of the two (docs/studies/calibration.md, "The
# point"); on the estimator's own physics the two tie.
POINT_LOSS = {**ERROR_LOSS, 'wind_speed': 'log', 'load_ratio': 'log',
              'air_coefficient': 'log'}  # fmt: skip
# widths compared on a log scale
LOG_SCALED = ('bending_scale', 'load_ratio', 'air_coefficient')


def refine_draws(samples_unit, grid, space: physsim.SearchSpace, measured: Measured,
                 seed: int, sub=(64, 8)) -> np.ndarray:  # fmt: skip
  """Draws from a grid posterior (uniform within their cells) with their
  bending and area weight placed within the cell by a bending length's
  reading (``log_prior`` with ``grid``: the cell's mass is the term's mean
  over the cell, so within it the draw follows the term): a continuous
  bending where the cell is wider than the reading. Unchanged without one.

  Args:
    samples_unit: (S, 3) unit draws, each within its grid cell.
    grid: cells per dimension.
    space, measured: the box and the readings.
    seed: of the within-cell draws.
    sub: sub-points per cell along bending and area weight.
  """
  x = np.array(samples_unit, np.float64)
  if not measured.bending_length_sd > 0 or not len(x):
    return x
  g = np.asarray(grid, np.float64)
  cell = np.clip(np.floor((x + 1.0) / 2.0 * g), 0, g - 1)
  # The term depends on bending and area weight alone: one row of sub-points
  # per (bending, area weight) cell the draws fell in, not one per draw.
  cells, which = np.unique(cell[:, [0, 2]], axis=0, return_inverse=True)
  which = np.ravel(which)
  centre = -1.0 + (2.0 * cells + 1.0) / g[[0, 2]]
  offsets = cell_offsets(grid, sub)[:, [0, 2]]
  pts = np.clip(centre[:, None, :] + offsets[None], -1.0, 1.0)  # (U, K, 2)
  flat = pts.reshape(-1, 2)
  p = physsim.params.from_unit(
    np.stack([flat[:, 0], np.zeros(len(flat)), flat[:, 1]], axis=1), space
  )
  term = length_term(p.bending_scale, p.area_weight, space, measured)
  term = term.reshape(len(cells), -1)
  cdf = np.cumsum(np.exp(term - term.max(axis=1, keepdims=True)), axis=1)
  width = 2.0 / g
  rng = np.random.default_rng([seed, 29])
  for start in range(0, len(x), 4096):  # the same draws whatever the chunking
    part = slice(start, start + 4096)
    mine = cdf[which[part]]
    u = rng.random(len(mine)) * mine[:, -1]
    k = np.minimum((mine < u[:, None]).sum(axis=1), mine.shape[1] - 1)
    jitter = (rng.random((len(mine), 2)) - 0.5) * np.array(
      [width[0] / sub[0], width[2] / sub[1]]
    )
    chosen = pts[which[part], k]
    x[part, 0] = chosen[:, 0] + jitter[:, 0]
    x[part, 2] = chosen[:, 1] + jitter[:, 1]
  return np.clip(x, -1.0, 1.0)


def prior_points(space: physsim.SearchSpace, measured: Measured, n: int = 2001) -> dict:
  """Per field and for the load ratio, the prior's own least-error point
  (``bo.calibration.bayes_point`` for ``ERROR_LOSS``),
  by quadrature: the prior is a product over the fields (uniform in the box,
  bending log-uniform, times each reading's Gaussian), so each marginal is a
  1-D integral and the load ratio's a 2-D one.

  Args:
    space: the search box.
    measured: the readings in the prior.
    n: nodes per field.
  """
  u = -1.0 + (2.0 * np.arange(n) + 1.0) / n  # cell centres of [-1, 1]
  nodes, weights = [], []
  for i in range(3):
    pts = np.zeros((n, 3))
    pts[:, i] = u
    lp = log_prior(pts, space, measured)  # other fields at 0: a constant here
    nodes.append(physical(pts, space)[:, i])
    weights.append(np.exp(lp - lp.max()))
  if measured.bending_length_sd > 0:  # bending and area weight read together
    # On the (bending x area weight) grid the prior is the area weight's own
    # terms times the strip's reading, which alone couples the two: the 1-D
    # terms once per line, the reading by broadcasting (the log prior of the
    # m x m points, without mapping each of them to physical values).
    m = min(n, 601)
    line = np.zeros((m, 3))
    line[:, 0] = line[:, 2] = -1.0 + (2.0 * np.arange(m) + 1.0) / m
    phys = physical(line, space)
    unread = dataclasses.replace(
      measured, bending_length=0.0, bending_length_sd=0.0, bending_length_dof=0.0
    )
    reading_range(space, 'bending_length')  # as log_prior: the box's fabric
    lp = log_prior(line * [0.0, 0.0, 1.0], space, unread)[None, :] + length_term(
      phys[:, :1], phys[None, :, 2], space, measured
    )
    joint_w = np.exp(lp - lp.max())
    nodes[0], weights[0] = phys[:, 0], joint_w.sum(axis=1)
    nodes[2], weights[2] = phys[:, 2], joint_w.sum(axis=0)
  out = {
    name: bo.calibration.bayes_point(nodes[i], ERROR_LOSS[name], weights=weights[i])
    for i, name in enumerate(FIELDS)
  }
  k = slice(None, None, max(1, len(nodes[2]) // 301))  # the ratio on a coarser grid
  v, w = np.meshgrid(nodes[1][k], nodes[2][k], indexing='ij')
  wt = np.outer(weights[1][k], weights[2][k])
  out['load_ratio'] = bo.calibration.bayes_point(
    physsim.load_ratio(v, w).ravel(), ERROR_LOSS['load_ratio'], weights=wt.ravel()
  )
  return out


_U = (np.arange(400) + 0.5) / 400  # shares of the calibrated distribution


def _stats(x: np.ndarray, prior: np.ndarray, name: str, cdf_levels=None,
           weight: float | None = None,
           prior_point: float | None = None) -> dict:  # fmt: skip
  """Median, central intervals, sd, how much narrower than the prior (on a
  log scale for bending and the load ratio), and the point (``bayes``): the
  posterior's own least-``POINT_LOSS`` point, moved towards the prior's
  least-``ERROR_LOSS`` one (``prior_point``, default from the ``prior``
  draws) by ``1 - weight`` (``bo.calibration.shrink``; 1: the posterior's
  alone).

  ``weight`` None (no calibration gave one): 0 for a quantity the data did
  not inform (its 90% interval at least ``bo.calibration.UNINFORMED`` of the
  prior's width, the calibration's own rule for such quantities), else 1.
  What little such a posterior leans one way is as likely the surrogate's
  noise as the video's information, so the prior's own point is the safer
  answer (the one calibrations chose for such quantities: weight 0).

  ``cdf_levels``: the CDF levels of ``bo.calibration.PROBS`` at which to read
  ``x`` (recalibrated); default the probs themselves."""
  probs = bo.calibration.PROBS
  nominal = cdf_levels is None
  lv = bo.calibration.nominal_levels() if nominal else np.asarray(cdf_levels)
  q = np.quantile(x, np.clip(lv, 0.0, 1.0))
  at = lambda p: float(q[probs.index(p)])
  out = {'median': at(0.5), 'std': float(np.std(x))}
  for level in LEVELS:
    a = level / 100
    out[f'interval_{level}'] = [at(round((1 - a) / 2, 2)), at(round((1 + a) / 2, 2))]
  f = np.log if name in LOG_SCALED else (lambda a: a)
  lo, hi = out['interval_90']
  prior_width = float(np.diff(f(np.quantile(prior, [0.05, 0.95])))[0])
  out['narrowing_90'] = prior_width / max(float(f(hi) - f(lo)), 1e-12)  # 1: the prior's
  if weight is None:
    uninformed = 1.0 / out['narrowing_90'] >= bo.calibration.UNINFORMED
    weight = 0.0 if uninformed else 1.0
  calibrated = (
    x if nominal else bo.calibration.linear_quantiles(x, bo.calibration.warp(_U, lv))
  )
  metric = ERROR_LOSS[name]
  own = bo.calibration.bayes_point(calibrated, POINT_LOSS[name])
  if prior_point is None:
    prior_point = bo.calibration.bayes_point(prior, metric)
  out['bayes'] = float(bo.calibration.shrink(own, prior_point, weight, metric))
  out['bayes_weight'] = float(weight)
  return out


def summarise(samples_unit, space: physsim.SearchSpace, prior_unit,
              recalibration: dict | None = None, weights: dict | None = None,
              measured: Measured | None = None, air=None,
              air_simulated=None) -> dict:  # fmt: skip
  """Physical summaries of posterior draws, each beside the prior's.

  With ``air`` (the air coefficient free: ``(c of the draws (S,), c of the
  prior's (S',))``, ``measurements.air_given_wind``), the draws' wind is the
  simulator's effective one: the fabric's true wind v_eff / sqrt(c) is
  summarised as ``wind_speed`` and c as ``air_coefficient``; the load ratio
  stays the effective load rho v_eff^2 / (w g) the video sees. Neither has a
  recalibrated level (they read at the nominal ones). ``air_simulated``
  (S,): the c each draw's effective wind was drawn with where it differs
  from the fabric's (a joint's shared discrepancy, ``joint``'s
  ``'air_simulated'``): the true wind is v_eff / sqrt of it.

  Args:
    samples_unit: (S, 3) posterior draws, unit cube.
    space: the search box.
    prior_unit: (S', 3) draws of the prior (same measured information).
    recalibration: ``{field: (len(PROBS),) CDF levels}`` from a calibration
      on simulations (``bo.calibration``), or None. With it, each quantity is
      read from the posterior's defensive mixture with the prior at those
      levels, as the calibration read it; without, at the nominal levels.
    weights: ``{field: weight}`` of each posterior point against the prior's
      own (``bo.calibration.choose_weight`` on the calibration), or None:
      0 for a quantity the data did not inform, else 1 (see ``_stats``).
    measured: the readings in the prior, for its own points by quadrature
      (``prior_points``); None: from the prior draws.

  Returns:
    ``{field: stats, 'load_ratio': stats}``; stats hold ``median``,
    ``interval_50``, ``interval_90``, ``std``, ``narrowing_90`` (the
    prior's 90% width over the posterior's, log scale for bending and the
    ratio: 1 means the data told nothing) and ``bayes`` (the value with the
    least expected percent error, factor error for bending).
  """
  with_ratio = lambda p: np.concatenate(
    [p, physsim.load_ratio(p[:, 1], p[:, 2])[:, None]], axis=1
  )
  post = with_ratio(physical(samples_unit, space))
  prior = with_ratio(physical(prior_unit, space))
  names = [*FIELDS, 'load_ratio']
  if air is not None:
    c_post, c_prior = (np.ravel(np.asarray(c, np.float64)) for c in air)
    c_wind = c_post if air_simulated is None else np.ravel(air_simulated)
    post[:, 1] /= np.sqrt(c_wind)
    prior[:, 1] /= np.sqrt(c_prior)
    post = np.concatenate([post, c_post[:, None]], axis=1)
    prior = np.concatenate([prior, c_prior[:, None]], axis=1)
    names.append('air_coefficient')
    # the readings' own points: the wind reading is of the true wind
    measured = None if measured is None else dataclasses.replace(
      measured, air_coefficient='fixed'
    )  # fmt: skip
  points = None if measured is None else prior_points(space, measured)
  if recalibration is not None:
    post = bo.calibration.defensive(post, prior)
  free = ('wind_speed', 'load_ratio', 'air_coefficient') if air is not None else ()
  return {
    name: _stats(
      post[:, i], prior[:, i], name,
      cdf_levels=None
      if recalibration is None or name in free
      else recalibration[name],
      weight=(weights or {}).get(name),
      prior_point=None if points is None or name not in points else points[name],
    )
    for i, name in enumerate(names)
  }  # fmt: skip


def prior_samples(key, grid, log_prior_grid, n: int) -> np.ndarray:
  """Draws of the prior on the grid (as the posterior's are drawn)."""
  pts = bo.posterior.grid_points(grid)
  with jax.enable_x64(True):  # float64, as the posterior's draws
    lp = bo.posterior.log_normalise(jax.numpy.asarray(log_prior_grid))
    return np.asarray(
      bo.posterior.sample_grid(key, jax.numpy.asarray(pts), lp, grid, n)
    )


BIAS_NODES = 9  # Gauss-Hermite nodes of a shared discrepancy


def _shifted(ev: np.ndarray, factor: float, area_weight_range) -> np.ndarray:
  """(nb, nw) evidence ``ev`` read at area weights ``factor`` times each
  cell's (linear in the w cells; the box's edge value beyond it)."""
  lo, hi = area_weight_range
  nw = ev.shape[1]
  centres = lo + (np.arange(nw) + 0.5) / nw * (hi - lo)
  at = (centres * factor - lo) / (hi - lo) * nw - 0.5  # fractional cell
  at = np.clip(at, 0.0, nw - 1.0)
  i0 = np.floor(at).astype(int)
  i1 = np.minimum(i0 + 1, nw - 1)
  t = at - i0
  return ev[:, i0] * (1 - t) + ev[:, i1] * t


def joint(log_liks, grid, log_prior_grid, key, n: int = 4096,
          shared_bias_sd: float = 0.0, area_weight_range=None,
          fans=None, air=None) -> dict:  # fmt: skip
  """The joint posterior of recordings of one fabric: shared bending and area
  weight, one wind each, or one per fan setting (``fans``).

  Recordings of one fabric in one room share more than the fabric: where the
  simulator differs from the world (the fan's direction, the air's drag, the
  cloth's edges), it differs the same way in each, so their evidence does not
  average that error away. ``shared_bias_sd`` > 0: every recording sees the
  area weight times one common exp(d), d ~ N(0, sd^2), integrated out
  (``BIAS_NODES`` Gauss-Hermite nodes), so the joint's area weight is no
  narrower than about ``sd``. Each wind is drawn given (b, w) without it.

  Args:
    log_liks: per recording, (G,) log likelihood on the grid (C order over
      bending, wind, area weight), all on the same grid and box.
    grid: (nb, nv, nw) cells per dimension.
    log_prior_grid: (G,) the log prior of one recording's (b, v, w), shared
      by all; or one (G,) per recording where their winds were measured
      apart (an anemometer at each fan setting): each a product of a (b, w)
      part, the same for all, and a wind part (its own reading).
    key: PRNG key for the draws.
    n: draws per recording.
    shared_bias_sd: the shared discrepancy's sd in log area weight (0: none).
    area_weight_range: the box's (lo, hi) area weight, kg/m^2 (needed with
      a shared discrepancy: the grid's w cells are linear in it).
    fans: per recording, its fan setting's label (recordings of one label
      were blown by one wind: a sheet and its twin with a known mass at the
      hem, filmed with the fan untouched, share it, and the hem then weighs
      the cloth whatever the wind); None: every recording its own. The
      recordings of one fan setting must have one prior (one reading of it).

    air: with the fabric's air coefficient c free and shared, ``(readings,
      winds)``: each recording's anemometer reading ``(m/s, sd)`` of its true
      wind, and the (nv,) effective winds of the grid's wind cells, m/s. Each
      recording's prior of its effective wind's cell is then its reading's
      mass there given c (``measurements.effective_wind_log_mass``), c is
      drawn with (b, w) from their joint, its prior log-uniform
      (``measurements.air_nodes``), and each wind's place within its cell
      follows its reading (``_draw_wind``); a shared discrepancy
      (``shared_bias_sd``) spreads c's draws by the same log-normal factor.

  Returns:
    ``{'samples': [(n, 3) unit draws of (b, v_k, w) per recording],
    'log_post_bw': (nb, nw)}``: each recording's draws share (b, w) from the
    joint and draw their own wind given them (one for a fan setting's
    recordings, the same in each); with ``air``, ``'air'``: (n,) the shared
    air coefficient's draws (v_k the effective wind), and ``'air_simulated'``:
    them before the shared discrepancy (the true wind is v_k / sqrt of it).

  Raises:
    ValueError: priors or fans for another number of recordings, or two
      recordings of one fan setting with different priors.
  """
  ll, lp, groups, members = _by_fan(log_liks, log_prior_grid, grid, fans)
  fans = list(range(len(log_liks))) if fans is None else list(fans)
  c, log_c, lp_v = _wind_priors(lp, members, air)
  log_bwc = _log_joint_bw(ll, lp, lp_v, log_c, shared_bias_sd, area_weight_range)
  k_bw, k_v, k_jit = jax.random.split(key, 3)
  idx = np.asarray(jax.random.categorical(k_bw, log_bwc.ravel(), shape=(n,)))
  ic, ib, iw = np.unravel_index(idx, log_bwc.shape)
  simulated = None if air is None else _simulated_air(c, ic, k_jit)
  given = [
    None if air is None else (air[1], air[0][ks[0]], simulated) for ks in members
  ]
  keys = lambda k: (jax.random.fold_in(k_v, k), jax.random.fold_in(k_jit, k))  # noqa: E731
  draws = [  # each fan setting's
    _draw_wind(x, (ic, ib, iw), [lv[k] for lv in lp_v], given[k], grid, *keys(k))
    for k, x in enumerate(ll)
  ]
  out = {
    'samples': [draws[groups.index(f)] for f in fans],
    'log_post_bw': np.asarray(logsumexp(log_bwc, axis=0)),
  }
  if air is not None:
    out['air_simulated'] = simulated
    out['air'] = _fabric_air(simulated, shared_bias_sd, k_jit)
  return out


def _log_joint_bw(ll: list, lp: list, lp_v: list, log_c, shared_bias_sd: float,
                  area_weight_range) -> np.ndarray:  # fmt: skip
  """(C, nb, nw) the joint's normalised log posterior of (air node, b, w): the
  prior of (b, w) (each fan setting's wind summed out of its prior ``lp``:
  the same up to a constant), the air node's (``log_c``), and each fan
  setting's evidence ``ll`` for (b, w), its wind integrated out over its prior
  given them (``lp_v``, ``_wind_priors``) and the shared discrepancy too."""
  lp_bw = logsumexp(lp[0], axis=1)  # (nb, nw)
  log_bwc = np.stack(
    [
      lp_bw
      + lc
      + _evidence(
        [np.asarray(logsumexp(x + v, axis=1)) for x, v in zip(ll, lv, strict=True)],
        shared_bias_sd,
        area_weight_range,
      )
      for lc, lv in zip(log_c, lp_v, strict=True)
    ]
  )  # fmt: skip  (C, nb, nw)
  return log_bwc - logsumexp(log_bwc)


def _wind_priors(lp: list, members: list, air) -> tuple:
  """``(c, log c, lp_v)``: the air coefficient's nodes (``[1], [0]`` without
  ``air``) and, per node and fan setting, the log prior of its wind on the
  grid: given (b, w) from its prior (``lp``, per fan setting) where the air
  coefficient is fixed, else its anemometer reading's given c
  (``joint``'s ``air``; ``members``: each fan setting's recordings), one row
  over the grid's wind cells."""
  if air is None:
    lp_v = [[p - logsumexp(p, axis=1)[:, None, :] for p in lp]]  # log p(v_k | b, w)
    return np.ones(1), np.zeros(1), lp_v
  readings, winds = air
  c, log_c = measurements.air_nodes()
  lo, hi = _cell_edges(winds)
  lp_v = [
    [
      measurements.effective_wind_log_mass(lo, hi, *readings[ks[0]], ci)[None, :, None]
      for ks in members
    ]
    for ci in c
  ]  # per c, per fan setting: log P(v_k's cell | c) on the grid's cells
  return c, log_c, lp_v


def _cell_edges(winds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
  """(lo, hi): the edges of the grid's wind cells from their (nv,) centres
  (equal steps, m/s)."""
  winds = np.asarray(winds, np.float64)
  step = float(np.abs(np.diff(winds[:2]))[0]) if len(winds) > 1 else 1.0
  return winds - step / 2, winds + step / 2


def _draw_wind(ll: np.ndarray, cells: tuple, lp_v: list, air, grid,
               key_v, key_jit) -> np.ndarray:  # fmt: skip
  """(n, 3) unit draws of one fan setting: the joint's (b, w) cells (``cells``:
  the air node, bending and area weight cell of each draw) with its wind cell
  drawn from its likelihood ``ll`` (nb, nv, nw) times its prior given them
  (``lp_v``: per air node, ``_wind_priors``'s), each uniform within its
  cell. ``air`` (the air coefficient free: ``(winds, reading, c)``, the grid's
  wind cells, this fan setting's reading and the draws' simulated c): the
  wind's prior varies with c, not with (b, w), and its position within its
  cell follows the reading (``measurements.true_wind_in_cell``), as a
  uniform one would widen the true wind v_eff / sqrt(c) by the cell."""
  ic, ib, iw = cells
  if air is None:  # (n, nv): wind given (b, w)
    cond = ll[ib, :, iw] + lp_v[0][ib, :, iw]
  else:  # ... and c
    cond = ll[ib, :, iw] + np.stack([lv[0, :, 0] for lv in lp_v])[ic]
  iv = np.asarray(jax.random.categorical(key_v, cond, axis=1))
  cell = np.stack([ib, iv, iw], axis=1).astype(np.float64)
  jit = np.array(jax.random.uniform(key_jit, (len(ib), 3)), np.float64)
  if air is not None:
    winds, (reading, sd), c = air
    lo, hi = (e[iv] for e in _cell_edges(winds))
    v = measurements.true_wind_in_cell(lo, hi, reading, sd, c, jit[:, 1])
    jit[:, 1] = np.clip((v * np.sqrt(c) - lo) / (hi - lo), 0.0, 1.0)
  return -1.0 + 2.0 * (cell + jit) / np.asarray(grid, np.float64)


def _simulated_air(c: np.ndarray, ic: np.ndarray, key) -> np.ndarray:
  """(n,) the air coefficient the simulator's push was read with: its nodes
  ``c`` at the draws' node ``ic``, each spread uniformly within its log
  step."""
  ratio = c[1] / c[0] if len(c) > 1 else 1.0
  u = np.asarray(jax.random.uniform(jax.random.fold_in(key, 99), (len(ic),)))
  return c[ic] * ratio ** (u - 0.5)


def _fabric_air(simulated: np.ndarray, shared_bias_sd: float, key) -> np.ndarray:
  """(n,) the fabric's own air coefficient: the ``simulated`` one spread by
  the shared discrepancy's log-normal factor where there is one."""
  if shared_bias_sd <= 0:
    return simulated
  # the pressure the simulator puts on every recording errs by one common
  # factor too (the fan's angle, drag): the fabric's own c is the
  # simulator's times exp(d), d ~ N(0, sd^2)
  z = np.asarray(jax.random.normal(jax.random.fold_in(key, 98), (len(simulated),)))
  return simulated * np.exp(shared_bias_sd * z)


def _by_fan(log_liks, log_prior_grid, grid, fans):
  """Recordings grouped by fan setting: per group the sum of its log
  likelihoods and its prior on the (nb, nv, nw) grid, the groups' labels and
  their members. Raises ValueError on priors or fans for another number of
  recordings, or a group whose recordings have different priors."""
  nb, nv, nw = grid
  ll = [np.asarray(x).reshape(nb, nv, nw) for x in log_liks]
  priors = (
    [log_prior_grid] * len(ll) if np.ndim(log_prior_grid) == 1 else log_prior_grid
  )
  if len(priors) != len(ll):
    raise ValueError(f'{len(priors)} priors for {len(ll)} recordings')
  fans = list(range(len(ll))) if fans is None else list(fans)
  if len(fans) != len(ll):
    raise ValueError(f'{len(fans)} fan settings for {len(ll)} recordings')
  lp = [np.asarray(p).reshape(nb, nv, nw) for p in priors]
  # One wind per fan setting: its recordings' likelihoods multiply at each v.
  groups = list(dict.fromkeys(fans))
  members = [[k for k, f in enumerate(fans) if f == g] for g in groups]
  for g, ks in zip(groups, members, strict=True):
    if any(not np.array_equal(lp[k], lp[ks[0]]) for k in ks):
      raise ValueError(
        f'recordings {ks} share fan setting {g!r} but not its prior: one '
        'wind, one reading of it'
      )
  ll = [sum(ll[k] for k in ks) for ks in members]
  lp = [lp[ks[0]] for ks in members]
  return ll, lp, groups, members


def _evidence(ev: list, shared_bias_sd: float, area_weight_range) -> np.ndarray:
  """(nb, nw): the fan settings' evidence for (b, w) together, their shared
  discrepancy (``joint``'s ``shared_bias_sd``) integrated out."""
  if not shared_bias_sd > 0:
    return sum(ev)
  if area_weight_range is None:
    raise ValueError('a shared discrepancy needs the area weight range of the box')
  z, wt = np.polynomial.hermite_e.hermegauss(BIAS_NODES)
  total = np.stack(
    [
      sum(_shifted(e, float(np.exp(shared_bias_sd * d)), area_weight_range) for e in ev)
      for d in z
    ]
  )  # (nodes, nb, nw)
  return np.asarray(logsumexp(total + np.log(wt / wt.sum())[:, None, None], axis=0))


# -------------------------------------------------------------------- figures


def plot(samples_unit, prior_unit, space, truth, path: str, title: str = '',
         summary: dict | None = None, point: str = 'median',
         units: tuple[dict, dict] | None = None) -> None:  # fmt: skip
  """Marginals (bending, wind, area weight, load ratio) over the prior, and the
  pairs: wind x area weight with the load ratio's iso-lines (the ridge the
  video measures), bending x wind, bending x area weight. The marked point
  (``summary[name][point]``: 'median' or 'bayes'), median and intervals, the
  iso-lines included, are ``summary``'s (``summarise``, e.g. recalibrated:
  what the table prints) where given, else the draws' own. ``units``: the
  table's names and factors (``units.in_units`` of the fabric: bending
  rigidity in uN m, area weight in g/m^2), the axes drawn in them; None: the
  search's own scales (bending as a multiple of the reference, kg/m^2)."""
  fig = figure(samples_unit, prior_unit, space, truth, title, summary, point, units)
  files.savefig(fig, path, dpi=80)
  files.pyplot().close(fig)


def figure(samples_unit, prior_unit, space, truth, title: str = '',
           summary: dict | None = None, point: str = 'median',
           units: tuple[dict, dict] | None = None):  # fmt: skip
  """``plot``'s figure (matplotlib), not saved: the draws and the prior's in
  physical values with the load ratio, each one's summary and the truth's
  (``posterior_figure.draw``)."""
  with_ratio = lambda p: {
    **{name: p[:, i] for i, name in enumerate(FIELDS)},
    'load_ratio': physsim.load_ratio(p[:, 1], p[:, 2]),
  }
  post = with_ratio(physical(samples_unit, space))
  prior = with_ratio(physical(prior_unit, space))
  stats = {
    name: summary[name] if summary else _stats(post[name], prior[name], name)
    for name in posterior_figure.NAMES
  }
  true = None
  if truth is not None:
    true = {f: truth[f] for f in FIELDS}
    true['load_ratio'] = float(
      physsim.load_ratio(truth['wind_speed'], truth['area_weight'])
    )
  return posterior_figure.draw(post, prior, stats, true, space.bounds(), LOG_SCALED,
                               point, title, units)  # fmt: skip
