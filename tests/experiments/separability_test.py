"""Tests for experiments.separability: the Cramer-Rao bound against the value
worked out by hand for a linear model, the ratio-only case, and a tiny run that
resumes."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

from experiments.studies import separability as sep

pytestmark = pytest.mark.slow  # the separability study end to end

# Sampling error of a covariance and of fitted slopes from 3,600 noisy worlds.
_SAMPLED = 0.1


def _linear_worlds(J, noise_sd, seeds=400, seed=0):
  """Statistics y = J @ (log v, log w) + Gaussian noise at a 3x3 grid."""
  rng = np.random.default_rng(seed)
  lv, lw = np.meshgrid(np.log([1.0, 2.0, 4.0]), np.log([0.1, 0.15, 0.2]))
  lv, lw = np.repeat(lv.ravel(), seeds), np.repeat(lw.ravel(), seeds)
  point = np.repeat(np.arange(9), seeds)
  Y = np.stack([lv, lw], 1) @ np.asarray(J).T
  Y = Y + rng.standard_normal(Y.shape) * np.asarray(noise_sd)
  return lv, lw, point, Y


def test_fisher_bounds_match_the_linear_model_by_hand():
  J = np.array([[2.0, -1.0], [0.5, 1.0], [1.0, 0.0]])  # three statistics
  sd = np.array([0.1, 0.2, 0.05])
  b = sep.fisher_bounds(*_linear_worlds(J, sd))
  # I = J^T S^-1 J, S = diag(sd^2); the bounds are sqrt(diag(I^-1)) and
  # sqrt(a^T I^-1 a) for log ratio = 2 log v - log w
  cov = np.linalg.inv(J.T @ np.diag(sd**-2) @ J)
  a = np.array([2.0, -1.0])
  want = np.sqrt([cov[0, 0], cov[1, 1], a @ cov @ a])
  np.testing.assert_allclose(b['sigma'], np.tile(want, (9, 1)), rtol=_SAMPLED)
  np.testing.assert_allclose(np.sqrt(np.diag(b['noise_cov'])), sd, rtol=_SAMPLED)
  assert np.all(b['fit_r2'] > 0.99)


def test_statistics_of_the_load_ratio_alone_bound_it_but_not_wind_or_weight():
  # both statistics see only 2 log v - log w: the ratio, never the two apart
  J = np.array([[2.0, -1.0], [-4.0, 2.0]])
  b = sep.fisher_bounds(*_linear_worlds(J, [0.1, 0.1]))
  s = np.median(b['sigma'], axis=0)
  assert s[2] < 0.1  # the ratio: about 0.045 from two statistics of noise 0.1
  assert s[1] > 10 * s[2] and s[0] > 5 * s[2]


def test_a_prior_on_area_weight_passes_half_its_spread_to_the_wind():
  # One statistic of the log ratio (noise s) and a prior of sd p on log w, flat
  # on log v: log v = (log r + log w) / 2, so var(log v) = (s^2 + p^2) / 4, while
  # log w keeps its prior's sd and the ratio its own noise.
  s, p = 0.1, 0.2
  b = sep.fisher_bounds(*_linear_worlds([[2.0, -1.0]], [s]), prior_sd=[np.inf, p])
  want = [np.sqrt(s**2 + p**2) / 2, p, s]
  np.testing.assert_allclose(np.median(b['sigma'], axis=0), want, rtol=_SAMPLED)


def test_too_few_seeds_is_refused():
  lv, lw, point, Y = _linear_worlds(np.eye(2), [0.1, 0.1], seeds=1)
  with pytest.raises(ValueError, match='more seeds or points'):
    sep.fisher_bounds(lv, lw, point, Y)


def test_tiny_run_sees_the_ratio_in_the_deflection_and_resumes(tmp_path, monkeypatch):
  config = dataclasses.replace(sep.PRESETS['smoke'], backend='c')
  workdir = str(tmp_path)
  result = sep.run(config, workdir)
  a = result['analysis']['red_violet']
  assert a['worlds'] == len(config.winds) * config.weights * len(config.seeds)
  assert a['used'] >= a['worlds'] - 2  # a still sheet's slowness may be NaN
  # the sheet's mean shape is a function of rho v^2 / (w g) (well above the rest)
  assert a['r2']['mean_deflection_m']['r2_base'] > 0.9
  b, box = a['bounds'], a['bounds_with_box']
  assert 0 < b['load_ratio_pct'] < b['area_weight_pct']
  # adding a prior's information narrows the bound below both the statistics' and its own
  assert box['area_weight_pct'] <= min(
    b['area_weight_pct'], a['box_sd']['area_weight_pct']
  )
  for name in ('separability.md', 'separability_stats.png', 'separability_bounds.png'):
    assert os.path.isfile(os.path.join(workdir, name))

  def no_simulation(*args):
    raise AssertionError('resumed run simulated again')

  monkeypatch.setattr(sep, 'simulate_fabric', no_simulation)
  assert sep.run(config, workdir)['analysis'] == result['analysis']


def test_tiny_bending_run_sweeps_bending_at_the_mean_area_weight(tmp_path):
  config = dataclasses.replace(sep.PRESETS['smoke_bending'], backend='c')
  a = sep.run(config, str(tmp_path))['analysis']['red_violet']
  assert a['varied'] == 'bending_scale'
  assert a['used'] >= a['worlds'] - 2
  # bending's range alone: log-uniform over 0.1-10, sd ln(100) / sqrt(12)
  assert a['box_sd']['bending_factor'] == pytest.approx(np.exp(np.log(100) / 12**0.5))
  assert 1 < a['bounds_with_box']['bending_factor'] <= a['box_sd']['bending_factor']
  rows = sep.run(config, str(tmp_path))['fabrics']['red_violet']['rows']
  assert {r['bending_scale'] for r in rows} == set(config.bendings)
  (weight,) = {r['area_weight'] for r in rows}
  assert weight == pytest.approx(0.135)  # (0.10 + 0.17) / 2
  assert os.path.isfile(str(tmp_path / 'separability_bending_bounds.png'))


def test_an_unknown_second_parameter_is_refused(tmp_path):
  with pytest.raises(ValueError, match="vary='fps'"):
    sep.run(dataclasses.replace(sep.PRESETS['smoke'], vary='fps'), str(tmp_path))
