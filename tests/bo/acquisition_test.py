"""Tests for bo.acquisition: log-EI against closed-form EI, stability, UCB."""

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

from bo import acquisition

_LOG_EI_RTOL = 1e-9


class AcquisitionTest(absltest.TestCase):
  def test_log_ei_matches_closed_form(self):
    # Where closed-form EI is far from underflow, both must agree.
    z = np.linspace(-8.0, 5.0, 131)
    with jax.enable_x64(True):
      mean = jnp.asarray(-z * 0.7)
      var = jnp.full_like(mean, 0.49)
      log_ei = acquisition.log_ei(mean, var, 0.0)
      ei = acquisition.ei(mean, var, 0.0)
    np.testing.assert_allclose(log_ei, np.log(ei), rtol=_LOG_EI_RTOL, atol=1e-12)

  def test_log_h_stable_in_the_tail(self):
    with jax.enable_x64(True):
      z = jnp.asarray([-10.0, -40.0, -1e3, -1e9])
      v = acquisition.log_h(z)
      g = jax.vmap(jax.grad(acquisition.log_h))(z)
    # Asymptote: log h(z) ~ -z^2/2 - log(2 pi)/2 - 2 log|z|.
    z = np.asarray(z)
    asym = -0.5 * z**2 - 0.5 * np.log(2 * np.pi) - 2 * np.log(np.abs(z))
    self.assertTrue(np.all(np.isfinite(v)) and np.all(np.isfinite(g)))
    np.testing.assert_allclose(v[2:], asym[2:], rtol=1e-6)
    # The gradient points towards larger z (more improvement).
    self.assertTrue(np.all(g > 0))

  def test_log_h_float32_finite(self):
    z = jnp.linspace(-200.0, 10.0, 64, dtype=jnp.float32)
    v = acquisition.log_h(z)
    g = jax.vmap(jax.grad(acquisition.log_h))(z)
    self.assertTrue(np.all(np.isfinite(v)) and np.all(np.isfinite(g)))
    self.assertTrue(np.all(np.diff(np.asarray(v)) > 0))

  def test_ucb(self):
    v = acquisition.ucb(jnp.array([1.0, 2.0]), jnp.array([4.0, 0.0]), 0.25)
    np.testing.assert_allclose(v, [0.0, -2.0])

  def test_optimize_finds_maximum(self):
    target = jnp.array([0.3, -0.6])
    acq = lambda x: -jnp.sum((x - target) ** 2, axis=-1)
    rng = np.random.default_rng(0)
    x, v = jax.jit(
      lambda k: acquisition.optimize(
        acq, k, jnp.asarray(rng.uniform(0, 1, (64, 2))), jnp.zeros((1, 2)),
        n_restarts=4,
      )
    )(jax.random.PRNGKey(0))  # fmt: skip
    np.testing.assert_allclose(x, target, atol=1e-4)
    # And at a bound when the optimum lies outside the box.
    acq2 = lambda x: -jnp.sum((x - 2.0) ** 2, axis=-1)
    x2, _ = acquisition.optimize(
      acq2, jax.random.PRNGKey(1), jnp.asarray(rng.uniform(0, 1, (64, 2))),
      jnp.zeros((1, 2)), n_restarts=4,
    )  # fmt: skip
    np.testing.assert_allclose(x2, [1.0, 1.0], atol=1e-6)


if __name__ == '__main__':
  absltest.main()
