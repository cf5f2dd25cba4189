"""The approximate likelihood of a GP of a noisy log discrepancy (after
BOLFI; ``bo.posterior``'s module doc has the derivation): ``'gibbs'`` and
``'threshold'`` likelihoods averaged over the GP's uncertainty by
Gauss-Hermite quadrature, a model-error term added in quadrature, the
calibration of its one constant, and the MaxVar acquisition built on its
moments."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import log_ndtr, logsumexp

from bo import gp

# Likelihoods of one discrepancy (formed again from a saved GP: log_likelihood),
# and all a search can use ('synthetic': bo.synthetic, from summaries).
DISCREPANCY_LIKELIHOODS = ('gibbs', 'threshold')
LIKELIHOODS = (*DISCREPANCY_LIKELIHOODS, 'synthetic')
# Gauss-Hermite nodes (probabilists') for averages over the GP's uncertainty.
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(21)
_GH_LOGW = np.log(_GH_W / _GH_W.sum())


def log_l(f, floor, sn, form: str = 'gibbs', sharpness: float = 1.0):
  """log L at latent log discrepancies ``f`` (see module doc); ``sn`` the
  scatter the likelihood is in units of (``moments`` adds the model error)."""
  if form == 'gibbs':
    return -sharpness * jnp.expm1(f - floor) / sn
  if form == 'threshold':
    return log_ndtr((floor + sharpness * sn - f) / sn)
  raise ValueError(f'likelihood must be one of {DISCREPANCY_LIKELIHOODS}, got {form!r}')


def moments(mean, var, floor, sn, form, sharpness, model_error=0.0):
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
  """``moments``' log E_f[L] as one program (a calibration reads thousands of
  saved GPs; op by op, dispatch cost more than the arithmetic)."""
  return moments(mean, var, floor, sn, form, sharpness, model_error)[0]


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
  log_lik, _ = moments(mean, var, floor, sn, form, sharpness, model_error)
  return Likelihood(log_lik, mean, var, sn, floor)


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
    log_m1, log_m2 = moments(mean, s2, floor, sn, form, sharpness, model_error)
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
