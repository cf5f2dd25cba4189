"""benchmarks.pooled_check: several checks' counts added up exactly, and
checks that cannot be pooled refused in one line naming the file."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import bo
import physsim
from benchmarks import pooled_check

Q = pooled_check.FIELDS


def _check(seed: int, n: int, held50: float, held90: float, err: float,
           physics='mismatched') -> dict:  # fmt: skip
  cell = {
    'interval_50': held50, 'interval_90': held90,
    'point_error_pct': err, 'centre_error_pct': 10.0,
    'point_error_factor': 1.0 + err / 100, 'centre_error_factor': 4.0,
  }  # fmt: skip
  return {
    'seed': seed, 'n': n, 'physics': physics,
    'shipped': {'setting': 'paper size, shape distance'},
    'config': {'estimate': {'q': 40, 'calibration': f'/somewhere/{seed}.json'}},
    'modes': {'known wind': {q: cell for q in Q}},
  }  # fmt: skip


def _write(tmp_path, name: str, doc: dict) -> str:
  p = tmp_path / name
  p.write_text(json.dumps(doc))
  return str(p)


def test_counts_add_up_to_the_pooled_coverage_and_errors_weigh_by_recordings(tmp_path):
  a = _write(tmp_path, 'a.json', _check(1, 56, 28 / 56, 50 / 56, 6.0))
  b = _write(tmp_path, 'b.json', _check(2, 28, 20 / 28, 27 / 28, 9.0))
  out = pooled_check.pool_checks([a, b])
  r = out['modes']['known wind']['area_weight']
  assert out['n'] == 84
  assert r['held_50']['count'] == 48 and r['held_50']['held'] == pytest.approx(48 / 84)
  assert r['held_90']['count'] == 77
  lo, hi = r['held_90']['ci']
  assert lo < 77 / 84 < hi
  assert r['held_50']['per_seed'] == pytest.approx([0.5, 20 / 28])
  # the mean error over recordings: (56 x 6 + 28 x 9) / 84
  assert r['point_error'] == pytest.approx((56 * 6.0 + 28 * 9.0) / 84)


@pytest.mark.parametrize(
  'second, match',
  [
    (_check(1, 56, 0.5, 0.9, 6.0), 'two files of one seed'),
    (_check(2, 56, 0.5, 0.9, 6.0, physics='own'), 'physics differs'),
  ],
)
def test_checks_that_cannot_be_pooled_are_refused_naming_the_file(
  tmp_path, second, match
):
  a = _write(tmp_path, 'a.json', _check(1, 56, 0.5, 0.9, 6.0))
  b = _write(tmp_path, 'b.json', second)
  with pytest.raises(ValueError, match=match):
    pooled_check.pool_checks([a, b])


def test_a_missing_or_foreign_file_is_named(tmp_path):
  with pytest.raises(ValueError, match='nope.json: file not found'):
    pooled_check.pool_checks([str(tmp_path / 'nope.json')])
  bad = _write(tmp_path, 'x.json', {'sets': []})
  with pytest.raises(ValueError, match='x.json: not a check.json'):
    pooled_check.pool_checks([bad])
  listed = _write(tmp_path, 'l.json', [1, 2])  # JSON, but not an object
  with pytest.raises(ValueError, match='l.json: expected a JSON object'):
    pooled_check.pool_checks([listed])


def _sets_doc(seed: int, truths_points: list[tuple[float, float, bool]]) -> dict:
  """An overhang_depth summary with one mode's sets: (truth, point, held)."""
  sets = []
  for t, p, h in truths_points:
    cell = {'point': p, 'interval_90': [p / 2, p * 2], 'held_90': h, 'held_50': False}
    sets.append({
      'seq': 0, 'material': 'gray_interlock',
      'truth': {'bending_scale': t, 'wind_speed': t, 'area_weight': t},
      'joint': {'sheet, anemometer, overhang': {'printed': {
        f: cell for f in pooled_check.SET_FIELDS}}},
    })  # fmt: skip
  return {'args': {'seed': seed, 'setups': 'protocol'}, 'dof': 10.0, 'floor': 0.0,
          'sets': sets}  # fmt: skip


def test_protocol_sets_pool_their_errors_and_the_bending_narrowing_by_hand(tmp_path):
  a = _write(tmp_path, 'a.json', _sets_doc(1, [(1.0, 1.1, True), (1.0, 0.8, False)]))
  b = _write(tmp_path, 'b.json', _sets_doc(2, [(2.0, 2.0, True)]))
  out = pooled_check.pool_sets([a, b])['modes']['sheet, anemometer, overhang']
  assert out['sets'] == 3 and out['how'] == 'printed'
  # factors 1.1, 1.25, 1.0: median 1.1; percent errors 10, 20, 0: mean 10
  assert out['bending_median_factor'] == pytest.approx(1.1)
  assert out['area_weight_mean_pct'] == pytest.approx(10.0)
  assert out['bending_scale_held_90']['count'] == 2
  assert out['bending_scale_held_90']['per_seed'] == pytest.approx([0.5, 1.0])
  fab = out['area_weight_by_fabric']['gray_interlock']
  lo, hi = physsim.search_space('gray_interlock').area_weight
  centre = np.mean([abs((lo + hi) / 2 / t - 1) for t in (1.0, 1.0, 2.0)])
  assert fab['sets'] == 3 and fab['mean_pct'] == pytest.approx(10.0)
  assert fab['centre_pct'] == pytest.approx(100 * centre)
  assert fab['box_ratio'] == pytest.approx(hi / lo)
  # truths (= winds here) 1, 1 and 2 m/s: 15% and 0%
  assert out['area_weight_by_wind'] == pytest.approx({'1-2 m/s': 15.0, '2-3 m/s': 0.0})
  # every interval spans a factor of 4: the prior's 0.9 of the log box over log 4
  b0, b1 = physsim.search_space('gray_interlock').bending_scale
  assert out['bending_narrowing_90_median'] == pytest.approx(
    0.9 * math.log(b1 / b0) / math.log(4.0)
  )
  other = _sets_doc(3, [(1.0, 1.0, True)])
  other['dof'] = 4.0
  c = _write(tmp_path, 'c.json', other)
  with pytest.raises(ValueError, match="reader's law differs"):
    pooled_check.pool_sets([a, c])


def test_pairs_that_hold_together_widen_the_interval_as_half_as_many_sets():
  """Pairs whose two sets always hold or miss together carry half the
  information: their bootstrap interval is about Wilson's on the pairs'
  count, wider than Wilson's on the sets'; independent sets in pairs of one
  give about Wilson's on the sets."""
  rng = np.random.default_rng(3)
  one = rng.random(100) < 0.5
  together = np.repeat(one, 2)  # 200 sets, 100 pairs
  pairs = np.repeat(np.arange(100), 2)
  lo, hi = pooled_check.pair_interval(together, pairs)
  k = int(together.sum())
  wl, wh = bo.calibration.binomial_interval(k, 200)
  pl, ph = bo.calibration.binomial_interval(k // 2, 100)
  assert hi - lo > 1.25 * (wh - wl)
  assert hi - lo == pytest.approx(ph - pl, rel=0.15)
  alone = rng.random(200) < 0.5
  lo, hi = pooled_check.pair_interval(alone, np.arange(200))
  wl, wh = bo.calibration.binomial_interval(int(alone.sum()), 200)
  assert hi - lo == pytest.approx(wh - wl, rel=0.15)


def test_each_fabric_counts_add_up_over_the_checks(tmp_path, capsys):
  def fabrics(held90):
    cell = {'interval_50': 0.5, 'interval_90': held90}
    return {'white_tablecloth': {'n': 8, **{q: cell for q in Q}},
            'black_denim': {'n': 8, **{q: {**cell, 'interval_90': 1.0} for q in Q}}}  # fmt: skip

  docs = [_check(1, 16, 0.5, 0.9, 6.0), _check(2, 16, 0.5, 0.9, 6.0)]
  for d, held in zip(docs, (6 / 8, 5 / 8), strict=True):
    d['modes']['video'] = {**d['modes']['known wind'], 'by_material': fabrics(held)}
  paths = [_write(tmp_path, f'{k}.json', d) for k, d in enumerate(docs)]
  out = pooled_check.pool_checks(paths)
  by = out['modes']['video']['by_material']
  r = by['white_tablecloth']['wind_speed']['held_90']
  assert by['white_tablecloth']['n'] == 16 and r['count'] == 11
  assert r['ci'][0] < 11 / 16 < r['ci'][1]
  assert by['black_denim']['area_weight']['held_90']['count'] == 16
  assert 'by_material' not in out['modes']['known wind']  # the checks had none
  text = pooled_check.table(out, None)
  assert '| white_tablecloth | 16 | 69%' in text
