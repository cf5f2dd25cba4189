"""experiments.pipeline.layout: an estimate's draws read back as written, and
every corrupt or incomplete file refused naming it (issue 78: export and plan
crashed with BadZipFile and KeyError on them)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import physsim
from experiments.pipeline import layout


def _write(workdir, samples=None, bounds=None, material='gray_interlock', **extra):
  space = physsim.search_space('gray_interlock')
  rng = np.random.default_rng(0)
  samples = rng.uniform(-1, 1, (50, 3)) if samples is None else samples
  bounds = space.bounds() if bounds is None else bounds
  np.savez(
    os.path.join(workdir, layout.POSTERIOR_FILE), samples=samples, bounds=bounds,
    **extra,
  )  # fmt: skip
  with open(os.path.join(workdir, layout.ESTIMATE_FILE), 'w') as f:
    json.dump({'material': material}, f)
  return space, samples


def test_draws_are_the_log_physical_values_of_the_unit_samples(tmp_path):
  space, u = _write(tmp_path)
  material, draws, weights = layout.read_draws(str(tmp_path))
  p = physsim.params.from_unit(u, space)  # the independent map, float64
  assert material == 'gray_interlock' and weights.tolist() == [1.0] * 50
  np.testing.assert_allclose(draws[:, 0], np.log(p.bending_scale), rtol=1e-12)
  np.testing.assert_allclose(draws[:, 1], np.log(p.area_weight), rtol=1e-12)


def test_a_joint_workdir_gives_its_shared_draws(tmp_path):
  space = physsim.search_space('gray_interlock')
  u = np.zeros((7, 3))
  np.savez(tmp_path / layout.JOINT_POSTERIOR_FILE, samples=u, bounds=space.bounds())
  (tmp_path / layout.JOINT_FILE).write_text(json.dumps({'material': 'black_denim'}))
  material, draws, _ = layout.read_draws(str(tmp_path))
  assert material == 'black_denim' and draws.shape == (7, 2)


@pytest.mark.parametrize(
  'corrupt, says',
  [
    (lambda d: (d / layout.POSTERIOR_FILE).write_bytes(b'PK\x03\x04 cut'), 'not a readable .npz'),
    (lambda d: np.savez(d / layout.POSTERIOR_FILE, samples=np.zeros((4, 3))), "no ['bounds']"),
    (lambda d: _write(d, samples=np.zeros((4, 2))), 'need (S, 3) draws'),
    (lambda d: _write(d, samples=np.full((4, 3), np.nan)), 'not finite'),
    (lambda d: _write(d, samples=np.zeros((0, 3))), 'or none'),
    (lambda d: _write(d, bounds=-np.ones((3, 2))), 'not positive'),
    (lambda d: _write(d, bounds=np.ones((3, 2))), 'is empty'),
    (lambda d: _write(d, samples=np.array([['a'] * 3] * 4)), 'floating point'),
    (lambda d: _write(d, material='fabrik'), 'no known fabric'),
  ],
)  # fmt: skip
def test_a_corrupt_or_incomplete_file_is_refused_naming_it(tmp_path, corrupt, says):
  corrupt(tmp_path)
  with pytest.raises(ValueError) as e:
    layout.read_draws(str(tmp_path))
  assert says in str(e.value) and str(tmp_path) in str(e.value)
  assert len(str(e.value)) <= 300


def test_a_corrupt_estimate_json_is_named(tmp_path):
  _write(tmp_path)
  (tmp_path / layout.ESTIMATE_FILE).write_text('{"material": ')
  with pytest.raises(ValueError, match='estimate.json: not a readable JSON file'):
    layout.read_draws(str(tmp_path))


def test_no_draws_says_where_they_were_looked_for(tmp_path):
  with pytest.raises(ValueError, match='no posterior draws'):
    layout.read_draws(str(tmp_path))
