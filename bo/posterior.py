"""Likelihood-free posteriors from a GP of a noisy discrepancy (after BOLFI).

A simulator with randomness (gusts, sensor noise) scores a candidate ``x`` by a
discrepancy ``d(x)`` to the data; repeated at one ``x`` it scatters. As in
BOLFI (Gutmann & Corander 2016, JMLR 17), a GP models ``log d`` with a noise
term that *is* that scatter (fitted, with replicates in every batch so it is
measured, not guessed: ``sn`` below), and an approximate likelihood turns the
GP into a posterior. Two likelihoods, both averaged over the GP's uncertainty
``f ~ N(mu(x), s2(x))`` of the latent log discrepancy by Gauss-Hermite
quadrature:

* ``'gibbs'`` (default): ``log L = -c (exp(f - m) - 1) / sn``, ``m`` the lowest
  GP mean. A tempered (Gibbs) likelihood, linear in the discrepancy in units of
  its own noise near the best fit (``sd(d) ~ d sn``). Where a discrepancy rises
  quadratically away from the truth (a squared distance between summaries, as
  the energy distance of embeddings is near its minimum), it is Gaussian with
  the true likelihood's shape, so one constant ``c`` sets the scale (calibrated on
  simulations: ``choose_sharpness``).
* ``'threshold'``: BOLFI's ``L = P(d < h) = Phi((log h - f) / sn)`` with
  ``log h = m + c sn``. Its shape is a plateau with light tails, so one ``c``
  can match one credible level but not every level; kept for comparison.

**Model discrepancy.** Both are in units of ``sn``, the scatter the simulator's own
randomness gives ``log d`` at one ``x``. A recording that the simulator cannot
reproduce (a world of other physics) adds a systematic part to ``d`` at every ``x``:
its best fit is worse and, relative to that, ``log d`` scatters less, so a
likelihood in units of ``sn`` alone sharpens exactly when the model is wrong. The
model error ``e`` (``PosteriorConfig.model_error``, fitted on recordings of another
physics by the calibration study) is scatter of ``log d`` the simulator does not
make, added in quadrature: the likelihood is read in units of ``sqrt(sn^2 + e^2)``
(Kennedy & O'Hagan 2001's discrepancy, as a variance in the discrepancy's log). The
GP's own noise, and so its fit and the acquisition's variance updates, keep ``sn``.

Where the data do not constrain a direction, ``L`` is flat along it and the
posterior keeps the prior's spread: the estimate says "unknown" there.

The posterior ``prior x L`` lives on a grid of cell centres of ``[-1, 1]^d``
(per-dimension resolution, so a well-measured direction gets more cells);
draws are uniform within cells picked by mass.

Acquisition (``maxvar_batch``; Jarvenpaa et al. 2019, Bayesian Analysis): the
point where the unnormalised posterior density is most uncertain under the GP,
``prior(x)^2 Var_f[L(x)]`` (the same quadrature), so simulations go where the
posterior is unsure, not only to the minimum. A batch is chosen greedily, each
pick lowering the GP variance around it as if it had been observed (the
variance does not depend on the value), plus ``replicates`` repeats of the
highest-posterior cell scored with fresh randomness, which measure the noise
where it matters.

``PosteriorSearch`` runs this as ask/tell steps with the interface of
``bo.Minimizer`` (start, ask, tell, done, result), so drivers that batch many
searches run either.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import log_ndtr, logsumexp

from bo import batched, gp, qmc, synthetic
from bo.loop import _capacity, _load, _save

# LogNormal prior on the noise variance of the standardised log discrepancy:
# median 0.05 (a noise sd of ~22% of the log discrepancy's spread over the
# box), wide. Replicates in every batch pin it down.
NOISE_PRIOR = (math.log(0.05), 1.5)
# Likelihoods of one discrepancy (formed again from a saved GP: log_likelihood),
# and all a search can use ('synthetic': bo.synthetic, from summaries).
DISCREPANCY_LIKELIHOODS = ('gibbs', 'threshold')
LIKELIHOODS = (*DISCREPANCY_LIKELIHOODS, 'synthetic')
# Floor on discrepancies before the log (a perfect match is 0).
_LOG_FLOOR = 1e-12
# Gauss-Hermite nodes (probabilists') for averages over the GP's uncertainty.
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(21)
_GH_LOGW = np.log(_GH_W / _GH_W.sum())


def grid_points(shape) -> np.ndarray:
  """(prod(shape), d) cell centres of a regular grid over ``[-1, 1]^d``, C order."""
  axes = [-1.0 + (2.0 * np.arange(n) + 1.0) / n for n in shape]
  mesh = np.meshgrid(*axes, indexing='ij')
  return np.stack([m.ravel() for m in mesh], axis=1)


def log_l(f, floor, sn, form: str = 'gibbs', sharpness: float = 1.0):
  """log L at latent log discrepancies ``f`` (see module doc); ``sn`` the
  scatter the likelihood is in units of (``_moments`` adds the model error)."""
  if form == 'gibbs':
    return -sharpness * jnp.expm1(f - floor) / sn
  if form == 'threshold':
    return log_ndtr((floor + sharpness * sn - f) / sn)
  raise ValueError(f'likelihood must be one of {DISCREPANCY_LIKELIHOODS}, got {form!r}')


def _moments(mean, var, floor, sn, form, sharpness, model_error=0.0):
  """(log E_f[L], log E_f[L^2]) over f ~ N(mean, var), each (G,): Gauss-
  Hermite, but BOLFI's mean in closed form, Phi((log h - mu) / sqrt(sn^2 + s^2)).
  The simulator's scatter ``sn`` and the model error add in quadrature."""
  sn = jnp.sqrt(sn**2 + model_error**2)
  var = jnp.maximum(var, 0.0)
  f = mean[:, None] + jnp.sqrt(var)[:, None] * _GH_X
  ll = log_l(f, floor, sn, form, sharpness)
  log_m2 = logsumexp(2.0 * ll + _GH_LOGW, axis=1)
  if form == 'threshold':
    log_m1 = log_ndtr((floor + sharpness * sn - mean) / jnp.sqrt(sn**2 + var))
    return log_m1, jnp.maximum(log_m2, 2.0 * log_m1)  # Var >= 0 despite quadrature
  return logsumexp(ll + _GH_LOGW, axis=1), log_m2


class Likelihood(NamedTuple):
  """The approximate likelihood on a set of points (and what it came from).

  Attributes:
    log_lik: (G,) log E_f[L(x)].
    mean: (G,) GP mean of log discrepancy.
    var: (G,) GP variance of the latent log discrepancy.
    noise_sd: () the GP's noise sd (the simulator's scatter, log scale).
    floor: () the lowest GP mean (the best fit's log discrepancy).
  """

  log_lik: jax.Array
  mean: jax.Array
  var: jax.Array
  noise_sd: jax.Array
  floor: jax.Array


def log_likelihood(mean, var, floor, noise_sd, *, form='gibbs', sharpness=1.0,
                   model_error=0.0):  # fmt: skip
  """(G,) log E_f[L] from the GP's mean and latent variance of log
  discrepancy per point (e.g. a saved ``Result``'s), for any likelihood and
  model error; float64 NumPy."""
  with jax.enable_x64(True):
    f64 = lambda a: jnp.asarray(a, jnp.float64)
    log_m1 = _log_m1(f64(mean), f64(var), f64(floor), f64(noise_sd),
                     f64(sharpness), f64(model_error), form)  # fmt: skip
    return np.asarray(log_m1)


@functools.partial(jax.jit, static_argnames=('form',))
def _log_m1(mean, var, floor, sn, sharpness, model_error, form):
  """``_moments``' log E_f[L] as one program (a calibration reads thousands of
  saved GPs; op by op, dispatch cost more than the arithmetic)."""
  return _moments(mean, var, floor, sn, form, sharpness, model_error)[0]


def choose_sharpness(coverage, levels) -> float:
  """The likelihood constant a calibration set supports: the sharpest candidate
  whose every interval holds the truth at least as often as its level says.

  Intervals then err wide, never narrow: an approximate posterior cannot match
  every level and direction with one constant, and an overconfident interval
  misleads where a wide one only says "less is known".

  Args:
    coverage: ``{sharpness: (n_levels, n_params) coverage}`` measured on
      calibration problems (e.g. held-out simulations).
    levels: ``(n_levels,)`` the nominal levels, e.g. ``(0.5, 0.9)``.

  Returns:
    That sharpness, or the least sharp candidate if none qualifies.
  """
  lv = np.asarray(levels, np.float64)[:, None]
  ok = [c for c, cov in coverage.items() if np.all(np.asarray(cov) >= lv)]
  return float(max(ok) if ok else min(coverage))


def likelihood(
  state: gp.GPState, xq, *, form: str = 'gibbs', sharpness: float = 1.0,
  kernel: str = 'matern52', model_error: float = 0.0,
) -> Likelihood:  # fmt: skip
  """The likelihood at points ``xq (G, d)``, averaged over the GP; its floor
  is the lowest GP mean over ``xq`` (dense points, e.g. the grid)."""
  mean, var = gp.posterior(state, xq, kernel=kernel)
  sn = gp.noise_sd(state)
  floor = jnp.min(mean)
  log_lik, _ = _moments(mean, var, floor, sn, form, sharpness, model_error)
  return Likelihood(log_lik, mean, var, sn, floor)


def log_normalise(log_w):
  """Log weights summing to one."""
  return log_w - logsumexp(log_w)


def maxvar_batch(
  state: gp.GPState, xq, log_prior, floor, q: int, *, form: str = 'gibbs',
  sharpness: float = 1.0, kernel: str = 'matern52', model_error: float = 0.0,
) -> jax.Array:  # fmt: skip
  """Indices into ``xq`` of a batch of ``q`` MaxVar picks (see module doc).

  Args:
    state: the fitted GP of log discrepancy.
    xq: (G, d) candidate points (the grid).
    log_prior: (G,) log prior density at them.
    floor: the likelihood's floor (``likelihood(...).floor``).
    q: batch size (static).
    form, sharpness, model_error: the likelihood (as ``likelihood``).
    kernel: kernel name.

  Returns:
    (q,) int indices.
  """
  mean, var = gp.posterior(state, xq, kernel=kernel)
  sn = gp.noise_sd(state)

  def log_acq(s2):
    log_m1, log_m2 = _moments(mean, s2, floor, sn, form, sharpness, model_error)
    # Var = E[L^2] - E[L]^2, in logs: log E[L^2] + log(1 - E[L]^2 / E[L^2]).
    gap = -jnp.expm1(jnp.minimum(2.0 * log_m1 - log_m2, 0.0))
    return 2.0 * log_prior + log_m2 + jnp.log(jnp.maximum(gap, 1e-300))

  def pick(s2, _):
    i = jnp.argmax(log_acq(s2))
    cov = (
      gp.posterior_cov(state, xq, xq[i], kernel=kernel) * state.y_scale**2
    )  # raw units
    s2 = jnp.maximum(s2 - cov**2 / (s2[i] + sn**2), 0.0)
    return s2, i

  _, idx = jax.lax.scan(pick, var, None, length=q)
  return idx


def sample_cells(key, log_p, n: int) -> jax.Array:
  """``n`` cell indices drawn with probabilities ``exp(log_p)`` (normalised
  here), by inverting the cumulative mass: O(G + n log G), where
  ``jax.random.categorical``'s Gumbel trick makes an (n, G) array (75
  million numbers for the default grid and draws). A cell of zero mass is
  never drawn."""
  p = jnp.exp(log_p - jnp.max(log_p))
  cdf = jnp.cumsum(p)
  u = jax.random.uniform(key, (n,), cdf.dtype) * cdf[-1]
  return jnp.minimum(jnp.searchsorted(cdf, u, side='right'), log_p.shape[0] - 1)


def sample_grid(key, points, log_post, shape, n: int) -> jax.Array:
  """``n`` draws from the piecewise-constant grid posterior: a cell by mass
  (``sample_cells``), then uniform within it. (n, d)."""
  k_cell, k_jit = jax.random.split(key)
  idx = sample_cells(k_cell, log_post, n)
  width = 2.0 / jnp.asarray(shape, points.dtype)
  jitter = (jax.random.uniform(k_jit, (n, points.shape[1]), points.dtype) - 0.5) * width
  return jnp.clip(points[idx] + jitter, -1.0, 1.0)


class PosteriorConfig(NamedTuple):
  """Static settings of a posterior search (hashable).

  Attributes:
    d: input dimension.
    grid: cells per dimension of the posterior grid.
    q: candidates per iteration, replicates included.
    replicates: of those, repeats of the highest-posterior cell's centre.
    likelihood: 'gibbs' or 'threshold' (see module doc), or 'synthetic'
      (``bo.synthetic``: the search is told summary residuals, not
      discrepancies).
    sharpness: the likelihood's constant c (see module doc); for
      'synthetic' its tempering exponent (1: the likelihood as it is).
    model_error: the model-discrepancy term (see module doc): scatter of
      log discrepancy that the simulator's own noise does not make, added to
      it in quadrature ('gibbs', 'threshold'); 0: the simulator is the world.
    summaries: values told per evaluation with 'synthetic' (the residual's
      length); 1 otherwise.
    kernel: GP kernel.
    noise_prior: (loc, scale) of the noise variance's LogNormal prior.
    fit_restarts, fit_maxiter: GP hyperparameter fit (warm-started from the
      previous iteration's, so few restarts do).
    samples: posterior draws kept in each result.
  """

  d: int
  grid: tuple[int, ...]
  q: int
  replicates: int = 1
  likelihood: str = 'gibbs'
  sharpness: float = 1.0
  model_error: float = 0.0
  summaries: int = 1
  kernel: str = 'matern52'
  noise_prior: tuple[float, float] = NOISE_PRIOR
  fit_restarts: int = 2
  fit_maxiter: int = 40
  samples: int = 4096


class Step(NamedTuple):
  """One posterior update (device arrays).

  Attributes:
    x: (q, d) the next candidates.
    samples: (S, d) posterior draws given the data so far.
    log_post: (G,) normalised log posterior mass per grid cell.
    log_lik: (G,) log likelihood per cell (for combining recordings).
    params: flat fitted GP hyperparameters (``gp.params_to_array``); (k, P)
      for the k GPs of 'synthetic'.
    noise_sd: () the simulator's scatter of log discrepancy the GP found;
      (k,) of each summary for 'synthetic'.
    floor: () the lowest GP mean of log discrepancy (0 for 'synthetic').
    mean, var: (G,) the GP's mean and latent variance of log discrepancy per
      cell (any likelihood of the module can be formed from them again);
      (G, k) of the summary residuals for 'synthetic'.
  """

  x: jax.Array
  samples: jax.Array
  log_post: jax.Array
  log_lik: jax.Array
  params: jax.Array
  noise_sd: jax.Array
  floor: jax.Array
  mean: jax.Array
  var: jax.Array


def _batch(config: PosteriorConfig, pts, idx, log_post, key) -> jax.Array:
  """The next candidates: the picked cells jittered within them, then
  ``replicates`` repeats of the most probable cell's centre."""
  width = 2.0 / jnp.asarray(config.grid, pts.dtype)
  jitter = jax.random.uniform(key, (len(idx), config.d), pts.dtype) - 0.5
  explore = jnp.clip(pts[idx] + jitter * width, -1.0, 1.0)
  best = jnp.tile(pts[jnp.argmax(log_post)], (config.replicates, 1))
  return jnp.concatenate([explore, best])


@functools.lru_cache(maxsize=16)
def make_step(config: PosteriorConfig):
  """The jitted ``step(x, y, mask, key, log_prior, init_params) -> Step``:
  fit the GP to the log discrepancies ``y (cap,)`` (or, for 'synthetic', the
  GPs to the summary residuals ``y (cap, k)``), form the posterior on the
  grid, draw samples and pick the next batch. ``init_params``: flat warm
  starts, (P,) or (k, P). Buffers have a fixed capacity (padding rows
  masked), so it compiles once per capacity; memoised per (hashable) config,
  so searches with equal settings share the compiles."""
  points = jnp.asarray(grid_points(config.grid))
  if config.likelihood not in LIKELIHOODS:
    raise ValueError(
      f'likelihood must be one of {LIKELIHOODS}, got {config.likelihood!r}'
    )
  n_explore = config.q - config.replicates
  if n_explore < 1:
    raise ValueError(
      f'q={config.q} leaves no room beside {config.replicates} replicates'
    )
  fit_kw = dict(
    kernel=config.kernel, n_restarts=config.fit_restarts,
    maxiter=config.fit_maxiter, noise_prior=config.noise_prior,
  )  # fmt: skip
  if config.likelihood == 'synthetic':
    return jax.jit(
      functools.partial(_synthetic_step, config, points, n_explore, fit_kw)
    )
  lik_kw = dict(
    form=config.likelihood, sharpness=config.sharpness, kernel=config.kernel,
    model_error=config.model_error,
  )  # fmt: skip

  def step(x, log_d, mask, key, log_prior, init_params) -> Step:
    k_fit, k_sample, k_jit = jax.random.split(key, 3)
    pts = points.astype(x.dtype)
    state = gp.fit(
      x, log_d, mask, k_fit, init_params=gp.params_from_array(init_params), **fit_kw
    )
    lik = likelihood(state, pts, **lik_kw)
    log_post = log_normalise(log_prior + lik.log_lik)
    samples = sample_grid(k_sample, pts, log_post, config.grid, config.samples)
    idx = maxvar_batch(state, pts, log_prior, lik.floor, n_explore, **lik_kw)
    return Step(
      _batch(config, pts, idx, log_post, k_jit), samples, log_post, lik.log_lik,
      gp.params_to_array(state.params), lik.noise_sd, lik.floor, lik.mean, lik.var,
    )  # fmt: skip

  return jax.jit(step)


def _synthetic_step(config, points, n_explore, fit_kw, x, r, mask, key, log_prior,
                    init_params) -> Step:  # fmt: skip
  """``make_step``'s step for the 'synthetic' likelihood (``bo.synthetic``)."""
  k_fit, k_sample, k_jit = jax.random.split(key, 3)
  pts = points.astype(x.dtype)
  states = synthetic.fit(x, r, mask, k_fit, init_params, **fit_kw)
  cov = synthetic.noise_cov(states, r, mask, config.kernel)
  mean, var = synthetic.emulate(states, pts, config.kernel)
  log_lik = config.sharpness * synthetic.moments(mean, var, cov)[0]
  log_post = log_normalise(log_prior + log_lik)
  samples = sample_grid(k_sample, pts, log_post, config.grid, config.samples)
  idx = synthetic.maxvar_batch(
    states, pts, log_prior, mean, var, cov, n_explore, kernel=config.kernel
  )
  return Step(
    _batch(config, pts, idx, log_post, k_jit), samples, log_post, log_lik,
    jnp.stack([gp.params_to_array(s.params) for s in states]),
    jnp.sqrt(jnp.diag(cov)), jnp.zeros((), x.dtype), mean, var,
  )  # fmt: skip


@functools.lru_cache(maxsize=16)
def _step_row(config: PosteriorConfig):
  """``make_step(config)`` as a ``bo.batched`` row function (the key as its
  raw data, so that rows stack as plain arrays)."""
  step = make_step(config)

  def row(x, y, mask, key_data, log_prior, init_params) -> Step:
    key = jax.random.wrap_key_data(key_data)
    return step(x, y, mask, key, log_prior, init_params)

  return row


class State(NamedTuple):
  """Where one posterior search stands (host arrays).

  Attributes:
    X: (n, d) evaluated points in ``[-1, 1]^d``.
    Y: (n,) their discrepancies (NaN: failed).
    iteration: iterations finished (0 until the initial design is told).
    history: (k, 3, d) the posterior's 5/50/95% quantiles at each ask (the
      posterior that chose each iteration's candidates).
    params: last fitted GP hyperparameters (flat) or None.
    stopped: the stopping rule ended it.
  """

  X: np.ndarray
  Y: np.ndarray
  iteration: int = 0
  history: np.ndarray | None = None
  params: np.ndarray | None = None
  stopped: bool = False


class Result(NamedTuple):
  """A finished (or current) posterior, unit-cube coordinates.

  Attributes:
    samples: (S, d) posterior draws.
    log_post: (G,) log posterior mass per grid cell (``grid_points(grid)``).
    log_lik: (G,) log likelihood per cell.
    grid: cells per dimension.
    noise_sd: the fitted scatter of log discrepancy; (k,) of each summary
      for 'synthetic'.
    floor: the lowest GP mean of log discrepancy (0 for 'synthetic').
    mean, var: (G,) the GP's mean and latent variance per cell; (G, k) for
      'synthetic'.
    X, Y: every evaluation (Y (n, k) residuals for 'synthetic').
    n_iter: iterations run.
    stopped_early: the stopping rule ended it.
  """

  samples: np.ndarray
  log_post: np.ndarray
  log_lik: np.ndarray
  grid: tuple[int, ...]
  noise_sd: float | np.ndarray
  floor: float
  mean: np.ndarray
  var: np.ndarray
  X: np.ndarray
  Y: np.ndarray
  n_iter: int
  stopped_early: bool


def _quantiles(samples) -> np.ndarray:
  return np.quantile(np.asarray(samples), [0.05, 0.5, 0.95], axis=0)  # (3, d)


class PosteriorSearch:
  """The posterior of ``x`` in ``[-1, 1]^d`` given a noisy discrepancy, as
  ask/tell steps (the interface of ``bo.Minimizer``).

  ``ask`` returns the initial design (``x0`` rows, then scrambled Halton
  points), then each iteration's ``q`` candidates; ``tell`` records their
  discrepancies (non-finite: the simulation failed), or with the
  'synthetic' likelihood their summary residuals ``(q, k)``, and saves the
  state.
  The search ends after ``n_iter`` iterations, or once the posterior's 5, 50
  and 95% quantiles have moved less than ``stop_tol`` (in unit-cube units) in
  every dimension for ``stop_window`` iterations, but not before
  ``min_iter``. ``log_prior (G,)`` is the prior density on the grid (uniform:
  zeros); ``device`` places the GP work (float64 under ``jax.enable_x64``).
  """

  def __init__(
    self,
    config: PosteriorConfig,
    *,
    n_init: int,
    n_iter: int,
    log_prior=None,
    x0=None,
    seed: int = 0,
    stop_tol: float | None = None,
    stop_window: int = 2,
    min_iter: int = 0,
    state_path: str | None = None,
    device=None,
  ):
    if n_init < 1 or n_iter < 0:
      raise ValueError(f'need n_init >= 1 and n_iter >= 0, got {n_init}, {n_iter}')
    if len(config.grid) != config.d:
      raise ValueError(f'grid {config.grid} is not {config.d}-dimensional')
    if config.summaries < 1:
      raise ValueError(f'need summaries >= 1, got {config.summaries}')
    self.config = config
    self.d = config.d
    self.n_init, self.n_iter = n_init, n_iter
    self.seed = seed
    self.stop_tol, self.stop_window, self.min_iter = stop_tol, stop_window, min_iter
    self.state_path = state_path
    self.device = device
    g = int(np.prod(config.grid))
    self.log_prior = np.zeros(g) if log_prior is None else np.asarray(log_prior, float)
    if self.log_prior.shape != (g,) or not np.isfinite(self.log_prior).any():
      raise ValueError(f'log_prior must be ({g},) with some finite entries')
    self.x0 = None if x0 is None else np.atleast_2d(np.asarray(x0, np.float64))
    # One buffer size for the whole budget: one compile per search setting.
    self.capacity = _capacity(n_init + config.q * n_iter)
    self._key = jax.random.key(seed)
    make_step(config)  # validates the config
    prior_sha = hashlib.sha1(np.ascontiguousarray(self.log_prior).tobytes()).hexdigest()
    self.signature = json.dumps(
      dict(config._asdict(), n_init=n_init, seed=seed, prior_sha1=prior_sha)
    )

  # ---------------------------------------------------------------- state

  def start(self) -> State:
    """A fresh state, or the one saved at ``state_path`` (resume)."""
    empty = State(
      np.zeros((0, self.d)), np.zeros((0, *self._y_shape)), 0, np.zeros((0, 3, self.d))
    )
    if self.state_path is None or not os.path.exists(self.state_path):
      return empty
    s = _load(self.state_path)
    if str(s['signature']) != self.signature:
      raise ValueError(f'{self.state_path} was written by a run with other settings.')
    state = State(
      s['X'], s['Y'].reshape(-1, *self._y_shape), int(s['iteration']),
      s['history'].reshape(-1, 3, self.d),
      s['params'] if s['params'].size else None,
    )  # fmt: skip
    return state._replace(stopped=self._rule(state))

  def done(self, state: State) -> bool:
    return state.X.shape[0] > 0 and (state.stopped or state.iteration >= self.n_iter)

  @property
  def _synthetic(self) -> bool:
    return self.config.likelihood == 'synthetic'

  @property
  def _y_shape(self) -> tuple[int, ...]:
    """The shape of one evaluation's value: () a discrepancy, (k,) residuals."""
    return (self.config.summaries,) if self._synthetic else ()

  def _ok(self, y) -> np.ndarray:
    """(n,) rows of told values that count (a failed simulation's do not)."""
    y = np.asarray(y)
    return np.isfinite(y).all(axis=1) if self._synthetic else np.isfinite(y)

  def _step_call(self, state: State, finish) -> batched.Call:
    """The GP step on the data so far as a ``bo.batched`` row: buffers of the
    search's capacity (padding masked), its own key for this iteration."""
    n = state.X.shape[0]
    cap = max(self.capacity, _capacity(n))
    mask = np.zeros(cap, bool)
    mask[:n] = self._ok(state.Y)
    x = np.zeros((cap, self.d))
    x[:n] = state.X
    y = np.zeros((cap, *self._y_shape))
    if self._synthetic:
      y[:n] = np.where(mask[:n, None], state.Y, 0.0)
    else:
      y[:n] = np.log(np.maximum(np.where(mask[:n], state.Y, 1.0), _LOG_FLOOR))
    with jax.enable_x64(True):
      init = state.params
      if init is None:  # the GP prior's medians
        p = gp.default_params(self.d, jnp.float64, self.config.noise_prior)
        init = np.tile(gp.params_to_array(p), (*self._y_shape, 1)).reshape(
          *self._y_shape, -1
        )
      key = np.asarray(
        jax.random.key_data(jax.random.fold_in(self._key, state.iteration))
      )
    args = (x, y, mask, key, self.log_prior, np.asarray(init, np.float64))
    return batched.Call(_step_row(self.config), args, finish)

  def ask(self, state: State) -> tuple[np.ndarray, State]:
    """The next candidates and the state (with the refitted GP): the batch
    of one of ``bo.batched.ask_many``, which asks many searches at once."""
    return batched.ask_many([self], [state])[0]

  def ask_plan(self, state: State) -> batched.Ready | batched.Call:
    """``ask`` as a ``bo.batched`` step: the answer, or the GP row to run."""
    if self.done(state):
      raise ValueError('ask() after the search has finished.')
    n = state.X.shape[0]
    if n == 0:
      starts = np.zeros((0, self.d)) if self.x0 is None else self.x0[: self.n_init]
      rest = 2.0 * qmc.halton(self.n_init - len(starts), self.d, seed=self.seed) - 1.0
      return batched.Ready((np.concatenate([starts, rest]), state))
    if not self._ok(state.Y).any():  # every simulation failed: explore
      u = 2.0 * qmc.halton(self.config.q, self.d, seed=self.seed, skip=n) - 1.0
      return batched.Ready((u, state))

    def finish(out):
      params = np.asarray(out.params)
      history = np.concatenate([state.history, _quantiles(out.samples)[None]])
      return np.asarray(out.x, np.float64), state._replace(
        params=params, history=history
      )

    return self._step_call(state, finish)

  def tell(self, state: State, x, y) -> State:
    """Records discrepancies ``y (q,)`` (residuals ``(q, k)`` for
    'synthetic') of the asked ``x``; saves; applies the rule."""
    x = np.asarray(x, np.float64).reshape(-1, self.d)
    y = np.asarray(y, np.float64).reshape(-1, *self._y_shape)
    if y.shape[0] != x.shape[0]:
      raise ValueError(f'{y.shape[0]} values for {x.shape[0]} points.')
    if self._synthetic:  # a failed simulation's whole row
      y = np.where(self._ok(y)[:, None], y, np.nan)
    else:
      y = np.where(np.isfinite(y) & (y >= 0), y, np.nan)
    first = state.X.shape[0] == 0
    state = state._replace(
      X=np.concatenate([state.X, x]), Y=np.concatenate([state.Y, y])
    )
    if not first:
      state = state._replace(iteration=state.iteration + 1)
    self._save(state)
    return state._replace(stopped=state.stopped or (not first and self._rule(state)))

  def stop(self, state: State) -> State:
    return state._replace(stopped=True)

  def result(self, state: State) -> Result:
    """The posterior given every evaluation so far (one more GP fit; many
    searches' at once: ``bo.batched.result_many``)."""
    return batched.result_many([self], [state])[0]

  def result_plan(self, state: State) -> batched.Call:
    """``result`` as a ``bo.batched`` step."""
    if not self._ok(state.Y).any():
      raise ValueError('no finite discrepancy: every simulation failed')

    def finish(out):
      return Result(
        np.asarray(out.samples), np.asarray(out.log_post), np.asarray(out.log_lik),
        tuple(self.config.grid),
        np.asarray(out.noise_sd) if self._synthetic else float(out.noise_sd),
        float(out.floor),
        np.asarray(out.mean), np.asarray(out.var),
        state.X, state.Y, state.iteration, state.stopped,
      )  # fmt: skip

    return self._step_call(state, finish)

  def _rule(self, state: State) -> bool:
    h = state.history
    if self.stop_tol is None or state.iteration < self.min_iter or h is None:
      return False
    if len(h) <= self.stop_window:
      return False
    moved = np.abs(h[-self.stop_window :] - h[-self.stop_window - 1 : -1])
    return bool(np.all(moved < self.stop_tol))

  def _save(self, state: State) -> None:
    if self.state_path is None:
      return
    _save(
      self.state_path,
      dict(
        X=state.X, Y=state.Y, iteration=np.int64(state.iteration),
        signature=np.array(self.signature),
        history=np.asarray(state.history).reshape(-1, 3, self.d),
        params=np.zeros(0) if state.params is None else np.asarray(state.params),
      ),
    )  # fmt: skip
