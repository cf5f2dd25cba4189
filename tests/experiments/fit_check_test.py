"""The fit check (issue 76): the gust floor against the distance to the
recording, and a reading the video alone disagrees with, each on cases whose
answer is known by construction."""

from __future__ import annotations

import numpy as np
import pytest

import bo
import physsim
from experiments.pipeline import fit_check, measurements, objective, table_notes


def _simulate_around(recording, sd, seed=0):
  """A stand-in for ``simulate``: k sheets whose mean shape scatters by
  ``sd`` (m, per axis) about the origin, against a recording at ``recording``."""

  def simulate(u):
    rng = np.random.default_rng(seed)
    s = rng.normal(0.0, sd, (len(u), 2))
    residual = (s - np.asarray(recording))[None]
    psd = np.sum(residual**2, axis=-1)
    return objective.Scores(psd[0], np.ones(len(u), bool), None, None, residual[0])

  return simulate


def test_a_recording_that_is_one_more_gust_draw_fits():
  # the recording drawn like the simulations: the ratio's expectation is 1
  ratios = []
  for seed in range(200):
    rec = np.random.default_rng(1000 + seed).normal(0.0, 0.01, 2)
    p = fit_check.predictive(_simulate_around(rec, 0.01, seed)(np.zeros((8, 3))))
    ratios.append(p['ratio'])
  assert np.mean(ratios) == pytest.approx(1.0, abs=0.15)
  assert np.mean(np.array(ratios) <= fit_check.MISFIT_RATIO) > 0.95


def test_a_recording_far_beyond_the_gusts_is_flagged_with_its_ratio_by_hand():
  rec = np.array([0.05, 0.0])  # 5 sd off along y
  p = fit_check.predictive(_simulate_around(rec, 0.01)(np.zeros((8, 3))))
  s = np.random.default_rng(0).normal(0.0, 0.01, (8, 2))
  fit = np.mean(np.sum((s - rec) ** 2, axis=1))
  i, j = np.triu_indices(8, 1)
  floor = np.mean(np.sum((s[i] - s[j]) ** 2, axis=1))
  assert p['ratio'] == pytest.approx(fit / floor, rel=1e-12) and not p['fits']
  line = table_notes.fit_line({'predictive': p, 'conflicts': []}, {})
  assert 'FARTHER than the gusts allow' in line


def _peaked_log_lik(grid, space, wind):
  """A log likelihood on the grid that reads the wind at ``wind`` m/s
  (sd 0.1 m/s), flat in bending and area weight."""
  v = np.ravel(
    physsim.params.from_unit(bo.posterior.grid_points(grid), space).wind_speed
  )
  return -0.5 * ((v - wind) / 0.1) ** 2


def test_a_wind_reading_the_video_disagrees_with_is_named():
  space, grid = physsim.search_space('gray_interlock'), (4, 64, 4)
  log_lik = _peaked_log_lik(grid, space, 3.0)
  far = measurements.Measured(wind_speed=4.2, wind_speed_sd=0.08)
  (c,) = fit_check.conflicts(log_lik, grid, space, far)
  assert c['reading'] == 'wind_speed' and c['video'][0] < 3.0 < c['video'][1]
  assert c['video'][1] < 4.2 - 2 * 0.08
  line = table_notes.fit_line({'conflicts': [c]}, far.to_dict())
  assert 'the video disagrees with the wind reading' in line
  assert '--air_coefficient=free' in line
  near = measurements.Measured(wind_speed=3.05, wind_speed_sd=0.06)
  assert fit_check.conflicts(log_lik, grid, space, near) == []
  # with the air free the reading is of the true wind: the video cannot say
  free = measurements.Measured(4.2, 0.08, air_coefficient='free')
  assert fit_check.conflicts(log_lik, grid, space, free) == []
