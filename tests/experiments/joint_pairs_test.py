"""Tests for benchmarks/joint_pairs.py on a CPU: one group of two smoke
recordings (fan settings drawn in a narrower range) estimated with the shape
distance and no network, the simulator's mesh and gusts set by flag; each
error is its point's, checked by hand, and a rerun resumes."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import physsim
from tests.experiments import estimate_fixtures as fx

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_EXACT = 1e-9  # errors and bias are recomputed from the same float64 values
NAMES = ('wind_speed', 'area_weight', 'load_ratio')


def _run(*args: str) -> subprocess.CompletedProcess:
  env = dict(os.environ, PYTHONPATH=_ROOT)
  return subprocess.run(
    [sys.executable, '-m', 'benchmarks.joint_pairs', *args],
    cwd=_ROOT, env=env, capture_output=True, text=True, timeout=1800,
  )  # fmt: skip


@pytest.fixture(scope='module')
def joint_run(tmp_path_factory):
  root = tmp_path_factory.mktemp('joint_pairs')
  args = (  # no --model: the shape distance needs no network
    f'--image_size={fx.SIZE}', f'--workdir={root / "work"}', '--smoke', '--backend=c',
    '--preset=smoke', '--pairs=1', '--group=2', '--distance=shape',
    '--gusts=0.3', '--cloth_resolution=8', '--fan_winds=2,3', '--physics=mismatched',
  )  # fmt: skip
  proc = _run(*args)
  assert proc.returncode == 0, proc.stderr[-3000:]
  path = root / 'work' / 'joint_pairs.json'
  return args, path, json.loads(path.read_text()), proc.stdout


@pytest.mark.slow
def test_errors_are_their_points_and_the_flags_are_recorded(joint_run):
  _, _, out, stdout = joint_run
  assert out['flags']['cloth_resolution'] == 8
  assert out['flags']['gusts'] == pytest.approx(0.3)
  assert out['flags']['distance'] == 'shape'
  assert out['flags']['model'] == '' and out['flags']['image_size'] == fx.SIZE
  assert out['flags']['fan_winds'] == ['2', '3']
  assert out['flags']['physics'] == 'mismatched'
  metas = list((joint_run[1].parent / 'recordings').rglob('meta.json'))
  assert metas  # the recordings say which physics made them
  assert all(json.loads(m.read_text())['physics'] == 'mismatched' for m in metas)
  rows = out['rows']
  assert len(rows) == 2
  for r in rows:
    t = r['truth']
    assert t['load_ratio'] == pytest.approx(
      float(physsim.load_ratio(t['wind_speed'], t['area_weight'])), rel=_EXACT
    )
    assert 2.0 <= t['wind_speed'] <= 3.0  # the fan settings asked for
    # a 2% anemometer reading: within 5 sd of the truth
    assert abs(r['reading'][0] / t['wind_speed'] - 1) < 0.1
    for who in ('alone', 'joint'):
      for n in NAMES:
        by_hand = 100 * abs(r[f'{who}_point'][n] / t[n] - 1)
        assert r[who][n] == pytest.approx(by_hand, rel=_EXACT, abs=_EXACT)
  # the group shares its area weight: one truth, one joint point
  assert rows[0]['truth']['area_weight'] == rows[1]['truth']['area_weight']
  assert rows[0]['joint_point']['area_weight'] == rows[1]['joint_point']['area_weight']
  s = out['summary']
  for n in NAMES:
    bias = 100 * np.mean([np.log(r['joint_point'][n] / r['truth'][n]) for r in rows])
    assert s['joint_bias'][n] == pytest.approx(bias, rel=_EXACT, abs=_EXACT)
    assert s['joint'][n] == pytest.approx(np.mean([r['joint'][n] for r in rows]))
  assert s['joint']['n'] == 2
  assert 'bias' in stdout and 'range centre' in stdout
  assert 'step' in stdout  # the searches ran (the resume test relies on it)


@pytest.mark.slow
def test_a_rerun_resumes_to_the_same_result(joint_run):
  args, path, out, _ = joint_run
  proc = _run(*args)
  assert proc.returncode == 0, proc.stderr[-3000:]
  assert 'step' not in proc.stdout  # every search had ended: nothing simulated
  assert json.loads(path.read_text())['rows'] == out['rows']


def test_a_negative_mesh_is_refused_by_name(tmp_path):
  proc = _run(f'--model={tmp_path}', f'--workdir={tmp_path}', '--cloth_resolution=-1')
  assert proc.returncode != 0
  assert 'cloth_resolution' in proc.stderr


def test_a_distance_that_embeds_needs_a_network(tmp_path):
  proc = _run(f'--workdir={tmp_path}', '--distance=energy')
  assert proc.returncode != 0
  assert 'missing --model: --distance=energy embeds frames' in proc.stderr
  assert not os.listdir(tmp_path)  # refused before anything was made


@pytest.mark.parametrize('winds', ['3,9', '4,2', 'a'])
def test_fan_winds_outside_the_box_are_refused_before_any_work(tmp_path, winds):
  proc = _run(f'--workdir={tmp_path / "w"}', '--distance=shape', f'--fan_winds={winds}')
  assert proc.returncode != 0
  assert f'--fan_winds={winds}: need lo,hi m/s with 1 <= lo < hi <= 6' in proc.stderr
  assert not (tmp_path / 'w').exists()


@pytest.mark.slow
def test_a_sheet_and_its_hemmed_twin_share_their_fan_and_the_hem_is_simulated(tmp_path):
  """``--hem_mass``: a pair is one truth filmed twice, the second sweep with
  the hem (its recordings say so) and its own cameras; with no anemometer
  (``--reading_sd=0``) the two share one wind in the joint (the same wind
  point), and the same searches with a wind each are read beside it."""
  work = tmp_path / 'work'
  proc = _run(
    f'--image_size={fx.SIZE}', f'--workdir={work}', '--smoke', '--backend=c',
    '--preset=smoke', '--pairs=1', '--group=2', '--distance=shape',
    '--cloth_resolution=8', '--fan_winds=2,3', '--physics=mismatched',
    '--hem_mass=0.3', '--reading_sd=0',
  )  # fmt: skip
  assert proc.returncode == 0, proc.stderr[-3000:]
  out = json.loads((work / 'joint_pairs.json').read_text())
  plain, hem = out['rows']
  assert plain['truth'] == hem['truth'] and plain['reading'] is None
  assert (plain['hem_mass'], hem['hem_mass']) == (0.0, 0.3)
  assert plain['joint_point']['wind_speed'] == hem['joint_point']['wind_speed']
  assert 'fans_apart' in plain and out['summary']['fans_apart']['n'] == 2
  metas = [
    json.loads(m.read_text()) for m in (work / 'recordings_hem').rglob('meta.json')
  ]
  assert metas and all(m['hem_mass'] == 0.3 for m in metas)
  assert all('hem_mass' not in json.loads(m.read_text())
             for m in (work / 'recordings').rglob('meta.json'))  # fmt: skip
  saved = json.loads((work / 'pair_00' / 'recording_1' / 'estimate.json').read_text())
  assert saved['config']['hem_mass'] == 0.3
  assert 'no readings; each pair one fan setting, the second with 300 g' in proc.stdout


def test_a_hem_pairs_two_recordings(tmp_path):
  proc = _run(f'--workdir={tmp_path / "w"}', '--distance=shape', '--hem_mass=0.3',
              '--group=3')  # fmt: skip
  assert proc.returncode != 0
  assert (
    '--hem_mass pairs a sheet with its hemmed twin: --group=2, got 3' in proc.stderr
  )
  assert not (tmp_path / 'w').exists()
