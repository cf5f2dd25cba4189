"""bo.design on toy problems whose answers are known by hand."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bo import design


def _draws(sd, n=4000, seed=0):
  """(n, p) draws whose sample covariance is exactly diag(sd^2)."""
  x = np.random.default_rng(seed).normal(size=(n, len(sd)))
  x -= x.mean(0)
  x = x @ np.linalg.inv(np.linalg.cholesky(np.atleast_2d(np.cov(x, rowvar=False)))).T
  return x * np.asarray(sd)


def test_one_parameter_designs_pick_the_widest_parameter_by_hand():
  # y_d = theta_d + noise: design d sees only parameter d, at noise sd sigma_d.
  s = np.array([2.0, 0.5])  # the current posterior: parameter 0 is the widest
  x = _draws(s)
  info = lambda d, sigma: np.diag([1.0 / sigma**2 if i == d else 0.0 for i in (0, 1)])
  gains = {f'see {d}': design.expected_gain(x, None, info(d, 1.0)) for d in (0, 1)}
  # by hand: 0.5 log(1 + s_d^2 / sigma_d^2)
  assert gains['see 0'] == pytest.approx(0.5 * np.log(1 + 4.0), rel=1e-9)
  assert gains['see 1'] == pytest.approx(0.5 * np.log(1 + 0.25), rel=1e-9)
  assert design.rank(gains)[0][0] == 'see 0'
  # a noisy enough look at the widest parameter loses: 0.5 log(1 + 4/25) < 0.5 log 1.25
  gains['see 0'] = design.expected_gain(x, None, info(0, 5.0))
  assert gains['see 0'] == pytest.approx(0.5 * np.log(1 + 4 / 25), rel=1e-9)
  assert design.rank(gains)[0][0] == 'see 1'
  # the set of both: widths 1 / sqrt(1 / s^2 + 1 / sigma^2), by hand
  total = design.combine([np.ones((1, 1)), np.ones((1, 1)) / 4], [[0], [1]], 2)
  np.testing.assert_allclose(total, np.diag([1.0, 0.25]))
  np.testing.assert_allclose(
    design.widths(s, total), 1 / np.sqrt(1 / s**2 + [1.0, 0.25]), rtol=1e-12
  )
  np.testing.assert_allclose(
    design.narrowing(s, total), s * np.sqrt(1 / s**2 + [1.0, 0.25])
  )


def test_a_nuisance_is_marginalised_by_hand():
  # y = theta_0 + nu + noise: the gain about theta_0 with nu (sd q) unknown
  s0, q, sigma = 1.0, 0.7, 0.3
  info = design.fisher(np.array([[1.0, 1.0]]), np.array([[sigma**2]]))
  gain = design.expected_gain(_draws([s0]), None, info, nuisance_sd=[q])
  post_var = s0**2 - s0**4 / (s0**2 + q**2 + sigma**2)
  assert gain == pytest.approx(0.5 * np.log(s0**2 / post_var), rel=1e-9)
  # known nuisance (q -> 0): all of it is about theta_0
  gain = design.expected_gain(_draws([s0]), None, info, nuisance_sd=[1e-9])
  assert gain == pytest.approx(0.5 * np.log(1 + s0**2 / sigma**2), rel=1e-6)


def test_linear_gaussian_eig_is_the_closed_form_and_nested_mc_agrees():
  rng = np.random.default_rng(1)
  a = rng.normal(size=(4, 3))
  r = np.diag([0.5, 1.0, 2.0, 1.5]) ** 2
  s = np.diag([0.8, 0.5, 1.2]) ** 2
  closed = 0.5 * np.linalg.slogdet(np.eye(3) + s @ a.T @ np.linalg.solve(r, a))[1]
  info = design.fisher(a, r)
  assert design.eig(s, info) == pytest.approx(closed, rel=1e-10)
  # the nested Monte Carlo of the same linear-Gaussian problem; tolerance: its
  # standard error at 4000 outer draws is ~0.015 nats and its O(1/inner) bias
  # smaller, so 0.05 nats is > 3 standard errors
  draws = rng.normal(size=(4000, 3)) @ np.sqrt(s)
  nmc = design.eig_nested_mc(
    jax.random.key(0), draws, lambda t: jnp.asarray(a) @ t, r, inner=4000
  )
  assert nmc == pytest.approx(closed, abs=0.05)


def test_per_draw_slopes_average_and_nearest_lookup():
  # y = exp(theta) + noise: the slope depends on where the draw is
  x = _draws([0.3], n=500)
  j = design.linearize(lambda t: jnp.exp(t), x)  # (S, 1, 1)
  np.testing.assert_allclose(j[:, 0, 0], np.exp(x[:, 0]), rtol=1e-6)
  infos = design.fisher(j, np.full((len(x), 1, 1), 0.1**2))
  gain = design.expected_gain(x, np.ones(len(x)), infos)
  by_hand = np.mean(0.5 * np.log(1 + 0.09 * np.exp(2 * x[:, 0]) / 0.01))
  assert gain == pytest.approx(by_hand, rel=1e-5)  # float32 slopes
  nodes = np.array([[-1.0], [0.0], [1.0]])
  np.testing.assert_array_equal(
    design.nearest([[-0.8], [0.4], [0.6]], nodes), [0, 1, 2]
  )


def test_box_prior_shrink_and_bad_inputs():
  assert design.log_box_sd(0.1, 10.0) == pytest.approx(np.log(100) / np.sqrt(12))
  c = np.array([[1.0, 0.9], [0.9, 1.0]])
  np.testing.assert_allclose(design.shrink(c, 0.5), [[1.0, 0.45], [0.45, 1.0]])
  with pytest.raises(ValueError):
    design.log_box_sd(1.0, 0.5)
  with pytest.raises(ValueError):
    design.fisher(np.ones((3, 2)), np.eye(2))
  with pytest.raises(ValueError):
    design.embed(np.eye(2), [0, 5], 3)
