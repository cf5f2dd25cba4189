"""Tests for model.psd: set-distance properties and a float64 NumPy reference."""

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

from model import psd

_F32_TOLERANCE = 1e-5  # float32 JAX vs float64 NumPy, relative to O(1) distances


def _np_energy(x, y):
  """Textbook float64 energy distance (V-statistics)."""
  x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)

  def mean_dist(a, b):
    return np.mean(np.linalg.norm(a[:, None] - b[None], axis=-1))

  return 2 * mean_dist(x, y) - mean_dist(x, x) - mean_dist(y, y)


def _sets(seed=0, n=60, m=45):
  rng = np.random.default_rng(seed)
  return (
    rng.normal(size=(n, 2)).astype(np.float32),
    (rng.normal(size=(m, 2)) * [1.5, 0.5] + [0.3, -0.2]).astype(np.float32),
  )


class EnergyDistanceTest(absltest.TestCase):
  def test_matches_float64_reference(self):
    for seed in range(3):
      x, y = _sets(seed)
      np.testing.assert_allclose(
        psd.energy_distance(x, y),
        _np_energy(x, y),
        rtol=_F32_TOLERANCE,
        atol=_F32_TOLERANCE,
      )

  def test_zero_for_identical_sets_and_nonnegative(self):
    x, y = _sets(1)
    self.assertEqual(float(psd.energy_distance(x, x)), 0.0)
    for seed in range(20):
      a, b = _sets(seed, n=7, m=9)
      self.assertGreaterEqual(float(psd.energy_distance(a, b)), 0.0)

  def test_invariant_to_frame_order_and_symmetric(self):
    x, y = _sets(2)
    d = psd.energy_distance(x, y)
    perm = np.random.default_rng(0).permutation(len(x))
    np.testing.assert_allclose(
      psd.energy_distance(x[perm], y[::-1]), d, atol=_F32_TOLERANCE
    )
    np.testing.assert_allclose(psd.energy_distance(y, x), d, atol=_F32_TOLERANCE)

  def test_grows_with_shift(self):
    x, _ = _sets(3)
    shifts = [0.0, 0.25, 0.5, 1.0, 2.0, 4.0]
    d = [float(psd.energy_distance(x, x + jnp.array([s, 0.0]))) for s in shifts]
    self.assertEqual(d[0], 0.0)
    self.assertTrue(all(b > a for a, b in zip(d, d[1:], strict=False)), d)

  def test_gradient_finite_at_coincident_points(self):
    x, _ = _sets(4, n=5)
    g = jax.grad(psd.energy_distance)(jnp.asarray(x), jnp.asarray(x))
    self.assertTrue(np.all(np.isfinite(g)))

  def test_vmap_over_candidates(self):
    x, y = _sets(5)
    cands = np.stack([x, x + 1.0, x[::-1]])
    got = jax.jit(jax.vmap(psd.energy_distance, in_axes=(0, None)))(cands, y)
    want = [_np_energy(c, y) for c in cands]
    np.testing.assert_allclose(got, want, rtol=_F32_TOLERANCE, atol=_F32_TOLERANCE)


class OtherDistancesTest(absltest.TestCase):
  def test_centroid(self):
    x, y = _sets(6)
    want = np.sum((x.astype(np.float64).mean(0) - y.astype(np.float64).mean(0)) ** 2)
    np.testing.assert_allclose(psd.centroid_distance(x, y), want, rtol=_F32_TOLERANCE)
    perm = np.random.default_rng(1).permutation(len(x))
    np.testing.assert_allclose(
      psd.centroid_distance(x[perm], y), want, rtol=_F32_TOLERANCE
    )

  def test_paired_depends_on_pairing(self):
    x, _ = _sets(7, n=30)
    key = jax.random.PRNGKey(0)
    perm = np.asarray(jax.random.permutation(key, 30))
    want = np.sum((x.astype(np.float64) - x[perm]) ** 2)
    np.testing.assert_allclose(
      psd.paired_distance(key, x, x), want, rtol=_F32_TOLERANCE
    )
    # Unlike the set distances, a video compared with itself is not at zero.
    self.assertGreater(float(psd.paired_distance(key, x, x)), 1.0)
    with self.assertRaisesRegex(ValueError, 'equal shapes'):
      psd.paired_distance(key, x, x[:10])

  def test_dispatch(self):
    x, y = _sets(8, n=10, m=10)
    self.assertEqual(
      float(psd.psd(x, y, 'centroid')), float(psd.centroid_distance(x, y))
    )
    with self.assertRaisesRegex(ValueError, 'kind'):
      psd.psd(x, y, 'cosine')
    with self.assertRaisesRegex(ValueError, 'key'):
      psd.psd(x, y, 'paired')


if __name__ == '__main__':
  absltest.main()
