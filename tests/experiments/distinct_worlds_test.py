"""Tests of ``objective.distinct_worlds``: which of a call's candidate worlds
simulate alike, derived by hand from small calls (no simulation)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from experiments.pipeline import objective as obj_lib

# A posterior search: every evaluation its own gust key.
CONFIG = obj_lib.EstimateConfig().replace(material='gray_interlock', seed=0)


def _data(ratios, boxes=None) -> obj_lib.ProblemData:
  """Stacked problem data with only what a simulation reads: boxes and
  rigidity ratios (the rest is not looked at)."""
  p = len(ratios)
  lo = np.tile(np.array([-1.0, 0.5, 0.1], np.float32), (p, 1))
  hi = np.tile(np.array([1.0, 6.0, 0.4], np.float32), (p, 1))
  if boxes is not None:
    hi[:, 2] = boxes
  return obj_lib.ProblemData(
    lo, hi, np.tile(np.array([1.0, 0.0, 0.0], np.float32), (p, 1)),
    np.asarray(ratios, np.float32), None, None, None, None, None,
  )  # fmt: skip


def _keys(firsts, q, config=CONFIG):
  """(P, q) gust keys of searches at evaluations ``firsts[i] ..``."""
  return jax.numpy.stack([obj_lib.candidate_keys(config, f, q)[0] for f in firsts])


def _points(p, q, seed=0):
  return np.random.default_rng(seed).uniform(-1, 1, (p, q, 3)).astype(np.float32)


def test_searches_sharing_a_design_simulate_it_once():
  # Problems 0-2: one fabric, the same design and keys (a calibration's
  # recordings); problem 3: the same fabric with other candidates.
  u = _points(4, 4)
  u[1:3] = u[0]
  rows, inverse = obj_lib.distinct_worlds(_data([1] * 4), u, _keys([0] * 4, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3, 12, 13, 14, 15])
  np.testing.assert_array_equal(inverse, [*range(4)] * 3 + [4, 5, 6, 7])


@pytest.mark.parametrize(
  'what',
  ['another fabric', 'another box', 'other keys', 'another point'],
)
def test_what_makes_a_simulation_differ(what):
  # Four searches given the same candidates; the fourth differs in one way.
  u = _points(4, 4)
  u[1:] = u[0]
  ratios, boxes, firsts = [1] * 4, None, [0] * 4
  if what == 'another fabric':
    ratios[3] = 0.5
  elif what == 'another box':
    boxes = [0.4, 0.4, 0.4, 0.5]
  elif what == 'other keys':
    firsts[3] = 4
  else:
    u[3, 2, 0] = np.nextafter(u[3, 2, 0], np.float32(2))  # one bit
  rows, inverse = obj_lib.distinct_worlds(_data(ratios, boxes), u, _keys(firsts, 4))
  if what == 'another point':  # only that world differs
    np.testing.assert_array_equal(rows, [0, 1, 2, 3, 14])
    np.testing.assert_array_equal(inverse[12:], [0, 1, 4, 3])
  else:  # all four of its worlds
    np.testing.assert_array_equal(rows, [0, 1, 2, 3, 12, 13, 14, 15])
    np.testing.assert_array_equal(inverse[12:], [4, 5, 6, 7])
  np.testing.assert_array_equal(inverse[:12], np.tile(np.arange(4), 3))


def test_common_random_numbers_repeat_a_candidate_within_a_search():
  # The paper's argmin scores every candidate with one key: a padded call's
  # repeated candidates are one simulation.
  config = CONFIG.replace(point='argmin')
  u = _points(1, 4)
  u[0, 1:] = u[0, 0]
  rows, inverse = obj_lib.distinct_worlds(_data([1]), u, _keys([0], 4, config))
  np.testing.assert_array_equal(rows, [0])
  np.testing.assert_array_equal(inverse, [0, 0, 0, 0])


def test_counts_are_padded_to_a_bucket_and_kept_only_where_they_halve_the_call():
  # 32 worlds: buckets of 32 // SIM_BUCKETS = 2 simulations.
  assert obj_lib.SIM_BUCKETS == 16
  u = _points(8, 4)
  u[1:] = u[0]  # 4 distinct simulations of 32
  rows, inverse = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3])
  np.testing.assert_array_equal(inverse, np.tile(np.arange(4), 8))
  u = _points(8, 4)
  u[4:] = u[:4]  # 16 distinct: half the call
  rows, inverse = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, np.arange(16))
  np.testing.assert_array_equal(inverse, np.tile(np.arange(16), 2))
  u[4, 0] += 0.5  # 17 distinct, padded to 18: more than half, the full call
  assert obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4)) is None
  u = _points(8, 4)
  u[1:4] = u[0]  # 4 + 16 = 20 distinct: the full call
  assert obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4)) is None
  u[4:6] = u[0]  # 4 + 8 = 12 distinct
  rows, _ = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3, *range(24, 32)])
  u[5, 0] += 0.5  # 13 distinct, padded to 14 with the last
  rows, _ = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3, 20, *range(24, 32), 31])
