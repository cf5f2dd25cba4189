"""experiments.pipeline.report: summaries and errors against values worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from experiments.pipeline import report

# Percent errors and factors are ratios of a few floats: exact to rounding.
TOL = 1e-9


def test_stats_reads_quantiles_of_the_samples():
  samples = np.arange(101, dtype=np.float64)  # 0..100: quantiles are the percent
  s = report.stats(np.array([42.0]), samples)
  assert s['value'] == 42.0
  assert s['posterior_median'] == 50.0
  assert s['interval_90'] == pytest.approx([5.0, 95.0], abs=TOL)
  assert s['std'] == pytest.approx(np.sqrt((101**2 - 1) / 12), rel=TOL)


def test_errors_by_hand():
  space = physsim.SearchSpace()  # wind 1-6, area weight 0.1-0.37, bending 0.1-10
  truth = {'bending_scale': 2.0, 'wind_speed': 4.0, 'area_weight': 0.2}
  best = physsim.Params(0.5, 5.0, 0.25)
  e = report.errors(best, truth, space)['estimate']
  assert e['wind_speed_pct'] == pytest.approx(25.0, abs=TOL)
  assert e['area_weight_pct'] == pytest.approx(25.0, abs=TOL)
  assert e['bending_factor'] == pytest.approx(4.0, rel=TOL)  # 0.5 vs 2: x4
  # rho v^2 / (w g): (25 / 0.25) / (16 / 0.2) = 100 / 80, 25% high.
  assert e['load_ratio_pct'] == pytest.approx(25.0, rel=TOL)
  centre = report.errors(best, truth, space)['range_centre']
  assert centre['wind_speed_pct'] == pytest.approx(100 * abs(3.5 - 4.0) / 4.0, rel=TOL)
  assert centre['bending_factor'] == pytest.approx(2.0, rel=TOL)  # log centre is 1


def test_mean_error_is_geometric_for_the_bending_factor_only():
  assert report.mean_error([2.0, 8.0], 'bending_factor') == pytest.approx(4.0)
  assert report.mean_error([2.0, 8.0], 'wind_speed_pct') == pytest.approx(5.0)


def test_covered_checks_each_interval_and_the_load_ratio():
  truth = {'bending_scale': 1.0, 'wind_speed': 3.0, 'area_weight': 0.2}
  ratio = float(physsim.load_ratio(3.0, 0.2))
  result = {
    'estimate': {
      'bending_scale': {'interval_90': [0.5, 2.0], 'interval_50': [1.1, 1.5]},
      'wind_speed': {'interval_90': [2.0, 2.9]},
      'area_weight': {'interval_90': [0.2, 0.3]},  # the edge counts as inside
    },
    'load_ratio': {'interval_90': [0.5 * ratio, 2 * ratio]},
  }
  c = report.covered(result, truth)
  assert c['bending_scale'] == {'interval_90': True, 'interval_50': False}
  assert c['wind_speed'] == {'interval_90': False}
  assert c['area_weight'] == {'interval_90': True}
  assert c['load_ratio'] == {'interval_90': True}


@pytest.mark.parametrize(
  'wind_sd, weight_sd, joint, mode',
  [
    (0.0, 0.0, False, 'video'),
    (0.1, 0.0, False, 'known wind'),
    (0.0, 0.01, False, 'known area weight'),
    (0.1, 0.01, False, None),
    (0.0, 0.0, True, 'joint pair'),
    (0.1, 0.0, True, 'joint pair, known winds'),
    (0.0, 0.01, True, None),
  ],
)
def test_calibration_mode(wind_sd, weight_sd, joint, mode):
  class Measured:
    wind_speed_sd = wind_sd
    area_weight_sd = weight_sd

  assert report.calibration_mode(Measured(), joint=joint) == mode


def test_shape_estimates_quote_their_own_calibration():
  class Config:
    calibration = ''
    distance = 'shape'

  assert report.calibration_file(Config()) == report.SHAPE_CALIBRATION_FILE
  Config.distance = 'psd'
  assert report.calibration_file(Config()) == report.CALIBRATION_FILE
  Config.calibration = '/elsewhere/mine.json'
  assert report.calibration_file(Config()) == '/elsewhere/mine.json'


def test_iterations_of_counts_the_initial_design_as_iteration_zero():
  it = report.iterations_of(n_evals=10, n_init=4, q=2)
  assert list(it) == [0, 0, 0, 0, 1, 1, 2, 2, 3, 3]
