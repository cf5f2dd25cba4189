"""Tests for model.metrics and model.splits on hand-made embeddings."""

import jax
import numpy as np
from absl.testing import absltest

from model import metrics, splits


class MetricsTest(absltest.TestCase):
  def test_triplet_accuracy_extremes(self):
    labels = np.repeat(np.arange(4), 5)
    perfect = np.stack([labels * 10.0, np.zeros_like(labels, float)], 1)
    key = jax.random.PRNGKey(0)
    self.assertEqual(metrics.triplet_accuracy(key, perfect, labels, 2000), 1.0)
    # Collapsed embedding: every distance ties, and ties count as wrong.
    self.assertEqual(
      metrics.triplet_accuracy(key, np.zeros((20, 2)), labels, 2000), 0.0
    )
    # Random embedding: near chance.
    rnd = np.random.default_rng(0).normal(size=(20, 2))
    self.assertAlmostEqual(
      metrics.triplet_accuracy(key, rnd, labels, 20_000), 0.5, delta=0.1
    )

  def test_knn_hand_case(self):
    ref = np.array([[0.0], [0.1], [0.2], [5.0], [5.1], [9.0]])
    ref_labels = np.array([7, 7, 7, 3, 3, 1])
    query = np.array([[0.05], [4.9], [8.0], [2.6]])
    # k=3: q0 -> 7,7,7; q1 -> 3,3,(9 vs 0.2: 0.2 is |4.9-0.2|=4.7 < 4.1? no, 9 -> 4.1) -> 3;
    # q2 -> 9 (1), 5.1 (3), 5.0 (3) -> 3; q3 -> 0.2, 0.1, 5.0 (2.4) -> 7.
    got = metrics.knn_accuracy(ref, ref_labels, query, np.array([7, 3, 3, 7]), k=3)
    self.assertEqual(got, 1.0)
    # k=2 tie for q2 (1 and 3 once each): the nearer neighbour's label (1) wins.
    self.assertEqual(
      metrics.knn_accuracy(ref, ref_labels, query[2:3], np.array([1]), k=2), 1.0
    )

  def test_embed_pads_last_batch(self):
    x = np.arange(10, dtype=np.float32)[:, None]
    out = metrics.embed(lambda p, v: v * p, np.float32(2.0), x, batch_size=4)
    np.testing.assert_array_equal(out, 2 * x)


class SplitsTest(absltest.TestCase):
  def test_by_group_holds_out_whole_groups(self):
    groups = np.repeat(np.arange(10), 6)
    train, test = splits.split_by_group(jax.random.PRNGKey(0), groups, 0.2)
    self.assertEqual(set(groups[test]).intersection(groups[train]), set())
    self.assertEqual(len(set(groups[test])), 2)
    np.testing.assert_array_equal(np.sort(np.concatenate([train, test])), np.arange(60))

  def test_random_split(self):
    train, test = splits.split_random(jax.random.PRNGKey(1), 50, 0.2)
    self.assertEqual((train.size, test.size), (40, 10))
    self.assertEqual(set(train) & set(test), set())
    with self.assertRaisesRegex(ValueError, 'test_fraction'):
      splits.split_random(jax.random.PRNGKey(1), 50, 1.5)
    with self.assertRaisesRegex(ValueError, 'two distinct'):
      splits.split_by_group(jax.random.PRNGKey(1), np.zeros(5, int), 0.5)


if __name__ == '__main__':
  absltest.main()
