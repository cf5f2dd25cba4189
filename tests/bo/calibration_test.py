"""Tests of bo.calibration: ranks and order statistics by hand, and recalibrated
intervals on a Gaussian problem whose exact posterior is known in closed form.

The problem: theta ~ N(0, 1), y ~ N(theta, SIGMA^2), so theta | y ~ N(m, s^2)
with m = y / (1 + SIGMA^2), s^2 = SIGMA^2 / (1 + SIGMA^2). An approximate
posterior that is too narrow, too wide or shifted is recalibrated on
``_N_CAL`` problems and checked on ``_N_TEST`` held-out ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from bo import calibration

_SIGMA = 0.5
_N_CAL, _N_TEST, _DRAWS = 300, 2000, 2000
# Binomial sd of a coverage over _N_TEST problems: 0.011 at 50%, 0.0067 at 90%;
# the calibration set's own randomness adds about sqrt(a(1-a)/_N_CAL) (0.029,
# 0.017). Four combined sds:
_TOL = {0.5: 0.12, 0.9: 0.075}


def test_ranks_by_hand():
  draws = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0], [3.0, 1.0]])
  r = calibration.ranks(draws, np.array([1.5, 1.0]))
  np.testing.assert_allclose(r, [0.5, 0.5])  # 2 of 4 below; 4 ties count half
  np.testing.assert_allclose(calibration.ranks(draws, np.array([-1.0, 9.0])), [0, 1])
  with pytest.raises(ValueError, match='need draws'):
    calibration.ranks(draws, np.zeros(3))


def test_levels_are_the_conformal_order_statistics():
  r = np.arange(1, 20)[:, None] / 20.0  # n = 19 ranks 0.05 .. 0.95
  lv = calibration.levels(r, (0.05, 0.5, 0.95))[:, 0]
  # (n + 1) p = 1 and 19: the 1st and 19th smallest; the median is the 10th
  np.testing.assert_allclose(lv, [0.05, 0.5, 0.95])
  lv = calibration.levels(r[:9], (0.05, 0.95))[:, 0]  # (n + 1) p = 0.5, 9.5
  np.testing.assert_allclose(lv, [0.0, 1.0])  # too few problems: the whole posterior
  with pytest.raises(ValueError, match=r'\[0, 1\]'):
    calibration.levels(r + 1.0)
  with pytest.raises(ValueError, match='probs'):
    calibration.levels(r, (0.0, 0.5))


def test_centred_levels_keep_the_median_and_cover_a_shifted_posterior():
  # by hand: n = 9 distances |r - 0.5| = 0.05 .. 0.45; a = 0.5 takes the
  # ceil(10 x 0.5) = 5th (0.25), a = 0.9 the 9th (0.45)
  r = 0.5 + np.array([0.05, -0.1, 0.15, -0.2, 0.25, -0.3, 0.35, -0.4, 0.45])[:, None]
  lv = calibration.levels(r, centred=True)[:, 0]
  np.testing.assert_allclose(lv, [0.05, 0.25, 0.5, 0.75, 0.95], atol=1e-12)
  # too few for a level: the whole posterior, as the one-sided levels
  np.testing.assert_allclose(calibration.levels(r[:5], (0.05, 0.95), centred=True)[:, 0],
                             [0.0, 1.0])  # fmt: skip
  # A posterior shifted and too wide: the truth's rank ~ Beta(6, 3). The
  # one-sided levels move the median; the centred ones leave it, and their
  # central intervals still hold the truth at least as often as they say on
  # fresh ranks (split-conformal), to the binomial's 3 sd.
  rng = np.random.default_rng(0)
  fit, fresh = rng.beta(6, 3, (399, 1)), rng.beta(6, 3, 20000)
  assert calibration.levels(fit)[2, 0] > 0.6
  lv = calibration.levels(fit, centred=True)[:, 0]
  np.testing.assert_allclose(lv[::-1], 1.0 - lv, atol=1e-12)
  for (lo, hi), a in ((lv[[1, 3]], 0.5), (lv[[0, 4]], 0.9)):
    held = np.mean((fresh >= lo) & (fresh <= hi))
    assert held >= a - 3 * np.sqrt(a * (1 - a) / 399), (a, held)
    assert held <= a + 2 / 400 + 3 * np.sqrt(a * (1 - a) / 399), (a, held)


def test_quantiles_per_column():
  draws = np.stack([np.linspace(0, 1, 101), np.linspace(0, 10, 101)], axis=1)
  q = calibration.quantiles(draws, np.array([[0.1, 0.5], [0.9, 1.0]]))
  np.testing.assert_allclose(q, [[0.1, 5.0], [0.9, 10.0]], atol=1e-12)


@pytest.mark.parametrize('shape', [(2500, 4), (401,), (7, 2)])
def test_linear_quantiles_are_numpys_to_the_bit(shape):
  # NumPy's default method is the reference: every level of a dense grid (its
  # ends included), on draws with ties, 1-D and 2-D.
  rng = np.random.default_rng(3)
  x = rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 3)
  x[: max(1, shape[0] // 10)] = x[0]  # ties
  q = np.concatenate([np.linspace(0.0, 1.0, 1001), rng.random(50)])
  np.testing.assert_array_equal(
    calibration.linear_quantiles(x, q), np.quantile(x, q, axis=0)
  )


def test_defensive_mixture_holds_the_share_of_prior_draws():
  post, prior = np.zeros((980, 2)), np.ones((50, 2))
  mix = calibration.defensive(post, prior, share=0.02)
  assert mix.shape == (1000, 2)  # 980 * 0.02 / 0.98 = 20 prior rows
  assert np.mean(mix[:, 0]) == pytest.approx(0.02)
  with pytest.raises(ValueError, match='share'):
    calibration.defensive(post, prior, share=1.0)
  with pytest.raises(ValueError, match='do not match'):
    calibration.defensive(post, np.ones((5, 3)))


def test_interval_score_by_hand():
  # width 2; the truth 1 above the upper bound costs 2 / 0.1 * 1 = 20
  assert calibration.interval_score(0.0, 2.0, 3.0, 0.9) == pytest.approx(22.0)
  assert calibration.interval_score(0.0, 2.0, 1.0, 0.9) == pytest.approx(2.0)


def _problems(rng, n, scale, shift):
  """Truths and draws of an approximate posterior N(m + shift s, (scale s)^2)."""
  theta = rng.standard_normal(n)
  y = theta + _SIGMA * rng.standard_normal(n)
  s = np.sqrt(_SIGMA**2 / (1 + _SIGMA**2))
  m = y / (1 + _SIGMA**2)
  draws = m + shift * s + scale * s * rng.standard_normal((_DRAWS, n))
  return theta, draws  # (n,), (S, n)


def _coverage(theta, draws, cdf_levels):
  """Per level of ``PROBS``' intervals (50%, 90%): share of truths inside."""
  lv = np.asarray(cdf_levels)
  q = np.stack([np.quantile(draws[:, i], lv) for i in range(len(theta))])  # (n, 5)
  out = {}
  for a, (lo, hi) in ((0.5, (1, 3)), (0.9, (0, 4))):
    out[a] = np.mean((q[:, lo] <= theta) & (theta <= q[:, hi]))
  return out


@pytest.mark.parametrize(
  'scale, shift',
  [(0.5, 0.0), (2.0, 0.0), (1.0, 0.8), (1.0, 0.0)],
  ids=['too narrow', 'too wide', 'shifted', 'exact'],
)
def test_recalibrated_intervals_cover_held_out_problems(scale, shift):
  rng = np.random.default_rng(0)
  theta, draws = _problems(rng, _N_CAL, scale, shift)
  r = np.array([calibration.ranks(draws[:, i : i + 1], theta[i : i + 1])[0]
                for i in range(_N_CAL)])  # fmt: skip
  lv = calibration.levels(r[:, None])[:, 0]
  theta, draws = _problems(rng, _N_TEST, scale, shift)
  raw = _coverage(theta, draws, calibration.nominal_levels())
  cal = _coverage(theta, draws, lv)
  for a in (0.5, 0.9):
    assert abs(cal[a] - a) < _TOL[a], (a, cal, raw)
  if (scale, shift) != (1.0, 0.0):  # the test has something to fix
    assert max(abs(raw[a] - a) for a in (0.5, 0.9)) > 0.1, raw
  else:  # an exact posterior keeps about its own levels
    np.testing.assert_allclose(lv, calibration.PROBS, atol=0.06)
  # The recalibrated median is the exact posterior median: for a shifted
  # posterior its CDF level moves by Phi(-shift) (0.21 at 0.8).
  if shift:
    assert lv[2] == pytest.approx(0.212, abs=0.06)


def test_an_uninformed_quantity_keeps_its_nominal_levels():
  # Where the data say nothing the posterior is the prior (here U(0, 1)) and a
  # truth's rank is the truth itself. A calibration whose truths happened to
  # avoid the ends (as the shipped area weight's did: 93% of them in the
  # central 90% of the range) narrows the conformal levels, and new truths
  # fall outside more often than promised; told that the posterior's
  # intervals are the prior's own width, the levels stay nominal.
  rng = np.random.default_rng(0)
  lucky = np.concatenate([rng.uniform(0.08, 0.96, 93), rng.uniform(0, 1, 7)])
  ranks = np.stack([lucky, rng.uniform(0, 1, 100)], axis=1)
  narrowed = calibration.levels(ranks)[:, 0]
  widths = np.stack([np.full(100, 0.98), np.full(100, 0.3)], axis=1)
  kept = calibration.levels(ranks, width_ratios=widths)
  np.testing.assert_array_equal(kept[:, 0], calibration.PROBS)
  np.testing.assert_array_equal(kept[:, 1], calibration.levels(ranks)[:, 1])
  new = rng.uniform(0, 1, 20000)  # new truths; the posterior's CDF is the identity
  held = lambda lv: np.mean((lv[0] <= new) & (new <= lv[4]))
  assert held(narrowed) < 0.875
  assert held(kept[:, 0]) == pytest.approx(0.9, abs=0.01)
  with pytest.raises(ValueError, match='width ratios'):
    calibration.levels(ranks, width_ratios=widths[:, :1])


def test_width_ratio_by_hand():
  rng = np.random.default_rng(0)
  prior = np.stack([rng.uniform(0, 1, 20000), np.exp(rng.uniform(-2, 2, 20000))], 1)
  post = np.stack(
    [rng.uniform(0.25, 0.75, 20000), np.exp(rng.uniform(-1, 1, 20000))], 1
  )
  # Half the width; on a log scale half as well, on a linear one
  # (e^0.9 - e^-0.9) / (e^1.8 - e^-1.8) = 0.35.
  np.testing.assert_allclose(
    calibration.width_ratio(post, prior, log=[False, True]), [0.5, 0.5], atol=0.02
  )
  assert calibration.width_ratio(post, prior)[1] == pytest.approx(0.349, abs=0.02)


def test_bayes_point_by_hand():
  # Relative error: the median weighted by 1/x. Samples 1 and 3 (equal mass):
  # |c - 1| + |c - 3| / 3 is least at c = 1.
  x = np.array([1.0] * 50 + [3.0] * 50)
  assert calibration.bayes_point(x, 'relative') == pytest.approx(1.0)
  # Factor error on a log-symmetric sample: its geometric centre.
  y = np.exp(np.linspace(-1, 1, 2001))
  assert calibration.bayes_point(y, 'factor') == pytest.approx(1.0, rel=0.01)
  # Absolute log error: the (weighted) median, here 2 (more than half the
  # weight at or below it, more than half at or above), where the percent
  # error's action stays at 1.
  z = np.array([1.0] * 30 + [2.0] * 40 + [4.0] * 30)
  assert calibration.bayes_point(z, 'log') == 2.0
  assert calibration.bayes_point(z, 'relative') == 1.0
  assert calibration.bayes_point(z, 'log', weights=np.r_[[3.0] * 30, [1.0] * 70]) == 1.0
  with pytest.raises(ValueError, match='positive'):
    calibration.bayes_point(np.array([0.0, 1.0]), 'relative')


def _matrix_costs(x, loss: str, n_candidates: int = 199, weights=None):
  """The matrix form ``bayes_point`` replaced: (the candidates, each one's
  expected error over every draw)."""
  w = np.ones_like(x) if weights is None else np.asarray(weights, np.float64)
  order = np.argsort(x)
  cw = np.cumsum(w[order]) / w.sum()
  probs = (np.arange(n_candidates) + 0.5) / n_candidates
  c = x[order][np.minimum(np.searchsorted(cw, probs), x.size - 1)][:, None]
  if loss == 'relative':
    cost = np.abs(c - x) / x @ w
  elif loss == 'log':
    cost = np.abs(np.log(c) - np.log(x)) @ w
  else:
    cost = np.exp(np.abs(np.log(c) - np.log(x))) @ w
  return c[:, 0], cost


@pytest.mark.parametrize('loss', calibration.LOSSES)
def test_bayes_point_is_the_brute_force_argmin(loss):
  # The prefix-sum form picks the candidate the full matrix does, or one whose
  # expected error ties it to round-off, on skewed, weighted and tied samples.
  rng = np.random.default_rng(3)
  for x, w in [
    (rng.lognormal(0.0, 0.8, 4096), None),
    (rng.uniform(0.15, 0.25, 3000), rng.uniform(0.0, 2.0, 3000)),
    (np.round(rng.lognormal(0.0, 1.0, 2000), 1) + 0.1, None),  # many ties
  ]:
    got = calibration.bayes_point(x, loss, weights=w)
    c, cost = _matrix_costs(x, loss, weights=w)
    assert got in c
    assert cost[np.flatnonzero(c == got)[0]] <= cost.min() * (1 + 1e-12)


def test_error_and_shrink_by_hand():
  np.testing.assert_allclose(
    calibration.error([3.0, 1.0], [2.0, 2.0], 'relative'), [50, 50]
  )
  np.testing.assert_allclose(calibration.error(4.0, 1.0, 'factor'), 4.0)
  np.testing.assert_allclose(calibration.error([4.0, 0.25], 1.0, 'log'), np.log(4.0))
  assert calibration.shrink(4.0, 1.0, 0.5, 'log') == pytest.approx(2.0)
  assert calibration.shrink(4.0, 1.0, 0.5, 'factor') == pytest.approx(2.0)  # log-midway
  assert calibration.shrink(4.0, 1.0, 0.5, 'relative') == pytest.approx(2.5)


def test_weights_trust_a_posterior_only_where_it_knows_something():
  rng = np.random.default_rng(0)
  truth = rng.uniform(1.0, 6.0, 500)
  prior_point = np.full(500, 3.0)
  informed = truth * (1 + 0.05 * rng.standard_normal(500))  # 5% error
  blind = rng.uniform(1.0, 6.0, 500)  # scatter that knows nothing of the truth
  assert calibration.choose_weight(informed, prior_point, truth, 'relative') == 1.0
  assert calibration.choose_weight(blind, prior_point, truth, 'relative') == 0.0


@pytest.mark.parametrize('k,n', [(90, 100), (27, 30), (30, 30), (0, 12), (5, 18)])
def test_binomial_interval_matches_scipys_wilson(k, n):
  from scipy import stats

  want = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method='wilson')
  lo, hi = calibration.binomial_interval(k, n)
  np.testing.assert_allclose([lo, hi], [want.low, want.high], atol=1e-3)  # z=1.96
  # By hand at the ends: none of n gives [0, z^2 / (n + z^2)].
  if k == 0:
    np.testing.assert_allclose(hi, 1.96**2 / (n + 1.96**2), rtol=1e-12)
    assert lo == 0.0


def test_binomial_interval_refuses_impossible_counts():
  for k, n in ((3, 0), (-1, 5), (6, 5)):
    with pytest.raises(ValueError, match='0 <= k <= n'):
      calibration.binomial_interval(k, n)


def test_unwarp_inverts_warp():
  levels = np.array([0.01, 0.1, 0.4, 0.9, 0.99])
  u = np.linspace(0, 1, 41)
  np.testing.assert_allclose(
    calibration.unwarp(calibration.warp(u, levels), levels), u, atol=1e-12
  )
  # By hand: a rank at the table's 0.1 level is the recalibrated 25% point;
  # halfway between 0.4 and 0.9 is halfway between 50% and 75%.
  np.testing.assert_allclose(calibration.unwarp([0.1, 0.65], levels), [0.25, 0.625])
