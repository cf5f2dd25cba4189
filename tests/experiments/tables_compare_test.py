"""Tests for benchmarks/tables_compare.py: two hand-made estimates, their mean
errors and coverage counts worked out by hand."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import tables_compare as tc

_TOL = 1e-9


def _estimate(truth, point, median, held90, load_ratio_90):
  est = {
    f: {
      'value': point[f],
      'median': median[f],
      'interval_90': [0.0, 10.0] if held90 else [100.0, 101.0],
      'interval_50': [100.0, 101.0],
    }
    for f in truth
  }
  errors = {
    'wind_speed_pct': 100 * abs(point['wind_speed'] / truth['wind_speed'] - 1),
    'area_weight_pct': 100 * abs(point['area_weight'] / truth['area_weight'] - 1),
    'bending_factor': max(
      point['bending_scale'] / truth['bending_scale'],
      truth['bending_scale'] / point['bending_scale'],
    ),
    'load_ratio_pct': 0.0,  # not recomputed by the script: passed through
  }
  covered = {
    q: {'interval_90': held90, 'interval_50': False}
    for q in ('wind_speed', 'area_weight', 'bending_scale', 'load_ratio')
  }
  return {
    'material': 'gray_interlock',
    'truth': truth,
    'estimate': est,
    'errors': {'estimate': errors},
    'covered': covered,
    'load_ratio': {'median': 2.0, 'interval_90': list(load_ratio_90)},
  }


def test_means_and_counts_by_hand():
  truth = dict(bending_scale=1.0, wind_speed=2.0, area_weight=0.2)
  a = _estimate(
    truth,
    point=dict(bending_scale=2.0, wind_speed=2.2, area_weight=0.21),
    median=dict(bending_scale=0.5, wind_speed=1.8, area_weight=0.2),
    held90=True,
    load_ratio_90=(1.6, 2.4),  # half-width 0.4 of median 2: 20%
  )
  b = _estimate(
    truth,
    point=dict(bending_scale=8.0, wind_speed=2.0, area_weight=0.18),
    median=dict(bending_scale=1.0, wind_speed=2.1, area_weight=0.22),
    held90=False,
    load_ratio_90=(1.8, 2.2),  # 10%
  )
  no_truth = {k: v for k, v in a.items() if k != 'truth'}
  s = tc.summarise([a, b, no_truth])
  assert s['n'] == 2
  np.testing.assert_allclose(s['point']['wind_speed_pct'], (10 + 0) / 2, atol=_TOL)
  np.testing.assert_allclose(s['point']['area_weight_pct'], (5 + 10) / 2, atol=_TOL)
  np.testing.assert_allclose(
    s['point']['bending_factor'], 4.0, atol=_TOL
  )  # sqrt(2 x 8)
  np.testing.assert_allclose(s['median']['wind_speed_pct'], (10 + 5) / 2, atol=1e-6)
  np.testing.assert_allclose(s['median']['area_weight_pct'], (0 + 10) / 2, atol=1e-6)
  np.testing.assert_allclose(s['median']['bending_factor'], np.sqrt(2.0), atol=1e-6)
  assert s['held']['wind_speed_90'] == 1 and s['held']['load_ratio_50'] == 0
  np.testing.assert_allclose(s['load_ratio_half_width_90_pct'], 15.0, atol=_TOL)
  assert '| run | 2 |' in tc._row('run', s)


def test_load_reads_tables_and_estimate_files(tmp_path):
  one = {'truth': {'wind_speed': 1.0}, 'n': 1}
  (tmp_path / 'tables.json').write_text(json.dumps({'estimates': {'a': one, 'b': one}}))
  for k in range(3):
    (tmp_path / f'e{k}').mkdir()
    (tmp_path / f'e{k}' / 'estimate.json').write_text(json.dumps(one))
  got = tc.load(f'{tmp_path}/tables.json+{tmp_path}/e*/estimate.json')
  assert got == [one] * 5
  with pytest.raises(ValueError, match='nothing matches'):
    tc.load(f'{tmp_path}/missing/*.json')
