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

from bo import batched, gp, qmc, synthetic
from bo.likelihood import (
  DISCREPANCY_LIKELIHOODS,
  LIKELIHOODS,
  Likelihood,
  choose_sharpness,
  likelihood,
  log_l,
  log_likelihood,
  maxvar_batch,
)
from bo.loop import _capacity, _load, _save
from bo.posterior_grid import grid_points, log_normalise, sample_cells, sample_grid

# The likelihood's and the grid's names, importable from here as before.
__all__ = [
  'DISCREPANCY_LIKELIHOODS', 'LIKELIHOODS', 'NOISE_PRIOR', 'Likelihood',
  'PosteriorConfig', 'PosteriorSearch', 'Result', 'State', 'Step',
  'choose_sharpness', 'grid_points', 'likelihood', 'log_l', 'log_likelihood',
  'log_normalise', 'make_step', 'maxvar_batch', 'sample_cells', 'sample_grid',
]  # fmt: skip

# LogNormal prior on the noise variance of the standardised log discrepancy:
# median 0.05 (a noise sd of ~22% of the log discrepancy's spread over the
# box), wide. Replicates in every batch pin it down.
NOISE_PRIOR = (math.log(0.05), 1.5)
# Floor on discrepancies before the log (a perfect match is 0).
_LOG_FLOOR = 1e-12


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
