"""Tests for bo.kernels against NumPy formulas."""

import jax
import numpy as np
from absl.testing import absltest, parameterized

from bo import kernels

_TOLERANCE = 1e-10


def _np_kernel(name, x1, x2, ls):
  r = np.sqrt((((x1[:, None] - x2[None]) / ls) ** 2).sum(-1))
  if name == 'rbf':
    return np.exp(-0.5 * r**2)
  s = np.sqrt(5.0) * r
  return (1 + s + s**2 / 3) * np.exp(-s)


class KernelsTest(parameterized.TestCase):
  @parameterized.parameters('matern52', 'rbf')
  def test_matches_numpy(self, name):
    rng = np.random.default_rng(0)
    x1, x2 = rng.uniform(-1, 1, (5, 3)), rng.uniform(-1, 1, (4, 3))
    ls = np.array([0.3, 1.0, 2.0])
    with jax.enable_x64(True):
      k = np.asarray(kernels.get(name)(x1, x2, ls))
    np.testing.assert_allclose(k, _np_kernel(name, x1, x2, ls), atol=_TOLERANCE)

  @parameterized.parameters('matern52', 'rbf')
  def test_gradient_finite_on_diagonal(self, name):
    x = np.zeros((2, 2), np.float32)
    g = jax.grad(lambda ls: kernels.get(name)(x, x, ls).sum())(np.ones(2, np.float32))
    self.assertTrue(np.all(np.isfinite(g)))

  def test_unknown(self):
    with self.assertRaises(ValueError):
      kernels.get('linear')


if __name__ == '__main__':
  absltest.main()
