"""Tests of experiments.studies.landscape: the pure helpers by hand, one tiny study."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

import physsim
from experiments.pipeline import objective as obj_lib
from experiments.studies import landscape as ls
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  write_hand_made_model,
  write_recording,
)

pytestmark = pytest.mark.slow  # maps the distance landscape by simulation

# The truth's PSD is zero but for the mm quantisation of the recording.
_TRUTH_PSD_TOLERANCE = 1e-3


def test_points_lines_through_the_truth_and_grid():
  config = ls.Config(points_1d=3, grid=2)
  u_truth = np.array([0.25, -0.5, 0.1])
  U, parts = ls.points(config, u_truth)
  assert len(U) == 3 * 4 + 4
  for i in range(3):
    line = U[parts[f'line_{i}']]
    others = np.delete(line, i, axis=1)
    np.testing.assert_array_equal(others, np.tile(np.delete(u_truth, i), (4, 1)))
    np.testing.assert_array_equal(line[:, i], np.sort([-1, 0, 1, u_truth[i]]))
  grid = U[parts['grid']]
  np.testing.assert_array_equal(grid[:, 0], u_truth[0])  # at the true bending
  # wind-major: row = wind index
  np.testing.assert_array_equal(grid[:, 1:], [[-1, -1], [-1, 1], [1, -1], [1, 1]])


def test_ratio_r2_separates_ratio_only_from_wind_dependent_stats():
  v, w = np.meshgrid(np.linspace(1, 6, 5), np.linspace(0.1, 0.37, 5), indexing='ij')
  v, w = v.ravel(), w.ravel()
  r = physsim.load_ratio(v, w)
  only_ratio = ls.ratio_r2(np.log(r) ** 2, v, w)  # a cubic in log ratio fits it
  assert only_ratio['r2_ratio'] == pytest.approx(1.0, abs=1e-9)
  wind = ls.ratio_r2(np.log(v), v, w)  # at a fixed ratio it still varies
  assert wind['r2_ratio'] < 0.99
  assert wind['r2_ratio_and_wind'] == pytest.approx(1.0, abs=1e-9)
  assert np.isnan(ls.ratio_r2(np.ones_like(v), v, w)['r2_ratio'])  # constant


def test_tiny_study_then_resume(tmp_path, monkeypatch):
  root = str(tmp_path)
  model_dir = write_hand_made_model(os.path.join(root, 'model'))
  seq = write_recording(root, TRUTH)
  config = ls.Config(objective=CONFIG, points_1d=2, grid=3, batch=8)
  workdir = os.path.join(root, 'land')
  result = ls.run(config, seq, model_dir, workdir)
  assert result['psd_truth'] < _TRUTH_PSD_TOLERANCE
  for name in ('wind_speed', 'area_weight'):
    line = result['line'][name]
    assert line['argmin'] == pytest.approx(TRUTH[name])
  grid = np.asarray(result['grid']['psd'])
  assert grid.shape == (3, 3) and np.isfinite(grid).all()
  assert result['failed_simulations'] == 0
  ident = result['identifiability']
  assert len(ident['ratio']) == 9 and all(
    np.isfinite(ident['stats'][s]).all() for s in ls.STATS
  )
  for name in ('landscape_1d.png', 'landscape_wind_weight.png', 'identifiability.png'):
    assert os.path.isfile(os.path.join(workdir, name))

  # A rerun simulates nothing and gives the same landscape.
  calls = []
  real = obj_lib.Objective.__call__
  monkeypatch.setattr(
    obj_lib.Objective, '__call__', lambda *a, **kw: calls.append(1) or real(*a, **kw)
  )
  again = ls.run(config, seq, model_dir, workdir)
  assert not calls
  assert again['grid'] == result['grid'] and again['line'] == result['line']
  other = dataclasses.replace(config, grid=2)
  with pytest.raises(ValueError, match='another study'):
    ls.run(other, seq, model_dir, workdir)


def test_the_shape_distance_maps_without_a_network(tmp_path):
  # --distance=shape and no --model: the discrepancy mapped is where the sheet
  # hangs (m^2), zero at the truth but for the recording's mm quantisation.
  from tests.experiments.estimate_fixtures import SIZE

  seq = write_recording(str(tmp_path), TRUTH)
  shape = CONFIG.replace(distance='shape')
  config = ls.Config(objective=shape, points_1d=2, grid=2, batch=8)
  result = ls.run(config, seq, '', str(tmp_path / 'land'), image_size=SIZE)
  assert result['model'] == ''
  assert result['psd_truth'] < _TRUTH_PSD_TOLERANCE
  line = result['line']['wind_speed']
  assert line['argmin'] == pytest.approx(TRUTH['wind_speed'])
  assert max(line['psd']) > 10 * result['psd_truth']  # the ends of the range are far
  with pytest.raises(ValueError, match='missing --model'):
    ls.run(ls.Config(objective=CONFIG), seq, '', str(tmp_path / 'no'))
