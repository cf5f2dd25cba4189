"""benchmarks.model_error: the model error chosen from its sweep's scores."""

from __future__ import annotations

import json

import pytest

from benchmarks import model_error


def _rows(scores: dict[float, float]) -> list[dict]:
  return [{'model_error': e, 'mismatched_score': s} for e, s in scores.items()]


def test_the_smallest_error_within_the_tolerance_of_the_best_is_chosen():
  rows = _rows({0.0: 0.5249, 0.5: 0.5239, 1.0: 0.5234, 2.0: 0.5265})
  assert model_error.choose(rows, 0.01) == 0.0  # 0.5249 <= 1.01 x 0.5234
  assert model_error.choose(rows, 0.0) == 1.0  # the best itself
  # a term that clearly helps is chosen
  assert model_error.choose(_rows({0.0: 0.70, 0.5: 0.52, 1.0: 0.53}), 0.01) == 0.5


def test_a_sweep_made_with_another_error_is_refused(tmp_path):
  for kind, body in (
    ('cal', {'model_error': 0.5, 'held_out': {}, 'n': 1}),
    ('chk', {'modes': {}, 'n': 1}),
  ):
    (tmp_path / f'{kind}_1').mkdir()
    (tmp_path / f'{kind}_1' / ('calibration.json' if kind == 'cal' else 'check.json')
     ).write_text(json.dumps(body))  # fmt: skip
  with pytest.raises(ValueError, match='made with model error 0.5'):
    model_error.row(str(tmp_path), '1')
  with pytest.raises(ValueError, match='missing'):
    model_error.row(str(tmp_path), '2')


def test_checks_of_several_seeds_pool_as_the_recordings_mean(tmp_path):
  cell = lambda v: {f: {'interval_50': v, 'interval_90': v, 'interval_score_90': v}
                    for f in model_error.FIELDS}  # fmt: skip
  docs = {
    'cal_0': ('calibration.json', {'model_error': 0.0, 'n': 1,
                                   'held_out': {'video': cell(0.5)}}),
    'chk_0': ('check.json', {'seed': 1, 'n': 56, 'modes': {'video': cell(0.4)}}),
    'chk_0_s2': ('check.json', {'seed': 2, 'n': 28, 'modes': {'video': cell(0.7)}}),
  }  # fmt: skip
  for d, (name, body) in docs.items():
    (tmp_path / d).mkdir()
    (tmp_path / d / name).write_text(json.dumps(body))
  r = model_error.row(str(tmp_path), '0', ('2',))
  got = r['mismatched']['video']['wind_speed']['interval_90']
  assert got == pytest.approx((56 * 0.4 + 28 * 0.7) / 84)
  assert r['n_mismatched'] == 84
  assert model_error.row(str(tmp_path), '0')['n_mismatched'] == 56
  same = json.loads((tmp_path / 'chk_0' / 'check.json').read_text())
  (tmp_path / 'chk_0_s2' / 'check.json').write_text(json.dumps(same))
  with pytest.raises(ValueError, match='two checks of one seed'):
    model_error.row(str(tmp_path), '0', ('2',))
