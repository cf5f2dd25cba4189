"""Tests for benchmarks/mesh_convergence.py: the interpolation by hand, a tiny run
that resumes, and experiments.files.resume."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

from benchmarks import mesh_convergence as mc
from experiments import files

_EXACT = 1e-12


def test_equivalent_wind_by_hand():
  winds = [1.0, 2.0, 3.0, 4.0]
  d = [0.10, 0.30, 0.40, 0.405]  # rising, then blown flat
  assert mc.equivalent_wind(winds, d, 0.20) == pytest.approx(1.5, abs=_EXACT)
  assert mc.equivalent_wind(winds, d, 0.35) == pytest.approx(2.5, abs=_EXACT)
  assert mc.equivalent_wind(winds, d, 0.10) == pytest.approx(1.0, abs=_EXACT)
  # 0.005 m per m/s between 3 and 4 m/s: flat, no wind information
  assert np.isnan(mc.equivalent_wind(winds, d, 0.402))
  assert np.isnan(mc.equivalent_wind(winds, d, 0.05))  # below the sweep
  assert np.isnan(mc.equivalent_wind(winds, d, 0.50))  # above it
  # past the first flat segment a later rise names no wind either
  assert np.isnan(mc.equivalent_wind(winds, [0.1, 0.3, 0.305, 0.35], 0.33))


def test_tiny_run_compares_meshes_and_resumes(tmp_path, monkeypatch):
  config = dataclasses.replace(mc.PRESETS['smoke'], backend='c')
  workdir = str(tmp_path)
  rows = mc.run(config, workdir)
  assert len(rows) == len(config.resolutions) * len(config.fabrics) * len(config.winds)
  assert all(r['valid'] for r in rows)
  for r in rows:
    if r['resolution'] == config.estimate_resolution:
      # its own deflection maps back to its own wind, where the curve rises
      eq = r['equivalent_wind']
      assert np.isnan(eq) or eq == pytest.approx(r['wind_speed'], abs=1e-9)
  assert os.path.isfile(os.path.join(workdir, 'mesh_convergence.png'))

  def no_simulation(*args):
    raise AssertionError('resumed run simulated again')

  monkeypatch.setattr(mc, 'simulate_resolution', no_simulation)
  assert mc.run(config, workdir) == rows
  with pytest.raises(AssertionError, match='simulated again'):
    mc.run(dataclasses.replace(config, seed=1), workdir)  # another config: reruns


def test_resume_reads_only_the_same_config(tmp_path):
  path = str(tmp_path / 'state.json')
  config = mc.PRESETS['smoke']
  assert files.resume(path, config) == {}
  files.write_json(
    path, {'config': dataclasses.asdict(config), 'resolutions': {'6': 1}}
  )
  assert files.resume(path, config)['resolutions'] == {'6': 1}  # lists vs tuples
  assert files.resume(path, dataclasses.replace(config, seed=3)) == {}
  files.write_json(path, {'config': {'unknown_field': 1}})
  assert files.resume(path, config) == {}
