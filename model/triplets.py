"""Triplet sampling (random, the paper's; batch-hard, optional) and the triplet loss.

A label is one simulation's parameter set (all its cameras and frames). A
triplet is (anchor, positive from the anchor's label, negative from any other
label). Samplers are pure functions of a key and integer index arrays, so they
jit; they return indices into the dataset, and the caller gathers images.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class Triplets(NamedTuple):
  """Dataset indices of a batch of triplets, each ``(B,)`` int32."""

  anchor: jax.Array
  positive: jax.Array
  negative: jax.Array


def check_labels(labels, name: str = 'labels') -> np.ndarray:
  """Validates labels on the host.

  Args:
    labels: ``(N,)`` integer labels.
    name: field name used in the error message.

  Returns:
    The labels as an ``(N,)`` int32 NumPy array.

  Raises:
    ValueError: if not 1-D integers or fewer than two distinct labels.
  """
  arr = np.asarray(labels)
  if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer):
    raise ValueError(
      f'{name} must be a 1-D integer array, got {arr.dtype} {arr.shape}.'
    )
  if np.unique(arr).size < 2:
    raise ValueError(f'{name} must contain at least two distinct labels for triplets.')
  return arr.astype(np.int32)


def _label_ranges(labels, query):
  """Sorted order of ``labels`` and, per query label, its [start, start+count)."""
  order = jnp.argsort(labels, stable=True)
  sorted_labels = labels[order]
  start = jnp.searchsorted(sorted_labels, query, side='left')
  end = jnp.searchsorted(sorted_labels, query, side='right')
  return order, start, end - start


def random_triplets(key: jax.Array, labels: jax.Array, anchors: jax.Array) -> Triplets:
  """The paper's random triplets for given anchors.

  The positive is uniform over the anchor's label without the anchor itself
  (the anchor when its label has one image); the negative is uniform over all
  images of the other labels.

  Args:
    key: PRNG key.
    labels: ``(N,)`` int labels of the dataset.
    anchors: ``(B,)`` anchor indices into ``labels``.

  Returns:
    ``Triplets`` of ``(B,)`` int32 indices.
  """
  k_pos, k_neg = jax.random.split(key)
  n = labels.shape[0]
  order, start, count = _label_ranges(labels, labels[anchors])
  rank = jnp.zeros((n,), jnp.int32).at[order].set(jnp.arange(n, dtype=jnp.int32))
  own = rank[anchors] - start
  r = jax.random.randint(k_pos, anchors.shape, 0, jnp.maximum(count - 1, 1))
  # Skipping past the anchor's own slot makes the positive a different image.
  pos_offset = jnp.where(count > 1, (own + 1 + r) % count, own)
  positive = order[start + pos_offset]
  r = jax.random.randint(k_neg, anchors.shape, 0, n - count)
  negative = order[jnp.where(r < start, r, r + count)]
  return Triplets(
    anchors.astype(jnp.int32), positive.astype(jnp.int32), negative.astype(jnp.int32)
  )


def sample_triplets(key: jax.Array, labels: jax.Array, num: int) -> Triplets:
  """``num`` random triplets with anchors drawn uniformly (with replacement).

  Args:
    key: PRNG key.
    labels: ``(N,)`` int labels.
    num: number of triplets (static).

  Returns:
    ``Triplets`` of ``(num,)`` int32 indices.
  """
  k_anchor, k_rest = jax.random.split(key)
  anchors = jax.random.randint(k_anchor, (num,), 0, labels.shape[0])
  return random_triplets(k_rest, labels, anchors)


def pk_batch(
  key: jax.Array,
  labels: jax.Array,
  unique_labels: jax.Array,
  num_labels: int,
  per_label: int,
) -> jax.Array:
  """A batch-hard batch: ``num_labels`` distinct labels x ``per_label`` images.

  Images within a label are drawn with replacement (labels may have fewer
  images than ``per_label``).

  Args:
    key: PRNG key.
    labels: ``(N,)`` int labels.
    unique_labels: ``(L,)`` the distinct labels (``L >= num_labels``).
    num_labels: P, static.
    per_label: K, static.

  Returns:
    ``(P * K,)`` int32 dataset indices, grouped by label.
  """
  k_lab, k_img = jax.random.split(key)
  chosen = jax.random.choice(k_lab, unique_labels, (num_labels,), replace=False)
  order, start, count = _label_ranges(labels, chosen)
  off = jax.random.randint(k_img, (num_labels, per_label), 0, count[:, None])
  return order[start[:, None] + off].reshape(-1).astype(jnp.int32)


def squared_distances(x: jax.Array, y: jax.Array) -> jax.Array:
  """Pairwise squared Euclidean distances ``(n, m)`` between ``(n, d)`` and ``(m, d)``.

  Computed from differences (not the |x|^2 - 2xy + |y|^2 expansion) so that
  identical points give exactly zero; embeddings are low-dimensional.
  """
  return jnp.sum((x[:, None, :] - y[None, :, :]) ** 2, axis=-1)


def triplet_loss(
  anchor: jax.Array, positive: jax.Array, negative: jax.Array, margin: float = 1.0
) -> tuple[jax.Array, jax.Array]:
  """The original triplet loss with squared Euclidean distances.

  ``mean_i max(0, |a_i - p_i|^2 - |a_i - n_i|^2 + margin)``.

  Args:
    anchor: ``(B, d)`` embeddings.
    positive: ``(B, d)``.
    negative: ``(B, d)``.
    margin: the margin (1 in the paper).

  Returns:
    (loss ``()``, fraction of triplets with a positive hinge ``()``).
  """
  d_ap = jnp.sum((anchor - positive) ** 2, axis=-1)
  d_an = jnp.sum((anchor - negative) ** 2, axis=-1)
  hinge = jnp.maximum(d_ap - d_an + margin, 0.0)
  return jnp.mean(hinge), jnp.mean(hinge > 0)


def batch_hard_indices(
  embeddings: jax.Array, labels: jax.Array
) -> tuple[jax.Array, jax.Array]:
  """Hardest positive and negative of each anchor within a batch.

  Args:
    embeddings: ``(B, d)``.
    labels: ``(B,)`` int labels.

  Returns:
    (positive, negative) ``(B,)`` int32 batch indices: the farthest image of
    the same label other than the anchor (the anchor itself when it has none)
    and the nearest image of another label.
  """
  d2 = squared_distances(embeddings, embeddings)
  same = labels[:, None] == labels[None, :]
  eye = jnp.eye(labels.shape[0], dtype=bool)
  pos_cand = jnp.where(same & ~eye, d2, -jnp.inf)
  positive = jnp.where(
    jnp.any(same & ~eye, axis=1),
    jnp.argmax(pos_cand, axis=1),
    jnp.arange(labels.shape[0]),
  )
  negative = jnp.argmin(jnp.where(same, jnp.inf, d2), axis=1)
  return positive.astype(jnp.int32), negative.astype(jnp.int32)


def batch_hard_loss(
  embeddings: jax.Array, labels: jax.Array, margin: float = 1.0
) -> tuple[jax.Array, jax.Array]:
  """Triplet loss over batch-hard triplets (every image is an anchor).

  Args:
    embeddings: ``(B, d)``.
    labels: ``(B,)`` int labels; the batch must hold at least two labels.
    margin: the margin.

  Returns:
    (loss ``()``, fraction of active triplets ``()``).
  """
  pos, neg = batch_hard_indices(jax.lax.stop_gradient(embeddings), labels)
  return triplet_loss(embeddings, embeddings[pos], embeddings[neg], margin)
