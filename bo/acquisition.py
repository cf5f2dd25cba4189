"""Acquisition functions (log-EI, UCB) and their multi-start maximisation.

All acquisition values are "larger is better" for a *minimisation* problem.
"""

import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import jaxopt
from jax.scipy.special import erfcx, ndtr

_C1 = 0.5 * math.log(2.0 * math.pi)
_C2 = 0.5 * math.log(math.pi / 2.0)
_SQRT2 = 2.0**0.5


def _log1mexp(x):
  """``log(1 - exp(x))`` for ``x < 0``, accurate on both sides of ``-log 2``."""
  x = jnp.minimum(x, -1e-300)
  small = x > -0.6931471805599453
  x_small = jnp.where(small, x, -1.0)
  x_large = jnp.where(small, -1.0, x)
  return jnp.where(small, jnp.log(-jnp.expm1(x_small)), jnp.log1p(-jnp.exp(x_large)))


def log_h(z: jnp.ndarray) -> jnp.ndarray:
  """Numerically stable ``log(phi(z) + z Phi(z))`` (Ament et al., 2023, eq. 9).

  Three branches: the direct formula for ``z > -1``, an ``erfcx`` form for
  moderately negative ``z`` and the asymptote ``-z^2/2 - c1 - 2 log|z|`` below
  ``-1/sqrt(eps)``. Each branch sees only safe inputs (the double-``where``
  trick) so gradients never pick up NaNs from the branches not taken.

  Args:
    z: standardised improvement, any shape.

  Returns:
    ``log h(z)``, same shape as ``z``.
  """
  eps = jnp.finfo(z.dtype).eps
  upper = z > -1.0
  tail = z <= -1.0 / jnp.sqrt(eps)
  z_up = jnp.where(upper, z, 0.0)
  z_mid = jnp.where(upper | tail, -2.0, z)
  z_tail = jnp.where(tail, z, -2.0)
  phi = jnp.exp(-0.5 * z_up * z_up - _C1)
  v_up = jnp.log(phi + z_up * ndtr(z_up))
  v_mid = (
    -0.5 * z_mid * z_mid
    - _C1
    + _log1mexp(jnp.log(erfcx(-z_mid / _SQRT2) * jnp.abs(z_mid)) + _C2)
  )
  v_tail = -0.5 * z_tail * z_tail - _C1 - 2.0 * jnp.log(jnp.abs(z_tail))
  return jnp.where(upper, v_up, jnp.where(tail, v_tail, v_mid))


def ei(mean: jnp.ndarray, var: jnp.ndarray, best_f) -> jnp.ndarray:
  """Closed-form expected improvement below ``best_f`` (minimisation).

  Args:
    mean: posterior mean.
    var: posterior variance.
    best_f: incumbent value.

  Returns:
    ``E[max(best_f - f, 0)]``, same shape as ``mean``.
  """
  sigma = jnp.sqrt(var)
  z = (best_f - mean) / sigma
  phi = jnp.exp(-0.5 * z * z - _C1)
  return sigma * (phi + z * ndtr(z))


def log_ei(mean: jnp.ndarray, var: jnp.ndarray, best_f) -> jnp.ndarray:
  """Log expected improvement below ``best_f`` (minimisation), stable everywhere.

  Args:
    mean: posterior mean.
    var: posterior variance (positive).
    best_f: incumbent value.

  Returns:
    ``log E[max(best_f - f, 0)]``, same shape as ``mean``.
  """
  sigma = jnp.sqrt(var)
  return log_h((best_f - mean) / sigma) + jnp.log(sigma)


def ucb(mean: jnp.ndarray, var: jnp.ndarray, beta) -> jnp.ndarray:
  """Upper confidence bound for minimisation, ``-mean + sqrt(beta var)``.

  This is BoTorch's ``UpperConfidenceBound(maximize=False)`` convention; the
  paper used ``beta = 0.1``.

  Args:
    mean: posterior mean.
    var: posterior variance.
    beta: exploration weight.

  Returns:
    Acquisition values, same shape as ``mean``.
  """
  return -mean + jnp.sqrt(beta * var)


def optimize(
  acq: Callable[[jnp.ndarray], jnp.ndarray],
  key: jax.Array,
  raw_base: jnp.ndarray,
  x_best: jnp.ndarray,
  *,
  n_restarts: int = 10,
  maxiter: int = 100,
  sigmas: tuple[float, ...] = (0.01, 0.1),
  n_around: int = 64,
):
  """Maximises ``acq`` over ``[-1, 1]^d`` by vmapped multi-start L-BFGS-B.

  Raw candidates are ``raw_base`` after a random shift modulo one (a
  Cranley-Patterson rotation, so every call sees a fresh quasi-random set of
  the same size), ``x_best`` itself, and Gaussian perturbations of
  ``x_best`` at each scale in ``sigmas``. The ``n_restarts`` raw candidates
  with the largest acquisition start L-BFGS-B (through ``lax.map``; see
  ``gp.fit`` for why not ``vmap``).

  Args:
    acq: batched acquisition, ``(m, d) -> (m,)``, larger is better.
    key: PRNG key.
    raw_base: quasi-random points in ``[0, 1)^d``, ``(r, d)``.
    x_best: incumbent points in ``[-1, 1]^d``, ``(k, d)``.
    n_restarts: number of L-BFGS-B starts.
    maxiter: L-BFGS-B iterations per start.
    sigmas: perturbation scales around ``x_best``.
    n_around: perturbed points per scale.

  Returns:
    ``(x, value)``: the maximiser ``(d,)`` and its acquisition value.
  """
  k_shift, k_near, k_pick = jax.random.split(key, 3)
  d = raw_base.shape[1]
  dtype = raw_base.dtype
  shift = jax.random.uniform(k_shift, (d,), dtype)
  raw = 2.0 * jnp.mod(raw_base + shift, 1.0) - 1.0
  near_keys = jax.random.split(k_near, len(sigmas))
  near = [
    x_best[jax.random.randint(kk, (n_around,), 0, x_best.shape[0])]
    + s * jax.random.normal(jax.random.fold_in(kk, 1), (n_around, d), dtype)
    for kk, s in zip(near_keys, sigmas, strict=True)
  ]
  cand = jnp.clip(jnp.concatenate([raw, x_best, *near]), -1.0, 1.0)
  vals = acq(cand)
  vals = jnp.where(jnp.isfinite(vals), vals, -jnp.inf)
  # Tiny random tie-break so flat regions do not all start at the same point.
  noise = 1e-9 * jax.random.uniform(k_pick, vals.shape, dtype)
  _, idx = jax.lax.top_k(vals + noise, n_restarts)
  starts = cand[idx]

  def neg(x):
    v = acq(x[None])[0]
    return -jnp.where(jnp.isfinite(v), v, -1e30)

  lo = -jnp.ones((d,), dtype)
  hi = jnp.ones((d,), dtype)
  solver = jaxopt.LBFGSB(fun=neg, maxiter=maxiter, tol=1e-6)
  res = jax.lax.map(lambda x: solver.run(x, bounds=(lo, hi)), starts)
  xs = jnp.clip(res.params, -1.0, 1.0)
  fin = acq(xs)
  fin = jnp.where(jnp.isfinite(fin), fin, -jnp.inf)
  # Never return something worse than the best raw candidate.
  i = jnp.argmax(fin)
  better = fin[i] >= vals[idx[0]]
  return jnp.where(better, xs[i], starts[0]), jnp.where(better, fin[i], vals[idx[0]])
