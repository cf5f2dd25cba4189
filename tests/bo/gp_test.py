"""Tests for bo.gp: posterior vs a float64 NumPy GP, LML gradient, no recompiles."""

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

from bo import gp

_POSTERIOR_TOLERANCE = 1e-8
_GRAD_RTOL = 1e-5
_FD_STEP = 1e-6


def _data(n, cap, d=2, seed=0):
  rng = np.random.default_rng(seed)
  x = np.zeros((cap, d))
  x[:n] = rng.uniform(-1, 1, (n, d))
  y = np.full(cap, np.nan)  # Padding holds garbage: it must be ignored.
  y[:n] = np.sin(3 * x[:n, 0]) + x[:n, 1] ** 2
  return x, y, np.arange(cap) < n


def _params(d):
  return gp.GPParams(
    jnp.log(jnp.linspace(0.4, 0.9, d)), jnp.asarray(0.3), jnp.asarray(-5.0)
  )


def _np_posterior(p, x, y, xq):
  """Textbook float64 GP (Matern-5/2) on the unpadded data."""
  ls, sf, sn = np.exp(p[:-2]), np.exp(p[-2]), np.exp(p[-1])

  def k(a, b):
    r = np.sqrt((((a[:, None] - b[None]) / ls) ** 2).sum(-1))
    s = np.sqrt(5) * r
    return sf * (1 + s + s**2 / 3) * np.exp(-s)

  mu, sd = y.mean(), y.std(ddof=1)
  ys = (y - mu) / sd
  kxx = k(x, x) + (sn + gp.JITTER) * np.eye(len(x))
  kq = k(xq, x)
  mean = kq @ np.linalg.solve(kxx, ys)
  var = sf - np.einsum('ij,ji->i', kq, np.linalg.solve(kxx, kq.T))
  return mu + sd * mean, sd**2 * var


class GPTest(absltest.TestCase):
  def test_posterior_matches_numpy(self):
    x, y, mask = _data(n=7, cap=16)
    xq = np.random.default_rng(1).uniform(-1, 1, (5, 2))
    with jax.enable_x64(True):
      p = _params(2)
      st = gp.condition(p, jnp.asarray(x), jnp.asarray(y), mask, kernel='matern52')
      mean, var = gp.posterior(st, xq)
      ref_mean, ref_var = _np_posterior(
        np.asarray(gp.params_to_array(p)), x[:7], y[:7], xq
      )
    np.testing.assert_allclose(mean, ref_mean, atol=_POSTERIOR_TOLERANCE)
    np.testing.assert_allclose(var, ref_var, atol=_POSTERIOR_TOLERANCE)

  def test_lml_gradient_matches_finite_differences(self):
    x, y, mask = _data(n=9, cap=16, d=3)
    with jax.enable_x64(True):
      ys, _, _ = gp.standardize(jnp.asarray(y), mask)

      def f(theta):
        p = gp.params_from_array(theta)
        return gp.log_marginal_likelihood(p, x, ys, mask, kernel='matern52')

      theta = gp.params_to_array(_params(3))
      grad = np.asarray(jax.grad(f)(theta))
      fd = np.array(
        [
          (f(theta.at[i].add(_FD_STEP)) - f(theta.at[i].add(-_FD_STEP)))
          / (2 * _FD_STEP)
          for i in range(theta.shape[0])
        ]
      )
    np.testing.assert_allclose(grad, fd, rtol=_GRAD_RTOL, atol=1e-7)

  def test_padding_does_not_change_lml(self):
    x, y, mask = _data(n=6, cap=8)
    with jax.enable_x64(True):
      p = _params(2)
      ys, _, _ = gp.standardize(jnp.asarray(y), mask)
      small = gp.log_marginal_likelihood(p, x[:6], ys[:6], mask[:6], kernel='rbf')
      padded = gp.log_marginal_likelihood(p, x, ys, mask, kernel='rbf')
    np.testing.assert_allclose(small, padded, rtol=1e-12)

  def test_fit_improves_objective_and_does_not_recompile(self):
    fit = jax.jit(gp.fit, static_argnames=('kernel', 'n_restarts', 'maxiter'))
    with jax.enable_x64(True):
      x, y, mask = _data(n=8, cap=16)
      key = jax.random.PRNGKey(0)
      prior = gp.default_params(2, jnp.float64)
      st = fit(x, np.nan_to_num(y), mask, key, init_params=prior)
      ys, _, _ = gp.standardize(jnp.asarray(y), mask)

      def objective(p):
        lml = gp.log_marginal_likelihood(p, x, ys, mask, kernel='matern52')
        return lml + gp.log_prior(p)

      self.assertGreater(objective(st.params), objective(prior))
      # More data in the same buffer: same compiled program.
      x2, y2, mask2 = _data(n=12, cap=16, seed=1)
      st2 = fit(x2, np.nan_to_num(y2), mask2, key, init_params=st.params)
      self.assertTrue(np.all(np.isfinite(gp.params_to_array(st2.params))))
    self.assertEqual(fit._cache_size(), 1)


if __name__ == '__main__':
  absltest.main()
