"""Tests for model.triplets: hand-computed loss, sampler invariants, batch-hard mining."""

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

from model import triplets

_TOLERANCE = 1e-6


class TripletLossTest(absltest.TestCase):
  def test_hand_computed(self):
    a = jnp.array([[0.0, 0.0], [1.0, 1.0]])
    p = jnp.array([[1.0, 0.0], [1.0, 2.0]])
    n = jnp.array([[0.0, 3.0], [1.0, 1.5]])
    # Triplet 0: |a-p|^2 = 1, |a-n|^2 = 9 -> max(0, 1 - 9 + 1) = 0.
    # Triplet 1: |a-p|^2 = 1, |a-n|^2 = 0.25 -> max(0, 1 - 0.25 + 1) = 1.75.
    loss, active = triplets.triplet_loss(a, p, n, margin=1.0)
    np.testing.assert_allclose(loss, (0.0 + 1.75) / 2, atol=_TOLERANCE)
    np.testing.assert_allclose(active, 0.5, atol=_TOLERANCE)

  def test_margin_enters_linearly(self):
    a, p, n = jnp.zeros((1, 2)), jnp.ones((1, 2)), jnp.ones((1, 2))
    loss, _ = triplets.triplet_loss(a, p, n, margin=0.3)
    np.testing.assert_allclose(loss, 0.3, atol=_TOLERANCE)


class SamplerTest(absltest.TestCase):
  def test_random_triplets_respect_labels(self):
    labels = jnp.array([5, 2, 5, 9, 2, 2, 9, 5, 7])  # label 7 has one image
    anchors = jnp.tile(jnp.arange(9), 200)
    t = jax.jit(triplets.random_triplets)(jax.random.PRNGKey(0), labels, anchors)
    lab = np.asarray(labels)
    a, p, n = (np.asarray(v) for v in t)
    np.testing.assert_array_equal(a, np.asarray(anchors))
    np.testing.assert_array_equal(lab[p], lab[a])
    self.assertTrue(np.all(lab[n] != lab[a]))
    single = lab[a] == 7
    np.testing.assert_array_equal(p[single], a[single])
    self.assertTrue(np.all(p[~single] != a[~single]))
    # Every same-label partner and every other-label image is reachable.
    for i in range(9):
      sel = a == i
      same = set(np.flatnonzero(lab == lab[i])) - (
        {i} if (lab == lab[i]).sum() > 1 else set()
      )
      self.assertEqual(set(p[sel]), same)
      self.assertEqual(set(n[sel]), set(np.flatnonzero(lab != lab[i])))

  def test_negative_is_uniform_over_other_images(self):
    labels = jnp.array([0] * 3 + [1] * 1 + [2] * 6)
    t = triplets.random_triplets(
      jax.random.PRNGKey(1), labels, jnp.zeros((20_000,), jnp.int32)
    )
    counts = np.bincount(np.asarray(t.negative), minlength=10)[3:] / 20_000
    np.testing.assert_allclose(counts, np.full(7, 1 / 7), atol=0.02)

  def test_pk_batch(self):
    labels = jnp.array([0, 0, 1, 1, 1, 2, 3, 3])
    unique = jnp.array([0, 1, 2, 3])
    idx = np.asarray(triplets.pk_batch(jax.random.PRNGKey(2), labels, unique, 3, 4))
    lab = np.asarray(labels)[idx].reshape(3, 4)
    self.assertTrue(np.all(lab == lab[:, :1]))
    self.assertEqual(len(set(lab[:, 0])), 3)


class BatchHardTest(absltest.TestCase):
  def test_hand_made_case(self):
    # Label 0 at x = 0, 1, 5; label 1 at x = 2, 10 (1-D embeddings).
    emb = jnp.array([[0.0], [1.0], [5.0], [2.0], [10.0]])
    labels = jnp.array([0, 0, 0, 1, 1])
    pos, neg = triplets.batch_hard_indices(emb, labels)
    # Farthest same-label / nearest other-label: 0 -> (2, 3); 1 -> (2, 3);
    # 2 -> (0, 3); 3 -> (4, 1 or 2? |2-1|=1 < |2-5|=3 -> 1); 4 -> (3, 2).
    np.testing.assert_array_equal(pos, [2, 2, 0, 4, 3])
    np.testing.assert_array_equal(neg, [3, 3, 3, 1, 2])
    loss, _ = triplets.batch_hard_loss(emb, labels, margin=1.0)
    d_ap = np.array([25, 16, 25, 64, 64], float)
    d_an = np.array([4, 1, 9, 1, 25], float)
    np.testing.assert_allclose(
      loss, np.maximum(d_ap - d_an + 1, 0).mean(), rtol=_TOLERANCE
    )

  def test_singleton_label_uses_itself_as_positive(self):
    emb = jnp.array([[0.0], [3.0], [4.0]])
    pos, neg = triplets.batch_hard_indices(emb, jnp.array([0, 1, 1]))
    np.testing.assert_array_equal(pos, [0, 2, 1])
    np.testing.assert_array_equal(neg, [1, 0, 0])

  def test_check_labels(self):
    with self.assertRaisesRegex(ValueError, 'two distinct'):
      triplets.check_labels(np.zeros(4, int))
    with self.assertRaisesRegex(ValueError, 'integer'):
      triplets.check_labels(np.zeros(4))


if __name__ == '__main__':
  absltest.main()
