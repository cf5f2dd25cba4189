"""Tests for benchmarks/mesh_convergence.py: the interpolation by hand, a tiny run
that resumes, and experiments.files.resume."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

from benchmarks import mesh_convergence as mc
from experiments.pipeline import files

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


def test_spread_between_meshes_and_seeds_by_hand():
  def row(res, seed, deflection):
    stats = dict.fromkeys(mc.STATS, 0.0) | {'mean_deflection_m': deflection}
    return {'fabric': 'f', 'wind_speed': 2.0, 'resolution': res, 'seed': seed,
            'valid': True, **stats}  # fmt: skip

  rows = [row(25, 0, 0.30), row(33, 0, 0.34), row(25, 1, 0.31), row(33, 1, 0.33)]
  rows.append({**row(33, 2, 9.9), 'valid': False})  # a blown-up world is left out
  s = mc.spread(rows)['mean_deflection_m']
  # between meshes: seed 0 range 0.04, seed 1 range 0.02; between seeds: 0.01, 0.01
  assert s['between_meshes'] == pytest.approx(0.03, abs=_EXACT)
  assert s['between_seeds'] == pytest.approx(0.01, abs=_EXACT)
  agg = {r['resolution']: r for r in mc.aggregate(rows)}
  assert agg[33]['seeds'] == 2
  assert agg[33]['mean_deflection_m']['mean'] == pytest.approx(0.335, abs=_EXACT)
  assert agg[33]['mean_deflection_m']['std'] == pytest.approx(0.005, abs=_EXACT)
  assert agg[25]['equivalent_wind'] is None  # compare() set none


def test_tiny_run_compares_meshes_and_resumes(tmp_path, monkeypatch):
  config = dataclasses.replace(mc.PRESETS['smoke'], backend='c')
  workdir = str(tmp_path)
  rows = mc.run(config, workdir)
  worlds = len(config.fabrics) * len(config.winds) * len(config.seeds)
  assert len(rows) == len(config.resolutions) * worlds
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
    mc.run(dataclasses.replace(config, seeds=(1,)), workdir)  # another config: reruns


def test_resume_reads_only_the_same_config(tmp_path):
  path = str(tmp_path / 'state.json')
  config = mc.PRESETS['smoke']
  assert files.resume(path, config) == {}
  files.write_json(
    path, {'config': dataclasses.asdict(config), 'resolutions': {'6': 1}}
  )
  assert files.resume(path, config)['resolutions'] == {'6': 1}  # lists vs tuples
  assert files.resume(path, dataclasses.replace(config, seeds=(3,))) == {}
  files.write_json(path, {'config': {'unknown_field': 1}})
  assert files.resume(path, config) == {}


@pytest.mark.parametrize(
  'script, output',
  [
    (['-m', 'benchmarks.mesh_convergence'], 'mesh_convergence.json'),
    (['-m', 'experiments.fabric_motion'], 'motion_sweep.json'),
  ],
)
def test_preset_scripts_run_from_the_command_line(tmp_path, script, output):
  # experiments.cli's flags, defined when the script runs (not on import)
  root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
  env = dict(os.environ, PYTHONPATH=root)
  args = ['--preset=smoke', '--backend=c', f'--workdir={tmp_path}']
  done = subprocess.run(
    [sys.executable, *script, *args], cwd=root, env=env, capture_output=True, text=True
  )
  assert done.returncode == 0, done.stderr[-2000:]
  assert os.path.isfile(tmp_path / output)
  bad = subprocess.run(
    [sys.executable, *script, '--preset=huge'], cwd=root, env=env, capture_output=True,
    text=True,
  )  # fmt: skip
  assert bad.returncode != 0 and 'huge' in bad.stderr
