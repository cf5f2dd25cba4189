"""Pair sampling and the contrastive loss used to train the SDN baseline."""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from model import triplets


class Pairs(NamedTuple):
  """Dataset indices of a batch of pairs.

  Attributes:
    first: ``(B,)`` int32.
    second: ``(B,)`` int32.
    same: ``(B,)`` bool, whether the two share a label.
  """

  first: jax.Array
  second: jax.Array
  same: jax.Array


def random_pairs(key: jax.Array, labels: jax.Array, anchors: jax.Array) -> Pairs:
  """Pairs an anchor with a same-label image or, with probability 1/2, another label's.

  Args:
    key: PRNG key.
    labels: ``(N,)`` int labels.
    anchors: ``(B,)`` indices.

  Returns:
    ``Pairs``; ``same`` is True exactly where the partner shares the label
    (a single-image label pairs with itself when drawn positive).
  """
  k_trip, k_coin = jax.random.split(key)
  t = triplets.random_triplets(k_trip, labels, anchors)
  want_same = jax.random.bernoulli(k_coin, 0.5, anchors.shape)
  second = jnp.where(want_same, t.positive, t.negative)
  return Pairs(t.anchor, second, labels[second] == labels[t.anchor])


def contrastive_loss(
  first: jax.Array, second: jax.Array, same: jax.Array, margin: float = 1.0
) -> tuple[jax.Array, jax.Array]:
  """Hadsell-Chopra-LeCun contrastive loss with Euclidean distance d.

  ``mean(same * d^2 + (1 - same) * max(0, margin - d)^2)``.

  Args:
    first: ``(B, d)`` embeddings.
    second: ``(B, d)``.
    same: ``(B,)`` bool.
    margin: distance beyond which different-label pairs stop pushing.

  Returns:
    (loss ``()``, fraction of pairs with nonzero loss ``()``).
  """
  d2 = jnp.sum((first - second) ** 2, axis=-1)
  # sqrt has an infinite derivative at 0; different-label pairs rarely coincide.
  d = jnp.sqrt(jnp.maximum(d2, 1e-12))
  per_pair = jnp.where(same, d2, jnp.maximum(margin - d, 0.0) ** 2)
  return jnp.mean(per_pair), jnp.mean(per_pair > 0)
