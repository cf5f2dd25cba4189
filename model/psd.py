"""Physics similarity distances between two videos embedded as 2-D point sets.

Each frame of a video maps to one point of the similarity map, so a video is a
point set ``(n, d)``. A real recording and a simulation are not aligned in
time (different start, phase and even frame rate), so the distance used for
optimisation should depend on the two point *sets* only:

- ``energy_distance`` (default): ``2 E|X-Y| - E|X-X'| - E|Y-Y'|`` with
  Euclidean norms and V-statistics (all pairs, self pairs included). It is
  zero iff the two empirical distributions are equal, symmetric, invariant to
  frame order, and >= 0 (it is the squared MMD of the distance kernel).
- ``centroid_distance``: squared distance between the two means; order
  invariant but blind to spread and shape.
- ``paired_distance``: the original code's objective, the sum over frames of
  squared distances with frames paired at random; it depends on the pairing
  (and so on frame order) and is kept for comparison.

All functions are pure and take one pair of sets; to score a batch of candidate
videos against one recording, use
``jax.vmap(energy_distance, in_axes=(0, None))(candidates, recording)``.
"""

import jax
import jax.numpy as jnp

KINDS = ('energy', 'centroid', 'paired')


def _pairwise_norms(x: jax.Array, y: jax.Array) -> jax.Array:
  """Euclidean distances ``(n, m)`` with a zero (not NaN) gradient at zero."""
  d2 = jnp.sum((x[:, None, :] - y[None, :, :]) ** 2, axis=-1)
  positive = d2 > 0
  return jnp.where(positive, jnp.sqrt(jnp.where(positive, d2, 1.0)), 0.0)


def energy_distance(x: jax.Array, y: jax.Array) -> jax.Array:
  """Energy distance between two point sets.

  Args:
    x: ``(n, d)`` points (e.g. frame embeddings of a simulation).
    y: ``(m, d)`` points (e.g. of the recording).

  Returns:
    ``()`` the V-statistic ``2 mean|x_i - y_j| - mean|x_i - x_k| - mean|y_j - y_l|``.
  """
  return (
    2.0 * jnp.mean(_pairwise_norms(x, y))
    - jnp.mean(_pairwise_norms(x, x))
    - jnp.mean(_pairwise_norms(y, y))
  )


def centroid_distance(x: jax.Array, y: jax.Array) -> jax.Array:
  """Squared Euclidean distance between the means of ``(n, d)`` and ``(m, d)``; ``()``."""
  return jnp.sum((jnp.mean(x, axis=0) - jnp.mean(y, axis=0)) ** 2)


def paired_distance(key: jax.Array, x: jax.Array, y: jax.Array) -> jax.Array:
  """The original objective: sum of squared distances under a random frame pairing.

  Args:
    key: PRNG key choosing the pairing (a permutation of ``y``'s frames).
    x: ``(n, d)``.
    y: ``(n, d)``, the same number of frames.

  Returns:
    ``()`` ``sum_i |x_i - y_{pi(i)}|^2``.
  """
  if x.shape != y.shape:
    raise ValueError(
      f'paired_distance needs equal shapes, got {x.shape} and {y.shape}.'
    )
  perm = jax.random.permutation(key, y.shape[0])
  return jnp.sum((x - y[perm]) ** 2)


def geometric_mean(d: jax.Array, floor: float = 1e-12) -> jax.Array:
  """Geometric mean of ``(K,)`` distances of one pair of videos under K
  embeddings (an ensemble): each member's relative change counts alike
  whatever its scale, and the log of the result (what a GP of the discrepancy
  models) is the mean of the members' logs. Distances below ``floor`` count as
  ``floor``; a NaN gives NaN. Returns ``()``."""
  return jnp.exp(jnp.mean(jnp.log(jnp.maximum(d, floor))))


def psd(
  x: jax.Array, y: jax.Array, kind: str = 'energy', key: jax.Array | None = None
) -> jax.Array:
  """Dispatches to one of the distances by name.

  Args:
    x: ``(n, d)``.
    y: ``(m, d)``.
    kind: 'energy', 'centroid' or 'paired' (the last needs ``key`` and n == m).
    key: PRNG key for 'paired'.

  Returns:
    ``()`` the distance.
  """
  if kind == 'energy':
    return energy_distance(x, y)
  if kind == 'centroid':
    return centroid_distance(x, y)
  if kind == 'paired':
    if key is None:
      raise ValueError("psd kind='paired' needs a key.")
    return paired_distance(key, x, y)
  raise ValueError(f'psd kind must be one of {KINDS}, got {kind!r}.')
