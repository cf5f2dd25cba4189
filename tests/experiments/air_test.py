"""The fabric's air coefficient c (issue 76): the effective wind's law given a
reading, c drawn given the effective wind, and c shared by a joint of
recordings, each against a float64 quadrature written here by hand."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import physsim
from experiments.pipeline import measurements, posterior

READ_SD = 0.02  # a 2% anemometer


def _by_hand_posterior_of_c(v_effs, readings, sds, lik_sd, c):
  """p(c | recordings) on nodes ``c``, by quadrature: each recording's
  likelihood of its effective wind is N(v_eff; v_effs[k], lik_sd[k]); its
  wind reading r_k +- sd_k is of the true wind v = v_eff / sqrt(c); c
  log-uniform (equal weight per node of a log grid)."""
  v = np.linspace(0.05, 12.0, 24001)
  dv = v[1] - v[0]
  logp = np.zeros(len(c))
  for ve, r, sd, s in zip(v_effs, readings, sds, lik_sd, strict=True):
    lik = np.exp(-0.5 * ((v - ve) / s) ** 2)
    for i, ci in enumerate(c):
      q = np.exp(-0.5 * ((v / np.sqrt(ci) - r) / sd) ** 2) / (sd * np.sqrt(ci))
      logp[i] += np.log(np.sum(lik * q) * dv)
  p = np.exp(logp - logp.max())
  return p / p.sum()


def test_the_effective_winds_law_is_normalised_and_stretched_by_sqrt_c():
  v = np.linspace(0.0, 10.0, 20001)
  for c in (0.4, 1.0, 1.3):
    dens = np.exp(measurements.effective_wind_log_density(v, 3.0, 0.06, c))
    assert np.sum(dens) * (v[1] - v[0]) == pytest.approx(1.0, abs=1e-6)
    assert v[np.argmax(dens)] == pytest.approx(3.0 * np.sqrt(c), abs=1e-3)


def test_c_given_the_effective_wind_follows_bayes_rule_by_hand():
  # a reading of 3 m/s; the video's effective wind 3 sqrt(0.6): c near 0.6
  v_eff = np.full(20000, 3.0 * np.sqrt(0.6))
  draws = measurements.air_given_wind(v_eff, 3.0, 3.0 * READ_SD, seed=0)
  c = np.exp(np.linspace(*np.log(measurements.AIR_RANGE), 4001))
  w = np.exp(-0.5 * ((v_eff[0] / np.sqrt(c) - 3.0) / (3.0 * READ_SD)) ** 2)
  w = w / np.sqrt(c)  # p(v_eff | c) has 1/sqrt(c); the log-uniform prior cancels dc/c
  cdf = np.cumsum(w) / w.sum()
  for q in (0.05, 0.5, 0.95):
    assert np.quantile(draws, q) == pytest.approx(c[np.searchsorted(cdf, q)], rel=0.01)


def test_without_a_reading_c_stays_the_prior():
  m = measurements.Measured(air_coefficient='free')
  draws = measurements.air_draws(np.full(40000, 2.0), m, seed=1)
  lo, hi = measurements.AIR_RANGE
  assert draws.min() >= lo and draws.max() <= hi
  # log-uniform: log c uniform, its median at the geometric centre
  assert np.median(draws) == pytest.approx(np.sqrt(lo * hi), rel=0.02)


def test_a_joint_reads_one_c_from_three_fan_settings_as_quadrature_does():
  """Three recordings of one fabric (c = 0.5) at 1.5, 2.5 and 3.5 m/s, each
  read by a 2% anemometer; the video of each says where its effective wind
  lies within 3%. The joint's draws of c match the quadrature's quantiles,
  and each recording's wind, v_eff / sqrt(c), its true wind."""
  c_true, winds = 0.5, np.array([1.5, 2.5, 3.5])
  v_effs = winds * np.sqrt(c_true)
  lik_sd = 0.03 * v_effs
  grid = (2, 400, 2)
  nodes = 0.2 + (5.0 - 0.2) * (np.arange(grid[1]) + 0.5) / grid[1]  # cell centres
  log_liks = [
    np.broadcast_to(-0.5 * ((nodes - ve) / s) ** 2, (2, 2, grid[1]))
    .transpose(0, 2, 1)
    .ravel()
    for ve, s in zip(v_effs, lik_sd, strict=True)
  ]
  flat_prior = np.zeros(np.prod(grid))
  readings = [(float(w), READ_SD * float(w)) for w in winds]
  out = posterior.joint(
    log_liks, grid, flat_prior, jax.random.key(0), n=20000, air=(readings, nodes)
  )
  c = np.exp(np.linspace(np.log(0.3), np.log(1.5), 801))
  p = _by_hand_posterior_of_c(v_effs, winds, READ_SD * winds, lik_sd, c)
  cdf = np.cumsum(p)
  for q in (0.05, 0.5, 0.95):
    want = c[np.searchsorted(cdf, q)]
    assert np.quantile(out['air'], q) == pytest.approx(want, rel=0.03), q
  assert np.median(out['air']) == pytest.approx(c_true, rel=0.05)
  for k, w in enumerate(winds):  # each recording's true wind from its draws
    v_eff = 0.2 + (5.0 - 0.2) * (out['samples'][k][:, 1] + 1.0) / 2.0
    assert np.median(v_eff / np.sqrt(out['air'])) == pytest.approx(w, rel=0.03)


def _three_fan_settings(c_true=0.5):
  winds = np.array([1.5, 2.5, 3.5])
  v_effs = winds * np.sqrt(c_true)
  grid = (2, 400, 2)
  nodes = 0.2 + (5.0 - 0.2) * (np.arange(grid[1]) + 0.5) / grid[1]
  log_liks = [
    np.broadcast_to(-0.5 * ((nodes - ve) / (0.03 * ve)) ** 2, (2, 2, grid[1]))
    .transpose(0, 2, 1)
    .ravel()
    for ve in v_effs
  ]
  readings = [(float(w), READ_SD * float(w)) for w in winds]
  return log_liks, grid, np.zeros(np.prod(grid)), (readings, nodes)


def test_the_shared_discrepancy_widens_c_but_not_the_anemometers_wind():
  """The discrepancy is an error of the simulator's push: the fabric's c
  spreads by it, while each true wind, v_eff / sqrt of the c the push was
  read with, stays as narrow as without it (the readings pin it); summarise
  reads the wind so."""
  log_liks, grid, prior, air = _three_fan_settings()
  space = physsim.search_space('gray_interlock')
  kw = dict(n=20000, air=air, area_weight_range=(0.1, 0.3))
  plain = posterior.joint(log_liks, grid, prior, jax.random.key(0), **kw)
  shared = posterior.joint(
    log_liks, grid, prior, jax.random.key(0), shared_bias_sd=0.3, **kw
  )
  width = lambda x: np.subtract(*np.quantile(np.log(x), [0.95, 0.05]))  # noqa: E731
  assert width(shared['air']) > 1.5 * width(plain['air'])
  np.testing.assert_array_equal(shared['air_simulated'], plain['air_simulated'])
  nodes = air[1]
  for k in range(3):
    v_eff = 0.2 + (5.0 - 0.2) * (shared['samples'][k][:, 1] + 1.0) / 2.0
    v = v_eff / np.sqrt(shared['air_simulated'])
    v0 = v_eff / np.sqrt(plain['air'])
    assert width(v) == pytest.approx(width(v0), rel=0.15)
    assert width(v) < 0.5 * width(v_eff / np.sqrt(shared['air']))
  # summarise on a box whose wind cells are those nodes: the wind's interval
  # is the narrow one with air_simulated, the discrepancy's without
  box = dataclasses.replace(space, wind_speed=(float(nodes[0]), float(nodes[-1])))
  s_in = lambda **a: posterior.summarise(  # noqa: E731
    shared['samples'][0], box, shared['samples'][0],
    air=(shared['air'], shared['air']), **a,
  )['wind_speed']['interval_90']  # fmt: skip
  narrow, wide = s_in(air_simulated=shared['air_simulated']), s_in()
  assert np.log(narrow[1] / narrow[0]) < 0.5 * np.log(wide[1] / wide[0])


def test_a_free_air_coefficient_leaves_the_calibrated_files_as_they_were():
  assert 'air_coefficient' not in measurements.Measured().to_dict()
  free = measurements.Measured(3.0, 0.06, air_coefficient='free').to_dict()
  assert free['air_coefficient'] == 'free'
  with pytest.raises(ValueError, match='--air_coefficient'):
    measurements.Measured(air_coefficient='loose').check(None)


def _coarse_flat_video(readings):
  """A search's coarse wind grid (32 cells over 1-6 m/s, 4-10% wide against
  2% readings) and videos that say nothing about the wind."""
  grid = (2, 32, 2)
  nodes = 1.0 + 5.0 * (np.arange(grid[1]) + 0.5) / grid[1]
  log_liks = [np.zeros(np.prod(grid)) for _ in readings]
  return log_liks, grid, np.zeros(np.prod(grid)), (readings, nodes)


def test_a_joints_true_wind_is_its_reading_where_the_video_is_silent():
  """With the video silent on the wind and c free, each true wind's
  posterior is its anemometer's Gaussian: the draws' quantiles match it to
  1% of its sd, though the grid's cells are 2-5x as wide as that sd (a
  uniform position within them widened the 50% interval by half)."""
  winds = np.array([1.5, 2.5, 3.5])
  readings = [(float(w), READ_SD * float(w)) for w in winds]
  log_liks, grid, prior, air = _coarse_flat_video(readings)
  out = posterior.joint(log_liks, grid, prior, jax.random.key(3), n=40000, air=air)
  z = np.array([-1.645, -0.674, 0.0, 0.674, 1.645])  # N(0, 1) at 5-95%
  for k, (r, sd) in enumerate(readings):
    v_eff = 1.0 + 5.0 * (out['samples'][k][:, 1] + 1.0) / 2.0
    v = v_eff / np.sqrt(out['air_simulated'])
    got = np.quantile(v, [0.05, 0.25, 0.5, 0.75, 0.95])
    np.testing.assert_allclose((got - r) / sd, z, atol=0.04)


def test_a_cells_reading_mass_and_draws_against_a_float64_quadrature():
  """``effective_wind_log_mass`` against the midpoint rule of the
  reading's density over the cell's span, far cells included; the draws of
  ``true_wind_in_cell`` stay in their span with its CDF."""
  reading, sd, c = 2.0, 0.04, 0.6
  lo = np.array([1.40, 1.52, 1.60, 1.70, 1.90])  # effective winds, m/s
  hi = lo + 0.08
  got = measurements.effective_wind_log_mass(lo, hi, reading, sd, c)
  for a, b, g in zip(lo, hi, got, strict=True):
    edges = np.linspace(a / np.sqrt(c), b / np.sqrt(c), 20001)
    v = 0.5 * (edges[1:] + edges[:-1])  # the midpoint rule
    dens = np.exp(-0.5 * ((v - reading) / sd) ** 2) / (sd * np.sqrt(2 * np.pi))
    want = np.log(np.sum(dens * np.diff(edges)))
    assert g == pytest.approx(want, abs=1e-6 + 1e-6 * abs(want))
  u = np.random.default_rng(0).random(20000)
  cell = np.full(20000, 1.52), np.full(20000, 1.60)
  v = measurements.true_wind_in_cell(*cell, reading, sd, c, u)
  span = cell[0][0] / np.sqrt(c), cell[1][0] / np.sqrt(c)
  assert span[0] <= v.min() and v.max() <= span[1]
  grid = np.linspace(*span, 4001)
  dens = np.exp(-0.5 * ((grid - reading) / sd) ** 2)
  cdf = np.cumsum(dens) / dens.sum()
  for q in (0.1, 0.5, 0.9):
    assert np.quantile(v, q) == pytest.approx(grid[np.searchsorted(cdf, q)], abs=2e-3)
