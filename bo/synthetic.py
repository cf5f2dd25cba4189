"""Synthetic likelihoods from GP emulators of a simulator's summaries.

``bo.posterior`` models one discrepancy per simulation (BOLFI). Where that
discrepancy is a distance between a few summary statistics ``s`` (the sheet's
mean shape, ``physsim.shape``), the summaries themselves can be modelled
instead: one GP per component of the residual ``r(x) = s_sim(x) - s_obs``,
whose noise term is the simulator's scatter of ``s`` (gusts, sensor noise),
fitted with the rest. The residual is smooth and nearly linear where the
discrepancy has a noisy minimum, so the GPs learn it from few simulations; and
the likelihood is the one the summaries imply (a synthetic likelihood, Wood
2010, Nature 466; GP emulators of each summary as in Meeds & Welling 2014,
GPS-ABC) rather than a shape with a tuned constant:

  L(x) = E_g[N(0; g(x), S)] = N(0; m(x), S + V(x)),

``g`` the GPs' latent residual (mean ``m``, variance ``V``, independent per
component), ``S`` the noise covariance: each GP's noise variance on the
diagonal and, off it, the correlation of the components' residuals about the
GP means (the sheet's centroid swings along one arc, so its two coordinates
scatter together; treated as independent they would count one piece of
information twice). ``sharpness`` tempers it (``L^c``; 1: as it is).

Acquisition is MaxVar on this likelihood, as in ``bo.posterior``, with its
moments over the GPs in closed form:

  E[L^2] = (4 pi)^(-k/2) |S|^(-1/2) N(0; m, S / 2 + V).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from bo import gp

# Largest |correlation| of the noise components (keeps S positive definite).
_MAX_CORR = 0.99


def _log_normal0(mean, cov):
  """log N(0; mean, cov) per row: mean (G, k), cov (G, k, k) or (k, k)."""
  k = mean.shape[-1]
  cov = jnp.broadcast_to(cov, mean.shape[:-1] + (k, k))
  _, logdet = jnp.linalg.slogdet(cov)
  quad = jnp.einsum('gi,gi->g', mean, jnp.linalg.solve(cov, mean[..., None])[..., 0])
  return -0.5 * (quad + logdet + k * math.log(2.0 * math.pi))


def moments(mean, var, cov):
  """(log E_g[L], log E_g[L^2]), each (G,), of ``L = N(0; g, cov)`` over
  independent ``g_j ~ N(mean_j, var_j)``: mean, var (G, k); cov (k, k)."""
  k = mean.shape[-1]
  v = jax.vmap(jnp.diag)(jnp.maximum(var, 0.0))  # (G, k, k)
  log_m1 = _log_normal0(mean, cov + v)
  _, logdet = jnp.linalg.slogdet(cov)
  log_m2 = (
    -0.5 * k * math.log(4.0 * math.pi)
    - 0.5 * logdet
    + _log_normal0(mean, 0.5 * cov + v)
  )
  return log_m1, jnp.maximum(log_m2, 2.0 * log_m1)  # Var >= 0 despite rounding


def fit(x, r, mask, key, init, *, kernel, n_restarts, maxiter, noise_prior):
  """One GP per residual component: ``r (cap, k)``; ``init (k, P)`` flat
  warm-start hyperparameters. Returns a list of k ``gp.GPState``."""
  keys = jax.random.split(key, r.shape[1])
  return [
    gp.fit(
      x,
      r[:, j],
      mask,
      keys[j],
      kernel=kernel,
      n_restarts=n_restarts,
      maxiter=maxiter,
      init_params=gp.params_from_array(init[j]),
      noise_prior=noise_prior,
    )  # fmt: skip
    for j in range(r.shape[1])
  ]


def noise_cov(states, r, mask, kernel: str):
  """(k, k) covariance of the simulator's scatter of the summaries: the GPs'
  noise variances, correlated as their residuals about the GP means are."""
  sd = jnp.stack([gp.noise_sd(s) for s in states])
  e = jnp.stack([
    jnp.where(mask, r[:, j] - gp.posterior(s, s.x, kernel=kernel)[0], 0.0)
    for j, s in enumerate(states)
  ])  # fmt: skip  # (k, cap)
  n = jnp.maximum(mask.sum(), 2)
  e = e - e.sum(axis=1, keepdims=True) / n * mask
  c = (e @ e.T) / (n - 1)
  s = jnp.sqrt(jnp.maximum(jnp.diag(c), 1e-300))
  corr = jnp.clip(c / (s[:, None] * s[None, :]), -_MAX_CORR, _MAX_CORR)
  corr = jnp.where(jnp.eye(len(states), dtype=bool), 1.0, corr)
  return corr * sd[:, None] * sd[None, :]


def emulate(states, xq, kernel: str):
  """GP means and latent variances of every component at ``xq (G, d)``:
  each (G, k)."""
  mv = [gp.posterior(s, xq, kernel=kernel) for s in states]
  return jnp.stack([m for m, _ in mv], -1), jnp.stack([v for _, v in mv], -1)


def maxvar_batch(states, xq, log_prior, mean, var, cov, q: int, *, kernel: str):
  """Indices into ``xq`` of ``q`` greedy MaxVar picks of the synthetic
  likelihood: the point of largest ``prior^2 Var_g[L]``, each pick lowering
  every component's GP variance around it as if it had been observed."""
  sn2 = jnp.stack([gp.noise_sd(s) ** 2 for s in states])  # (k,)

  def pick(v, _):
    log_m1, log_m2 = moments(mean, v, cov)
    gap = -jnp.expm1(jnp.minimum(2.0 * log_m1 - log_m2, 0.0))
    i = jnp.argmax(2.0 * log_prior + log_m2 + jnp.log(jnp.maximum(gap, 1e-300)))
    cols = []
    for j, s in enumerate(states):
      c = gp.posterior_cov(s, xq, xq[i], kernel=kernel) * s.y_scale**2
      cols.append(jnp.maximum(v[:, j] - c**2 / (v[i, j] + sn2[j]), 0.0))
    return jnp.stack(cols, -1), i

  _, idx = jax.lax.scan(pick, var, None, length=q)
  return idx
