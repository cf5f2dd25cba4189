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


def _script(*args):
  """python -m benchmarks.fan_settings, as a user runs it."""
  return subprocess.run(
    [sys.executable, '-m', 'benchmarks.fan_settings', *args],
    cwd=_ROOT, env=dict(os.environ, PYTHONPATH=_ROOT), capture_output=True,
    text=True, timeout=300,
  )  # fmt: skip


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
  proc = _script(f'--results={src}', f'--out={out}')
  assert proc.returncode == 0, proc.stderr[-2000:]
  assert '| reading <= 3.5 m/s | 3 | 4.0% (1.2)' in proc.stdout
  assert json.loads(out.read_text())['strata']['reading > 3.5 m/s']['n'] == 2


def _errors(wind, area, ratio):
  return {'wind_speed': wind, 'area_weight': area, 'load_ratio': ratio}


def _grouped(seq, alone, joint, first_2=None):
  row = _row(2.0, 3.0, alone, 1.0, 10.0)
  row['seq'] = seq
  row['alone'] = _errors(1.0, alone, 2.0)
  row['joint'] = _errors(1.0, joint, 2.0)
  row['centre'] = _errors(50.0, 10.0, 100.0)
  if first_2 is not None:
    row['first_2'] = _errors(1.0, first_2, 2.0)
  return row


# two files, groups of 3 (seq // 3); the joint error is shared within a group
RUN_A = [
  _grouped(0, 4.0, 3.0, 5.0), _grouped(1, 6.0, 3.0, 7.0), _grouped(2, 8.0, 3.0),
  _grouped(3, 2.0, 1.0, 2.0), _grouped(4, 2.0, 1.0, 4.0), _grouped(5, 5.0, 1.0),
]  # fmt: skip
RUN_B = [_grouped(0, 9.0, 8.0, 9.0), _grouped(1, 3.0, 8.0, 1.0), _grouped(2, 3.0, 8.0)]


def test_by_group_counts_each_group_once_in_the_standard_error():
  out = fs.by_group([(RUN_A, 3), (RUN_B, 3)])
  joint = out['joint']
  assert joint['groups'] == 3 and joint['n'] == 9
  assert joint['area_weight'] == pytest.approx(4.0, rel=_EXACT)  # (9 + 3 + 24) / 9
  # group means 3, 1, 8: SE = sd / sqrt(3), not the recordings' sd / sqrt(9)
  assert joint['area_weight_se'] == pytest.approx(
    np.std([3.0, 1.0, 8.0], ddof=1) / np.sqrt(3), rel=_EXACT
  )
  alone = out['alone']  # group means 6, 3, 5
  assert alone['area_weight'] == pytest.approx(42 / 9, rel=_EXACT)
  assert alone['area_weight_se'] == pytest.approx(
    np.std([6.0, 3.0, 5.0], ddof=1) / np.sqrt(3), rel=_EXACT
  )
  first = out['first_2']  # two rows a group: means 6, 3, 5 again
  assert first['n'] == 6 and first['area_weight'] == pytest.approx(28 / 6, rel=_EXACT)
  assert out['centre']['wind_speed'] == pytest.approx(50.0, rel=_EXACT)


def test_script_pools_files_by_group_when_they_record_their_groups(tmp_path):
  paths = []
  for name, rows in (('a', RUN_A), ('b', RUN_B)):
    p = tmp_path / f'{name}.json'
    p.write_text(json.dumps({'rows': rows, 'flags': {'group': 3}}))
    paths.append(str(p))
  out = tmp_path / 'pooled.json'
  proc = _script(f'--results={",".join(paths)}', f'--out={out}')
  assert proc.returncode == 0, proc.stderr[-2000:]
  assert '| joint | 3 | 9 | 1.0% (0.0) | 4.0% (2.1) |' in proc.stdout
  assert json.loads(out.read_text())['by_group']['joint']['groups'] == 3


@pytest.mark.parametrize(
  'text, why',
  [
    ('{"summary": {}}', "'rows'"),
    ('{"rows": [{"reading": [2, 0.04], "truth": {}, "alone": {}}]}', "no 'centre'"),
    ('[1, 2]', 'indices'),
    (json.dumps({'rows': [{**ROWS[0], 'truth': {}}]}), "a row lacks 'load_ratio'"),
    (
      json.dumps({'rows': [{**RUN_B[0], 'joint': {}}], 'flags': {'group': 3}}),
      "a row lacks 'wind_speed'",
    ),
  ],
)
def test_a_file_that_is_not_a_result_is_named(tmp_path, text, why):
  bad = tmp_path / 'bad.json'
  bad.write_text(text)
  proc = _script(f'--results={bad}')
  assert proc.returncode != 0
  assert f'{bad}: not a joint_pairs.json' in proc.stderr and why in proc.stderr
  assert 'Traceback' not in proc.stderr


def test_estimate_notes_strong_fan_settings_and_the_gentler_wind():
  from experiments.pipeline import advice

  note = advice.fan_setting_note([12.0, 15.0], 'gray_interlock')
  # load ratio 8 at the middle area weight (0.185 kg/m^2): v = sqrt(8 w g / rho)
  v = np.sqrt(8.0 * 0.185 * 9.81 / 1.0)
  assert f'about {v:.1f} m/s or less for gray_interlock' in note
  assert 'about 12, 15' in note
  assert 'three gentler settings' in note and '--recording=a,b,c' in note
  assert advice.fan_setting_note(12.0, 'gray_interlock') is not None  # a scalar
  # one gentle recording among strong ones: nothing to advise
  assert advice.fan_setting_note([12.0, 5.0], 'gray_interlock') is None
  assert advice.fan_setting_note([advice.STRONG_LOAD_RATIO], 'gray_interlock') is None


def test_the_note_reads_a_posterior_median_or_the_argmin_protocols_value():
  from experiments.pipeline import summaries

  assert summaries.point_of({'median': 12.0, 'value': 11.0}) == 12.0
  assert summaries.point_of({'value': 9.5, 'posterior_median': 9.0}) == 9.5  # argmin
