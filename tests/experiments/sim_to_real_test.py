"""Tests for benchmarks/sim_to_real.py's recording variants (its run is a benchmark)."""

from __future__ import annotations

import dataclasses

import numpy as np

from benchmarks import sim_to_real
from experiments.pipeline import demo


def _changed(a, b) -> set[str]:
  return {
    f.name for f in dataclasses.fields(a) if getattr(a, f.name) != getattr(b, f.name)
  }


def test_each_variant_adds_one_difference_to_the_training_like_recording():
  train_cfg, rec_cfg, _, _ = demo.configs('gray_interlock', 8, 0, 'c')
  v = sim_to_real.variants(train_cfg, rec_cfg)
  base = v['training-like']
  # Training-like: the training data's simulation, frames and poses, the
  # recording's seed (so every variant has the same truth and gusts).
  for name in ('cloth_resolution', 'fps', 'frames', 'timestep', 'gust_intensity'):
    assert getattr(base, name) == getattr(train_cfg, name), name
  assert (base.noise, base.poses, base.seed) == (False, 'train', rec_cfg.seed)
  assert v['all (the demo recording)'] == rec_cfg
  expected = {
    'gusts': {'gust_intensity'},
    'finer mesh': {'cloth_resolution'},
    '24 fps': {'fps', 'frames', 'timestep'},
    'sensor model': {'noise'},
    'unseen poses': {'poses'},
  }
  for name, fields in expected.items():
    assert _changed(v[name], base) == fields, name
    for f in fields:
      assert getattr(v[name], f) == getattr(rec_cfg, f), (name, f)


def test_wind_line_passes_through_the_truth_and_holds_the_others():
  u = np.array([0.3, -0.55, 0.1])
  line = sim_to_real.wind_line(u, 5)
  assert line.shape == (6, 3)
  np.testing.assert_array_equal(line[:, [0, 2]], np.tile(u[[0, 2]], (6, 1)))
  assert np.all(np.diff(line[:, 1]) > 0) and -0.55 in line[:, 1]
  assert line[0, 1] == -1.0 and line[-1, 1] == 1.0
