"""Evaluation of an embedding: triplet accuracy, k-NN label accuracy, batched embedding."""

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from model import triplets


def embed(apply: Callable, params, x, batch_size: int = 256) -> np.ndarray:
  """Embeds a dataset in fixed-size batches (the last one padded, so one compile).

  Args:
    apply: ``apply(params, x) -> (B, d)``; it is jitted here.
    params: network params.
    x: ``(N, ...)`` host or device array.
    batch_size: batch size.

  Returns:
    ``(N, d)`` float32 NumPy embeddings.
  """
  fn = jax.jit(apply)
  n = len(x)
  out = []
  for i in range(0, n, batch_size):
    chunk = np.asarray(x[i : i + batch_size])
    pad = batch_size - len(chunk) if n > batch_size else 0
    if pad:
      chunk = np.concatenate([chunk, np.repeat(chunk[-1:], pad, axis=0)])
    out.append(np.asarray(fn(params, jnp.asarray(chunk)))[: len(chunk) - pad])
  return np.concatenate(out).astype(np.float32)


def triplet_accuracy(
  key: jax.Array, embeddings, labels, num_triplets: int = 10_000
) -> float:
  """Fraction of random triplets ordered correctly: ``d(a, p) < d(a, n)``.

  Triplets are drawn as in training (``triplets.sample_triplets``: uniform
  anchor, uniform other image of its label, uniform image of another label)
  within the given set only; distances are squared Euclidean; a tie counts as
  wrong. On a by-simulation split this measures whether the embedding groups
  images of *unseen* parameter sets. Chance level is 0.5.

  Args:
    key: PRNG key (fix it for comparable numbers).
    embeddings: ``(N, d)``.
    labels: ``(N,)`` int labels with at least two distinct values.
    num_triplets: number of triplets sampled.

  Returns:
    The accuracy in [0, 1].
  """
  labels = jnp.asarray(triplets.check_labels(labels))
  return float(_triplet_accuracy(key, jnp.asarray(embeddings), labels, num_triplets))


@functools.partial(jax.jit, static_argnums=3)
def _triplet_accuracy(key, e, labels, num_triplets):
  t = triplets.sample_triplets(key, labels, num_triplets)
  d_ap = jnp.sum((e[t.anchor] - e[t.positive]) ** 2, axis=-1)
  d_an = jnp.sum((e[t.anchor] - e[t.negative]) ** 2, axis=-1)
  return jnp.mean(d_ap < d_an)


def knn_accuracy(
  ref_embeddings, ref_labels, query_embeddings, query_labels, k: int = 5
) -> float:
  """k-nearest-neighbour label accuracy of queries against a reference set.

  Each query takes the majority label of its k nearest reference embeddings
  (Euclidean); a tie goes to the tied label with the nearer neighbour. Under
  the paper's random per-image split the query labels occur in the reference
  (training) set, so this is a clustering/classification accuracy; under a
  by-simulation split it is always 0 and is not meaningful.

  Args:
    ref_embeddings: ``(R, d)``.
    ref_labels: ``(R,)`` int.
    query_embeddings: ``(Q, d)``.
    query_labels: ``(Q,)`` int.
    k: neighbours (``1 <= k <= R``).

  Returns:
    The fraction of queries whose predicted label is right.
  """
  ref_labels = np.asarray(ref_labels)
  if not 1 <= k <= len(ref_labels):
    raise ValueError(f'k must be in [1, {len(ref_labels)}], got {k}.')
  classes, ref_ids = np.unique(ref_labels, return_inverse=True)
  pred = _knn_predict(
    jnp.asarray(ref_embeddings),
    jnp.asarray(ref_ids),
    jnp.asarray(query_embeddings),
    k,
    classes.size,
  )
  return float(np.mean(classes[np.asarray(pred)] == np.asarray(query_labels)))


@functools.partial(jax.jit, static_argnums=(3, 4))
def _knn_predict(ref, ref_ids, query, k, num_classes):
  d2 = triplets.squared_distances(query, ref)
  _, nearest = jax.lax.top_k(-d2, k)  # (Q, k), nearest first
  votes = jax.nn.one_hot(ref_ids[nearest], num_classes)  # (Q, k, L)
  # Count decides (steps of 2); the nearest member's rank term, in (0, 1], breaks ties.
  nearness = 1.0 - jnp.arange(k)[None, :, None] / k
  scores = 2.0 * jnp.sum(votes, axis=1) + jnp.max(votes * nearness, axis=1)
  return jnp.argmax(scores, axis=1)
