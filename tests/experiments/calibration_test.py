"""The calibration study's analysis against a likelihood that is exact.

Synthetic saved posteriors stand in for estimates: each recording's "GP" of log
discrepancy is ``m + log(1 + a |u - u_obs|^2)`` on the grid, ``u_obs`` the
truth (unit cube) plus Gaussian noise of sd ``S``. The Gibbs likelihood
``-c (exp(f - m) - 1) / sn`` is then ``N(u_obs, S^2)`` exactly at
``c = C_TRUE``, so with truths drawn from the prior its intervals must hold the
truth as often as they say there and too rarely when sharper; the study's
choice must not be the sharper one.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import bo
import physsim
from experiments.pipeline import report, search
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import calibration

S = 0.3  # observation noise, unit-cube coordinates
SN, C_TRUE = 0.5, 1.0
A = SN / (2 * S**2 * C_TRUE)  # makes c = C_TRUE exact
GRID = (20, 20, 20)


def _fake_runs(config: calibration.Config, root: str) -> list[dict]:
  space = physsim.search_space(config.material)
  truths = calibration.truths(config)
  units = physsim.to_unit(truths, space)
  rng = np.random.default_rng(1)
  points = bo.posterior.grid_points(GRID)
  runs = []
  for seq, u in enumerate(units):
    obs = u + S * rng.standard_normal(3)
    mean = -2.0 + np.log1p(A * np.sum((points - obs) ** 2, -1))
    wd = os.path.join(root, f'{seq:04d}')
    os.makedirs(wd)
    np.savez(os.path.join(wd, search.POSTERIOR_FILE), gp_mean=mean,
             gp_var=np.zeros_like(mean), floor=mean.min(), noise_sd=SN)  # fmt: skip
    truth = {
      f: float(np.ravel(getattr(truths, f))[seq]) for f in physsim.Params._fields
    }
    runs.append({'seq': seq, 'truth': truth, 'workdir': wd})
  return runs


@pytest.mark.slow
def test_analysis_recovers_the_exact_likelihoods_calibration(tmp_path):
  config = calibration.Config(
    pairs=100, sharpness_grid=(0.25, C_TRUE, 4.0),
    estimate=EstimateConfig(posterior_grid=GRID),
  )  # fmt: skip
  analysis = calibration.analyse(config, _fake_runs(config, str(tmp_path)))
  gibbs = analysis['sweep']['gibbs']
  held = {c: gibbs[c]['held_out']['video'] for c in config.sharpness_grid}
  assert held[C_TRUE]['n'] == 100
  for f in physsim.Params._fields:  # 100 held out: binomial sd 0.03 at 90%, 0.05 at 50%
    assert abs(held[C_TRUE][f]['interval_90'] - 0.9) < 0.09, f
    assert abs(held[C_TRUE][f]['interval_50'] - 0.5) < 0.15, f
    assert held[4.0][f]['interval_90'] < 0.8, f  # sharper: too narrow
  # Flatter tends to the prior, itself calibrated over prior draws: the 50%
  # intervals hold the truth too often, the 90% ones hardly change.
  assert np.mean([held[0.25][f]['interval_50'] for f in physsim.Params._fields]) > 0.57
  assert analysis['best_sharpness']['gibbs'] in (0.25, C_TRUE)
  # A measured wind (2%) narrows the wind's intervals and keeps them honest.
  known = gibbs[C_TRUE]['held_out']['known wind']['wind_speed']
  assert abs(known['interval_90'] - 0.9) < 0.09
  assert known['median_error_pct'] < held[C_TRUE]['wind_speed']['median_error_pct']


def test_an_estimate_quotes_coverage_only_for_the_calibrated_settings(
  tmp_path, monkeypatch
):
  cal = {
    'n': 50, 'setting': 'gibbs likelihood, sharpness 0.7, demo-size', 'likelihood': 'gibbs',
    'sharpness': 0.7, 'coverage': {'wind_speed': {'interval_50': 0.48, 'interval_90': 0.88}},
  }  # fmt: skip
  path = tmp_path / 'calibration.json'
  path.write_text(json.dumps(cal))
  monkeypatch.setattr(report, 'CALIBRATION_FILE', str(path))
  same = report.calibration_note(EstimateConfig(sharpness=0.7))
  assert 'wind 88%/48%' in report.calibration_line(same)
  other = report.calibration_note(EstimateConfig(sharpness=1.4))
  assert other['matches'] is False
  assert 'not for this sharpness' in report.calibration_line(other)
  other = report.calibration_note(EstimateConfig(sharpness=0.7, likelihood='threshold'))
  assert other['matches'] is False
  assert other['differs'] == ['likelihood']
  # A setting that changes what a score means (the mesh) also voids the quote.
  cal['config'] = {'estimate': {'cloth_resolution': 25, 'frames': 60}}
  path.write_text(json.dumps(cal))
  assert report.calibration_note(EstimateConfig(sharpness=0.7))['matches'] is True
  other = report.calibration_note(EstimateConfig(sharpness=0.7, cloth_resolution=10))
  assert other['differs'] == ['cloth_resolution']
  monkeypatch.setattr(report, 'CALIBRATION_FILE', str(tmp_path / 'none.json'))
  assert 'not measured' in report.calibration_line(report.calibration_note())
