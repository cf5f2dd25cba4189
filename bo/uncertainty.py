"""How sure is the optimiser? The GP posterior distribution of the minimiser.

After an estimate, the best evaluated point is one sample of a noisy landscape.
We fit the GP to every evaluation and draw joint posterior sample paths on a
dense candidate set (quasi-random points, the evaluated points, and a cloud
around the incumbent); each path's argmin is one draw of where the minimum is
(the distribution Thompson sampling acts on). Its spread per dimension is the
uncertainty we report: wide where the landscape is flat (a parameter the data
cannot pin down), narrow where it is sharp.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from bo import gp, kernels, qmc


class MinimizerSamples(NamedTuple):
  """Posterior draws of the minimiser's location, original units.

  Attributes:
    samples: (S, d) argmin of each posterior sample path.
    mean: (d,) their mean.
    std: (d,) their standard deviation.
    quantiles: (3, d) their 5%, 50% and 95% quantiles.
  """

  samples: np.ndarray
  mean: np.ndarray
  std: np.ndarray
  quantiles: np.ndarray


def _capacity(n: int) -> int:
  return max(16, 1 << int(np.ceil(np.log2(max(n, 1)))))


def minimizer_samples(
  X,
  Y,
  bounds,
  key: jax.Array,
  *,
  n_samples: int = 512,
  n_candidates: int = 1024,
  local_fraction: float = 0.5,
  kernel: str = 'matern52',
) -> MinimizerSamples:
  """Draws the GP posterior distribution of ``argmin f``.

  Args:
    X: (n, d) evaluated points, original units.
    Y: (n,) values; NaN marks failures (left out).
    bounds: (d, 2) lower and upper bounds.
    key: PRNG key.
    n_samples: posterior sample paths S.
    n_candidates: points each path is evaluated on.
    local_fraction: share of candidates drawn around the incumbent (Gaussian,
      a tenth of the range), where the argmin mostly falls.
    kernel: GP kernel, as in ``bo.minimize``.

  Returns:
    ``MinimizerSamples``.

  Raises:
    ValueError: shapes disagree or fewer than two evaluations succeeded.
  """
  X = np.asarray(X, np.float64)
  Y = np.asarray(Y, np.float64)
  bounds = np.asarray(bounds, np.float64)
  if X.ndim != 2 or Y.shape != (X.shape[0],) or bounds.shape != (X.shape[1], 2):
    raise ValueError(
      f'need X (n, d), Y (n,), bounds (d, 2); got {X.shape}, {Y.shape}, {bounds.shape}'
    )
  ok = np.isfinite(Y)
  if ok.sum() < 2:
    raise ValueError(f'need at least 2 successful evaluations, got {int(ok.sum())}')
  lo, hi = bounds[:, 0], bounds[:, 1]
  to_unit = lambda x: 2.0 * (x - lo) / (hi - lo) - 1.0
  d = X.shape[1]
  seed = int(np.asarray(jax.random.randint(key, (), 0, 2**31 - 1)))
  n, cap = X.shape[0], _capacity(X.shape[0])
  xb = np.zeros((cap, d))
  xb[:n] = to_unit(X)
  yb = np.zeros(cap)
  yb[:n] = np.where(ok, Y, 0.0)
  mask = np.zeros(cap, bool)
  mask[:n] = ok

  n_local = int(local_fraction * n_candidates)
  best = xb[np.argmin(np.where(ok, Y, np.inf))]
  local = best + 0.2 * np.random.default_rng(seed).standard_normal((n_local, d))
  cand = np.concatenate(
    [
      2.0 * qmc.halton(n_candidates - n_local, d, seed=seed) - 1.0,
      np.clip(local, -1.0, 1.0),
      xb,  # evaluated points; padding rows add the centre, harmlessly
    ]
  )
  with jax.enable_x64(True):
    arg = _argmin_draws(
      jnp.asarray(xb), jnp.asarray(yb), jnp.asarray(mask), jnp.asarray(cand),
      jnp.asarray(jax.random.key_data(key)), kernel=kernel, n_samples=n_samples,
    )  # fmt: skip
  arg = np.asarray(arg)
  u = cand[arg]
  samples = lo + (u + 1.0) * 0.5 * (hi - lo)
  return MinimizerSamples(
    samples=samples,
    mean=samples.mean(0),
    std=samples.std(0),
    quantiles=np.quantile(samples, [0.05, 0.5, 0.95], axis=0),
  )


@functools.partial(jax.jit, static_argnames=('kernel', 'n_samples'))
def _argmin_draws(xb, yb, mask, cand, key_data, *, kernel, n_samples):
  """(S,) index into ``cand`` (m, d) of each posterior sample path's minimum."""
  k_fit, k_draw = jax.random.split(jax.random.wrap_key_data(key_data))
  state = gp.fit(xb, yb, mask, k_fit, kernel=kernel)
  p = state.params
  ls = jnp.exp(p.log_lengthscales)
  scale = jnp.exp(p.log_outputscale)
  kqq = scale * kernels.get(kernel)(cand, cand, ls)
  kqx = jnp.where(mask[None, :], scale * kernels.get(kernel)(cand, state.x, ls), 0.0)
  v = jax.scipy.linalg.solve_triangular(state.chol, kqx.T, lower=True)
  mean = kqx @ state.alpha
  cov = kqq - v.T @ v
  # Jitter relative to the signal variance keeps the factorisation stable.
  chol = jnp.linalg.cholesky(cov + 1e-8 * scale * jnp.eye(cand.shape[0]))
  z = jax.random.normal(k_draw, (cand.shape[0], n_samples), cand.dtype)
  return jnp.argmin(mean[:, None] + chol @ z, axis=0)
