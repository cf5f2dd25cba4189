"""Tests for bo.qmc."""

import numpy as np
from absl.testing import absltest

from bo import qmc


class HaltonTest(absltest.TestCase):
  def test_shape_range_and_determinism(self):
    a = qmc.halton(64, 5, seed=3)
    self.assertEqual(a.shape, (64, 5))
    self.assertTrue(np.all((a >= 0) & (a < 1)))
    np.testing.assert_array_equal(a, qmc.halton(64, 5, seed=3))
    self.assertFalse(np.allclose(a, qmc.halton(64, 5, seed=4)))

  def test_skip_continues_sequence(self):
    full = qmc.halton(20, 2, seed=1)
    np.testing.assert_allclose(qmc.halton(5, 2, seed=1, skip=15), full[15:])

  def test_low_discrepancy(self):
    # Each half of each axis gets close to half of the points.
    a = qmc.halton(256, 4, seed=0)
    frac = (a < 0.5).mean(axis=0)
    np.testing.assert_allclose(frac, 0.5, atol=0.02)


if __name__ == '__main__':
  absltest.main()
