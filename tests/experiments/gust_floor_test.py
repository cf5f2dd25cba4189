"""Tests for benchmarks/gust_floor.py: the Cramer-Rao standard error against
its closed form, the area-weight floor against a Monte Carlo of the same
measurement, the summary against a float64 NumPy mean, and the script end to
end on a small cloth (MuJoCo C)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from benchmarks import gust_floor as gf

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_EXACT = 1e-9
_MC = 0.02  # relative: 200k Monte Carlo draws


def test_ratio_sd_is_the_inverse_fisher_information_of_the_summary():
  rng = np.random.default_rng(0)
  z = rng.standard_normal((50, 2))
  z = (z - z.mean(0)) @ np.linalg.inv(np.linalg.cholesky(np.cov(z, rowvar=False)).T)
  cov = np.array([[4e-4, 1e-4], [1e-4, 9e-4]])  # m^2
  samples = 0.3 + z @ np.linalg.cholesky(cov).T  # sample covariance exactly cov
  slope = np.array([0.02, -0.05])  # m per unit log ratio
  by_hand = 1 / np.sqrt(slope @ np.linalg.inv(cov) @ slope)
  assert gf.ratio_sd(samples, slope) == pytest.approx(by_hand, rel=_EXACT)
  # a steeper slope: proportionally smaller error
  assert gf.ratio_sd(samples, 2 * slope) == pytest.approx(by_hand / 2, rel=_EXACT)


@pytest.mark.parametrize('k', [1, 3])
def test_floor_is_the_mean_error_of_k_readings_and_clips(k):
  s, r, n = 0.08, 0.02, 200_000
  rng = np.random.default_rng(k)
  # each recording: log ratio measured with sd s, log wind read with sd r;
  # log w = 2 log v - log ratio + const, averaged over the k recordings
  log_w = (2 * r * rng.standard_normal((n, k)) - s * rng.standard_normal((n, k))).mean(
    1
  )
  mc = 100 * np.mean(np.abs(np.expm1(log_w)))
  assert gf.floor(s, r, k) == pytest.approx(mc, rel=_MC)


def test_summaries_are_the_mean_centroid_over_the_first_frames():
  rng = np.random.default_rng(1)
  pos = rng.normal(size=(3, 7, 5, 3))
  got = gf.summaries(pos.astype(np.float32), 4)
  want = np.array([[pos[b, :4, :, j].mean() for j in (1, 2)] for b in range(3)])
  assert got == pytest.approx(want, rel=1e-5)


@pytest.mark.slow
def test_script_writes_a_floor_per_wind_and_clip(tmp_path):
  out = tmp_path / 'floor.json'
  proc = subprocess.run(
    [sys.executable, '-m', 'benchmarks.gust_floor', '--winds=3', '--draws=4',
     '--seconds=1', '--clips=0.5,1', '--cloth_resolution=8', '--backend=c',
     f'--out={out}'],
    cwd=_ROOT, env=dict(os.environ, PYTHONPATH=_ROOT), capture_output=True,
    text=True, timeout=600,
  )  # fmt: skip
  assert proc.returncode == 0, proc.stderr[-3000:]
  rows = json.loads(out.read_text())['rows']
  assert [r['clip_s'] for r in rows] == [0.5, 1.0]
  for r in rows:
    assert np.isfinite(r['ratio_sd']) and r['ratio_sd'] > 0
    assert len(r['slope_m']) == 2 and min(r['gust_sd_m']) > 0
    f = r['area_weight_floor_0.02']
    assert f['1'] == pytest.approx(gf.floor(r['ratio_sd'], 0.02, 1), rel=_EXACT)
    assert f['3'] < f['1']
  assert '| 3 |' in proc.stdout and 'floor' in proc.stdout
  assert not list(tmp_path.glob('*.tmp*'))  # written whole


@pytest.mark.parametrize(
  'args, named',
  [
    (['--seconds=1', '--clips=2'], '--clips up to 2'),
    (['--winds=a'], '--winds=a: need positive numbers'),
    (['--winds=3,-1'], '--winds=3,-1: need positive numbers'),
    (['--clips=2,nan'], '--clips=2,nan: need positive numbers'),
  ],
)
def test_bad_flags_are_refused_by_name_before_any_simulation(args, named):
  proc = subprocess.run(
    [sys.executable, '-m', 'benchmarks.gust_floor', *args],
    cwd=_ROOT, env=dict(os.environ, PYTHONPATH=_ROOT), capture_output=True,
    text=True, timeout=300,
  )  # fmt: skip
  assert proc.returncode != 0
  assert named in proc.stderr
  assert 'Traceback' not in proc.stderr
