"""A posterior on a grid of cell centres of ``[-1, 1]^d`` (per-dimension
resolution): the cells, their log weights normalised, and draws, uniform
within cells picked by mass."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import logsumexp


def grid_points(shape) -> np.ndarray:
  """(prod(shape), d) cell centres of a regular grid over ``[-1, 1]^d``, C order."""
  axes = [-1.0 + (2.0 * np.arange(n) + 1.0) / n for n in shape]
  mesh = np.meshgrid(*axes, indexing='ij')
  return np.stack([m.ravel() for m in mesh], axis=1)


def log_normalise(log_w):
  """Log weights summing to one."""
  return log_w - logsumexp(log_w)


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
