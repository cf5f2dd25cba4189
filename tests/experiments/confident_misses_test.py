"""Confident misses (a point far off with the truth outside its 90% interval),
counted and expected from the posteriors themselves, by hand."""

from __future__ import annotations

import json

import numpy as np
import pytest

import bo
from benchmarks import pooled_check
from experiments.studies import calibration

NOMINAL = bo.calibration.nominal_levels()


def _uniform(lo: float, hi: float, truth: float) -> dict:
  """A score whose one field's posterior is uniform on [lo, hi]."""
  return {
    'truth': np.array([truth]),
    'qf': (lo + (hi - lo) * calibration._QGRID)[:, None],
  }


def test_a_wide_posterior_expects_its_tails_and_a_narrow_one_none():
  # Uniform on [1, 5], point 3, 90% interval [1.2, 4.8]: a truth below 1.2
  # is a miss and more than 25% off (3 > 1.25 x 1.2); the posterior itself
  # puts 5% below 1.2 and 5% above 4.8 (both beyond 3/1.25 and 3/0.75).
  wide = [_uniform(1.0, 5.0, 1.1), _uniform(1.0, 5.0, 3.5)]
  seen, expected = calibration._confident_misses(
    wide, [NOMINAL, NOMINAL], 0, np.array([3.0, 3.0]), np.array([1.2, 1.2]),
    np.array([4.8, 4.8]), 'relative',
  )  # fmt: skip
  assert seen == 1 and expected == pytest.approx(0.2, abs=1e-9)
  # Uniform on [2.9, 3.1] around 3: no mass 25% away, so none expected; a
  # truth at 3.2 is outside its interval but only 6% off: not counted.
  narrow = [_uniform(2.9, 3.1, 3.2)]
  seen, expected = calibration._confident_misses(
    narrow, [NOMINAL], 0, np.array([3.0]), np.array([2.91]), np.array([3.09]),
    'relative',
  )  # fmt: skip
  assert seen == 0 and expected == 0.0
  # Bending's factor: a truth 1.3 x the point outside the interval counts.
  seen, _ = calibration._confident_misses(
    [_uniform(0.5, 2.0, 1.3)], [NOMINAL], 0, np.array([1.0]), np.array([0.6]),
    np.array([1.2]), 'factor',
  )  # fmt: skip
  assert seen == 1


def test_pooled_checks_add_their_confident_misses(tmp_path):
  paths = []
  for seed, seen, expected in ((1, 1, 1.8), (2, 2, 1.5)):
    cell = {
      'interval_50': 0.5, 'interval_90': 0.9, 'point_error_pct': 7.0,
      'centre_error_pct': 50.0, 'point_error_factor': 1.1, 'centre_error_factor': 4.0,
      'confident_misses': seen, 'confident_misses_expected': expected,
    }  # fmt: skip
    doc = {
      'seed': seed, 'n': 56, 'physics': 'mismatched',
      'shipped': {'setting': 'paper size'}, 'config': {'estimate': {'q': 40}},
      'modes': {'video': dict.fromkeys(pooled_check.FIELDS, cell)},
    }  # fmt: skip
    p = tmp_path / f'check{seed}.json'
    p.write_text(json.dumps(doc))
    paths.append(str(p))
  out = pooled_check.pool_checks(paths)
  wind = out['modes']['video']['wind_speed']
  assert wind['confident_misses'] == 3
  assert wind['confident_misses_expected'] == pytest.approx(3.3)
  assert 'video 3 (3.3)' in pooled_check.table(out, None)
