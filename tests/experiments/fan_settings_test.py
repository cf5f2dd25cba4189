"""Tests for benchmarks/fan_settings.py: strata of hand-made rows, each mean
and standard error checked against NumPy by hand, and a bad file named."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from benchmarks import fan_settings as fs

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_EXACT = 1e-12


def _row(reading, ratio, area, ratio_err, centre):
  return {
    'reading': [reading, 0.02 * reading],
    'truth': {'load_ratio': ratio},
    'alone': {'area_weight': area, 'load_ratio': ratio_err},
    'centre': {'area_weight': centre},
  }


ROWS = [
  _row(2.0, 3.0, 4.0, 5.0, 9.0),
  _row(3.0, 9.0, 6.0, 7.0, 8.0),  # gentle reading, high ratio (light fabric)
  _row(4.0, 10.0, 12.0, 14.0, 11.0),
  _row(5.5, 15.0, 10.0, 11.0, 13.0),
  _row(3.5, 6.0, 2.0, 3.0, 7.0),  # on the split: gentle
]


def test_strata_split_by_reading_and_by_ratio():
  out = fs.strata(ROWS, 3.5, 8.0)
  gentle = out['reading <= 3.5 m/s']
  assert gentle['n'] == 3
  assert gentle['area_weight'] == pytest.approx(4.0, rel=_EXACT)  # (4 + 6 + 2) / 3
  assert gentle['area_weight_se'] == pytest.approx(2 / np.sqrt(3), rel=_EXACT)
  strong = out['reading > 3.5 m/s']
  assert strong['n'] == 2 and strong['load_ratio'] == pytest.approx(12.5, rel=_EXACT)
  assert strong['centre_area_weight'] == pytest.approx(12.0, rel=_EXACT)
  low = out['load ratio <= 8']
  assert low['n'] == 2 and low['area_weight'] == pytest.approx(3.0, rel=_EXACT)
  assert out['load ratio > 8']['n'] == 3


def test_script_prints_and_writes_the_strata(tmp_path):
  src = tmp_path / 'joint_pairs.json'
  src.write_text(json.dumps({'rows': ROWS}))
  out = tmp_path / 'strata.json'
  proc = subprocess.run(
    [sys.executable, 'benchmarks/fan_settings.py', f'--results={src}', f'--out={out}'],
    cwd=_ROOT, env=dict(os.environ, PYTHONPATH=_ROOT), capture_output=True,
    text=True, timeout=300,
  )  # fmt: skip
  assert proc.returncode == 0, proc.stderr[-2000:]
  assert '| reading <= 3.5 m/s | 3 | 4.0% (1.2)' in proc.stdout
  assert json.loads(out.read_text())['strata']['reading > 3.5 m/s']['n'] == 2


def test_a_file_that_is_not_a_result_is_named(tmp_path):
  bad = tmp_path / 'bad.json'
  bad.write_text('{"summary": {}}')
  proc = subprocess.run(
    [sys.executable, 'benchmarks/fan_settings.py', f'--results={bad}'],
    cwd=_ROOT, env=dict(os.environ, PYTHONPATH=_ROOT), capture_output=True,
    text=True, timeout=300,
  )  # fmt: skip
  assert proc.returncode != 0
  assert f'{bad}: not a joint_pairs.json' in proc.stderr


def test_estimate_notes_strong_fan_settings_and_the_gentler_wind():
  from experiments.pipeline import report

  note = report.fan_setting_note([12.0, 15.0], 'gray_interlock')
  # load ratio 8 at the middle area weight (0.185 kg/m^2): v = sqrt(8 w g / rho)
  v = np.sqrt(8.0 * 0.185 * 9.81 / 1.0)
  assert f'about {v:.1f} m/s or less for gray_interlock' in note
  assert 'about 12, 15' in note
  assert report.fan_setting_note(12.0, 'gray_interlock') is not None  # a scalar
  # one gentle recording among strong ones: nothing to advise
  assert report.fan_setting_note([12.0, 5.0], 'gray_interlock') is None
  assert report.fan_setting_note([report.STRONG_LOAD_RATIO], 'gray_interlock') is None


def test_the_note_reads_a_posterior_median_or_the_argmin_protocols_value():
  from experiments.pipeline import report

  assert report.point_of({'median': 12.0, 'value': 11.0}) == 12.0
  assert report.point_of({'value': 9.5, 'posterior_median': 9.0}) == 9.5  # argmin
