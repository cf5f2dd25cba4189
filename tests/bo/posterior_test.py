"""Tests of bo.posterior: the likelihoods by hand and by closed form, the MaxVar
variance update against a refitted GP, grid sampling, resume, and calibration
on a simulator whose posterior is known in closed form."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.scipy.stats import norm

from bo import gp, posterior
from model import psd

# BOLFI's likelihood is in closed form; the Gibbs one by 21-node Gauss-Hermite
# against 10^6 Monte Carlo draws: the double exponential is hardest where the
# GP is unsure (sd 0.63 against a noise sd of 0.3), where it is 1.3% off at a
# likelihood of 0.015; near the mode it agrees to 1e-4.
_QUADRATURE_TOLERANCE = 1e-6
_MONTE_CARLO_TOLERANCE = 2e-2  # relative


def test_grid_points_are_cell_centres_in_c_order():
  pts = posterior.grid_points((2, 3))
  np.testing.assert_allclose(pts[:, 0], [-0.5, -0.5, -0.5, 0.5, 0.5, 0.5])
  np.testing.assert_allclose(pts[:3, 1], [-2 / 3, 0.0, 2 / 3])


@pytest.fixture(autouse=True)
def _x64():
  with jax.enable_x64(True):  # as bo.posterior runs inside PosteriorSearch
    yield


def test_log_likelihoods_by_hand():
  floor, sn, c = -2.0, 0.5, 0.7
  f = jnp.array([floor, floor + np.log(2.0), floor + c * sn])
  gibbs = posterior.log_l(f, floor, sn, 'gibbs', c)
  np.testing.assert_allclose(gibbs[:2], [0.0, -c / sn], rtol=1e-12)  # e^(log 2) - 1 = 1
  thr = posterior.log_l(f, floor, sn, 'threshold', c)
  np.testing.assert_allclose(thr[2], np.log(0.5), rtol=1e-12)  # on the threshold
  with pytest.raises(ValueError, match='likelihood'):
    posterior.log_l(f, floor, sn, 'exact', c)


def test_the_model_error_adds_to_the_simulators_scatter_in_quadrature():
  """By hand at a known f (no GP uncertainty): the likelihood in units of
  sqrt(sn^2 + e^2); e = 0 is the likelihood without the term."""
  mean = jnp.array([-2.0, -1.5, -0.4])
  var = jnp.zeros(3)
  floor, sn, c, e = -2.0, 0.3, 0.5, 0.4
  for form in posterior.DISCREPANCY_LIKELIHOODS:
    got = posterior.log_likelihood(
      mean, var, floor, sn, form=form, sharpness=c, model_error=e
    )
    want = posterior.log_l(mean, floor, 0.5, form, c)  # hypot(0.3, 0.4) = 0.5
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)  # quadrature sums
    np.testing.assert_array_equal(
      posterior.log_likelihood(mean, var, floor, sn, form=form, sharpness=c,
                               model_error=0.0),
      posterior.log_likelihood(mean, var, floor, sn, form=form, sharpness=c),
    )  # fmt: skip
  # gibbs, by hand: -c (e^(f - m) - 1) / sqrt(sn^2 + e^2)
  got = posterior.log_likelihood(mean, var, floor, sn, sharpness=c, model_error=e)
  np.testing.assert_allclose(
    got, -c * np.expm1(np.asarray(mean) - floor) / 0.5, rtol=1e-12, atol=1e-15
  )


def test_a_model_error_widens_the_posterior_about_the_same_place():
  """A quadratic log distance over one axis: the grid posterior's spread
  grows with the model error as sqrt(sn^2 + e^2) / sn does for a Gaussian
  (its variance goes with the likelihood's unit), and its mean stays."""
  x = jnp.linspace(-1.0, 1.0, 801)
  floor, sn = -3.0, 0.2
  mean = floor + jnp.log1p(20.0 * (x - 0.1) ** 2)  # d = d_min (1 + 20 (x - 0.1)^2)

  def moments(e):
    ll = posterior.log_likelihood(mean, jnp.zeros_like(x), floor, sn, model_error=e)
    w = np.exp(ll - ll.max())
    w /= w.sum()
    m = float(np.sum(w * x))
    return m, float(np.sqrt(np.sum(w * (x - m) ** 2)))

  (m0, s0), (m1, s1) = moments(0.0), moments(0.15)
  assert abs(m1 - m0) < 1e-6 and abs(m0 - 0.1) < 1e-6
  np.testing.assert_allclose(s1 / s0, np.sqrt(np.hypot(sn, 0.15) / sn), rtol=1e-3)


def test_averaging_over_the_gp_matches_closed_form_and_monte_carlo():
  mean = jnp.array([-1.0, 0.0, 0.8])
  var = jnp.array([0.0, 0.09, 0.4])
  floor, sn, c = -1.2, 0.3, 0.5
  # BOLFI's form has a closed form: E Phi((h - f) / sn) = Phi((h - mu) / sqrt(sn^2 + s^2)).
  got = posterior.log_likelihood(mean, var, floor, sn, form='threshold', sharpness=c)
  want = norm.logcdf((floor + c * sn - mean) / jnp.sqrt(sn**2 + var))
  np.testing.assert_allclose(got, want, atol=_QUADRATURE_TOLERANCE)
  f = mean + jnp.sqrt(var) * jax.random.normal(jax.random.key(0), (1_000_000, 3))
  mc = jnp.log(jnp.mean(jnp.exp(-c * jnp.expm1(f - floor) / sn), axis=0))
  got = posterior.log_likelihood(mean, var, floor, sn, form='gibbs', sharpness=c)
  np.testing.assert_allclose(np.exp(got), np.exp(mc), rtol=_MONTE_CARLO_TOLERANCE)


def _fitted(n=12, seed=0):
  with jax.enable_x64(True):
    rng = np.random.default_rng(seed)
    x = jnp.asarray(rng.uniform(-1, 1, (16, 2)))
    y = jnp.asarray(np.sin(3 * x[:, 0]) + 0.1 * rng.standard_normal(16))
    mask = jnp.arange(16) < n
    state = gp.fit(x, y, mask, jax.random.key(1), noise_prior=posterior.NOISE_PRIOR)
  return state, x, y, mask


def test_variance_update_equals_refitting_with_the_point():
  # MaxVar lowers the GP variance around each pick as if observed: the same
  # as conditioning on the point (hyperparameters fixed), whatever its value.
  with jax.enable_x64(True):
    state, x, y, mask = _fitted()
    xq = jnp.asarray(posterior.grid_points((7, 7)))
    _, var = gp.posterior(state, xq)
    c = xq[17]
    sn2 = jnp.exp(state.params.log_noise) * state.y_scale**2
    cov = gp.posterior_cov(state, xq, c, kernel='matern52') * state.y_scale**2
    updated = var - cov**2 / (var[17] + sn2)
    x2, y2, m2 = x.at[12].set(c), y.at[12].set(123.0), mask.at[12].set(True)
    refit = gp.condition(state.params, x2, y2, m2, kernel='matern52')
    # standardisation changes with the new value: compare in standardised units
    _, var2 = gp.posterior(refit, xq)
    np.testing.assert_allclose(
      updated / state.y_scale**2, var2 / refit.y_scale**2, rtol=1e-6, atol=1e-10
    )


def test_maxvar_batch_spreads_and_respects_the_prior():
  with jax.enable_x64(True):
    state, *_ = _fitted()
    xq = jnp.asarray(posterior.grid_points((9, 9)))
    mean, _ = gp.posterior(state, xq)
    floor = jnp.min(mean)
    idx = np.asarray(posterior.maxvar_batch(state, xq, jnp.zeros(81), floor, 4))
    assert len(set(idx.tolist())) == 4  # the update moves the next pick away
    # a prior that rules out half of the box keeps every pick in the other half
    lp = jnp.where(xq[:, 0] < 0, 0.0, -1e6)
    idx = np.asarray(posterior.maxvar_batch(state, xq, lp, floor, 4))
    assert np.all(np.asarray(xq)[idx, 0] < 0)


def test_grid_draws_follow_the_cell_masses():
  pts = jnp.asarray(posterior.grid_points((2, 2)))
  log_post = jnp.log(jnp.array([0.25, 0.0, 0.0, 0.75]) + 1e-30)
  s = np.asarray(
    posterior.sample_grid(jax.random.key(0), pts, log_post, (2, 2), 40_000)
  )
  # cells (0, 0) and (1, 1): the quadrants x, y < 0 and x, y > 0
  assert np.all((s[:, 0] < 0) == (s[:, 1] < 0))
  assert np.mean(s[:, 0] > 0) == pytest.approx(0.75, abs=0.01)
  assert np.all(np.abs(s) <= 1.0)


def test_cell_draws_match_the_masses_of_a_float64_reference():
  # 18 432 cells, the default grid's count, with masses spanning 1e-6..1 and a
  # block of cells ruled out; 200 000 draws.
  rng = np.random.default_rng(3)
  mass = rng.random(12 * 64 * 24) ** 6
  mass[100:400] = 0.0
  p = mass / mass.sum()  # float64 reference
  with np.errstate(divide='ignore'):
    log_p = jnp.asarray(np.log(mass) + 7.0)  # unnormalised, as log posteriors are
  n = 200_000
  idx = np.asarray(posterior.sample_cells(jax.random.key(1), log_p, n))
  assert idx.min() >= 0 and idx.max() < len(p)
  assert not np.any((idx >= 100) & (idx < 400))  # zero mass: never drawn
  # coarse bins of ~1% mass each: counts within 5 binomial sd of n * mass
  edges = np.searchsorted(np.cumsum(p), np.linspace(0, 1, 101)[1:-1])
  counts = np.add.reduceat(np.bincount(idx, minlength=len(p)), np.r_[0, edges])
  expect = n * np.add.reduceat(p, np.r_[0, edges])
  sd = np.sqrt(expect * (1 - expect / n))
  assert np.all(np.abs(counts - expect) <= 5 * sd + 1), np.max(
    np.abs(counts - expect) / sd
  )


def _quadratic_config(**kw):
  return posterior.PosteriorConfig(d=2, grid=(10, 10), q=4, samples=500, **kw)


def test_resumed_search_goes_as_an_uninterrupted_one(tmp_path):
  def d(x):  # a noiseless bowl: every run sees the same values
    return np.sum((x - 0.3) ** 2, axis=1) + 0.01

  def run(path, stop_after=None):
    s = posterior.PosteriorSearch(_quadratic_config(), n_init=6, n_iter=3, x0=[0, 0],
                                  state_path=path)  # fmt: skip
    st = s.start()
    k = 0
    while not s.done(st) and (stop_after is None or k < stop_after):
      x, st = s.ask(st)
      st = s.tell(st, x, d(x))
      k += 1
    return s, st

  _, full = run(str(tmp_path / 'a.npz'))
  run(str(tmp_path / 'b.npz'), stop_after=2)
  _, resumed = run(str(tmp_path / 'b.npz'))
  np.testing.assert_allclose(resumed.X, full.X, atol=1e-12)
  assert resumed.iteration == full.iteration == 3
  with pytest.raises(ValueError, match='other settings'):
    posterior.PosteriorSearch(
      _quadratic_config(sharpness=2.0), n_init=6, n_iter=3,
      state_path=str(tmp_path / 'a.npz'),
    ).start()  # fmt: skip


# -------------------------------------------------- calibration, closed form
#
# A simulator like the estimate's: a "video" is T points of a 2-D embedding
# drawn around g(theta) = A theta with spread SIGMA, the discrepancy is the
# energy distance between the recording's points and a simulation's (as the
# PSD is). The exact posterior given the recording depends on its mean only:
# prior(theta) x N(mean; A theta, SIGMA^2 / T), on a fine grid.

_T, _SIGMA = 16, 0.3
_A = np.array([[1.0, 0.3], [0.0, 0.6]])


@jax.jit
def _discrepancy(theta, obs, key):
  pts = (theta @ _A.T)[:, None, :] + _SIGMA * jax.random.normal(
    key, (theta.shape[0], _T, 2)
  )
  return jax.vmap(lambda p: psd.energy_distance(p, obs))(pts)


def _exact_intervals(obs, log_prior_fn, levels):
  fine = posterior.grid_points((200, 200))
  ll = -0.5 * np.sum((obs.mean(0) - fine @ _A.T) ** 2, -1) / (_SIGMA**2 / _T)
  lp = ll + log_prior_fn(fine)
  w = np.exp(lp - lp.max())
  out = {}
  for i in range(2):
    order = np.argsort(fine[:, i])
    cdf = np.cumsum(w[order]) / w.sum()
    out[i] = {
      lv: np.interp([(1 - lv) / 2, (1 + lv) / 2], cdf, fine[order, i]) for lv in levels
    }
  return out


_SHARPNESS = (0.5, 0.7, 1.0, 1.4, 2.0, 2.8)  # candidates of the likelihood's constant
_LEVELS = (0.5, 0.9)
_WIDTH_RATIO = 1.8  # calibrated 90% width / exact 90% width, at most


def _check(cover, width):
  """Held-out coverage near the levels and erring wide (binomial sd over 100
  problems: 0.03 at 90%, 0.05 at 50%), widths within _WIDTH_RATIO of exact."""
  np.testing.assert_array_less(0.9 - 0.06, cover['bolfi'][1])
  np.testing.assert_array_less(cover['bolfi'][1], 0.99)
  np.testing.assert_array_less(0.5 - 0.1, cover['bolfi'][0])
  np.testing.assert_array_less(cover['bolfi'][0], 0.5 + 0.15)
  np.testing.assert_array_less(width['bolfi'], _WIDTH_RATIO * width['exact'])


def _problems(n_problems, log_prior_fn=None):
  """Runs the search on ``n_problems`` toy recordings; per problem the truth,
  the exact central intervals ``[level, bound, dim]``, the log prior on the
  search grid and the final GP (mean, variance, floor, noise) on it."""
  config = posterior.PosteriorConfig(d=2, grid=(24, 24), q=6, samples=2000)
  grid = posterior.grid_points(config.grid)
  rng = np.random.default_rng(0)
  out = []
  for i in range(n_problems):
    theta = rng.uniform(-1, 1, 2)
    obs = theta @ _A.T + _SIGMA * rng.standard_normal((_T, 2))
    lp_fn = log_prior_fn(theta, rng) if log_prior_fn else (lambda p: np.zeros(len(p)))
    s = posterior.PosteriorSearch(config, n_init=12, n_iter=3, x0=[0, 0], seed=i,
                                  log_prior=lp_fn(grid))  # fmt: skip
    st, k = s.start(), 0
    while not s.done(st):
      x, st = s.ask(st)
      y = _discrepancy(jnp.asarray(x), jnp.asarray(obs), jax.random.key(1000 * i + k))
      st, k = s.tell(st, x, np.asarray(y)), k + 1
    res = s.result(st)
    exact = _exact_intervals(obs, lp_fn, _LEVELS)
    out.append(dict(
      theta=theta, log_prior=lp_fn(grid), gp=(res.mean, res.var, res.floor, res.noise_sd),
      exact=np.array([[[exact[d][lv][b] for d in range(2)] for b in range(2)]
                      for lv in _LEVELS]),
    ))  # fmt: skip
  return out, config.grid


def _coverage(problems, shape, sharpness):
  """Coverage ``[level, dim]`` and mean 90% widths ``(dim,)`` of the posterior
  at ``sharpness`` (formed from each problem's final GP) and of the exact one."""
  points = posterior.grid_points(shape)
  hit = {k: np.zeros((2, 2)) for k in ('bolfi', 'exact')}
  width = {k: np.zeros(2) for k in ('bolfi', 'exact')}
  for i, p in enumerate(problems):
    ll = posterior.log_likelihood(*p['gp'], sharpness=sharpness)
    log_post = posterior.log_normalise(jnp.asarray(p['log_prior'] + ll))
    draws = np.asarray(
      posterior.sample_grid(jax.random.key(i), points, log_post, shape, 4000)
    )
    for j, lv in enumerate(_LEVELS):
      q = np.quantile(draws, [(1 - lv) / 2, (1 + lv) / 2], axis=0)
      for name, (lo, hi) in (('bolfi', q), ('exact', p['exact'][j])):
        hit[name][j] += (lo <= p['theta']) & (p['theta'] <= hi)
        if lv == 0.9:
          width[name] += hi - lo
  n = len(problems)
  return {k: v / n for k, v in hit.items()}, {k: v / n for k, v in width.items()}


def _calibrated(problems, shape) -> float:
  """The sharpness ``bo.posterior.choose_sharpness`` picks on ``problems``."""
  cover = {c: _coverage(problems, shape, c)[0]['bolfi'] for c in _SHARPNESS}
  return posterior.choose_sharpness(cover, _LEVELS)


@pytest.fixture(scope='module')
def toy_problems():
  # 200 problems: 100 choose the sharpness, 100 held out report it (a coverage
  # of 0.9 has a binomial sd of 0.03 there, 0.5 of 0.05).
  with jax.enable_x64(True):
    problems, shape = _problems(200)
    return problems, shape, _calibrated(problems[:100], shape)


@pytest.mark.slow
def test_calibrated_intervals_cover_held_out_truths_as_often_as_they_say(toy_problems):
  problems, shape, c = toy_problems
  cover, width = _coverage(problems[100:], shape, c)
  # Not wide for safety: from 30 noisy simulations the 90% widths are about
  # 1.6x the exact posterior's (the GP's own uncertainty), the prior's ~7x.
  _check(cover, width)


@pytest.mark.slow
def test_a_measured_coordinate_narrows_the_other_as_the_exact_posterior_does(
  toy_problems,
):
  # The known-wind mode on the same simulator, with the sharpness calibrated
  # on the video alone: dimension 0 read with sd 0.05 (a noisy reading around
  # the truth) enters as a Gaussian prior.
  def prior(theta, rng):
    reading = theta[0] + 0.05 * rng.standard_normal()
    return lambda p: -0.5 * ((p[:, 0] - reading) / 0.05) ** 2

  _, shape, c = toy_problems
  problems, _ = _problems(100, log_prior_fn=prior)
  cover, width = _coverage(problems, shape, c)
  _check(cover, width)


def test_choose_sharpness_takes_the_sharpest_that_never_under_covers():
  levels = (0.5, 0.9)
  cover = {
    0.5: [[0.7, 0.6], [0.97, 0.95]],
    1.0: [[0.55, 0.5], [0.92, 0.9]],  # every coverage at its level or above
    2.0: [[0.5, 0.45], [0.9, 0.85]],  # closer on average, but under-covers
  }
  assert posterior.choose_sharpness(cover, levels) == 1.0
  assert (
    posterior.choose_sharpness({1.0: [[0.4], [0.8]], 3.0: [[0.3], [0.7]]}, levels)
    == 1.0
  )
