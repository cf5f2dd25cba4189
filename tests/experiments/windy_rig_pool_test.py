"""benchmarks/windy_rig.py --pool: the windy rig's runs pooled, checked by hand."""

import json
import math

import pytest

from benchmarks import windy_rig
from bo.calibration import binomial_interval
from bo.design import Z90

SETTING = (
  'gibbs likelihood, sharpness 0.5, cameras off by 0.99-4 cm / 0.79-3.2 deg (1 sd)'
)


def _row(truth, median, lo50, hi50, lo90, hi90, setting=SETTING):
  return {
    'exit': 0, 'recording': 'rec00', 'truth': truth, 'median': median,
    'error': abs(median - truth) / truth,
    'interval_50': [lo50, hi50], 'interval_90': [lo90, hi90],
    'holds_50': lo50 <= truth <= hi50, 'holds': lo90 <= truth <= hi90,
    'calibration_setting': setting,
  }  # fmt: skip


def _run(path, rows, draws=-1):
  path.write_text(json.dumps({'settings': {'fabric_draws': draws}, 'rows': rows}))
  return str(path)


def test_the_pools_90_percent_binomial_interval_by_hand():
  # k = 5 of n = 10 at z = 1.645: centre 0.5, half z sqrt(0.025 + z^2/400) / (1 + z^2/10)
  z = Z90
  half = z * math.sqrt(0.025 + z * z / 400) / (1 + z * z / 10)
  lo, hi = binomial_interval(5, 10, z)
  assert lo == pytest.approx(0.5 - half) and hi == pytest.approx(0.5 + half)
  rows = [_row(3.0, 3.1, 2.9, 3.3, 2.5, 3.6)] * 5 + [
    _row(4.0, 3.0, 2.8, 3.2, 2.5, 3.8)
  ] * 5
  (group, _) = windy_rig.pooled([{**r, 'drawn': False, 'table': 't'} for r in rows])
  assert group['held_50'] == 5
  assert group['held_50_ci'] == pytest.approx((0.5 - half, 0.5 + half))


def test_half_widths_on_the_truths_side():
  # median 3, 50% interval [2.5, 4]: a truth of 3.5 is half the upper half-width
  assert windy_rig.half_widths(_row(3.5, 3.0, 2.5, 4.0, 2, 5)) == pytest.approx(0.5)
  assert windy_rig.half_widths(_row(2.0, 3.0, 2.5, 4.0, 2, 5)) == pytest.approx(2.0)


def test_the_50_percent_width_beside_the_median_by_hand(tmp_path):
  # median 3, 50% interval [2.5, 4]: half-width 0.75, a quarter of the median
  assert windy_rig.width_50(_row(3.5, 3.0, 2.5, 4.0, 2, 5)) == pytest.approx(0.25)
  rows = [_row(3.0, 2.0, 1.9, 2.1, 1, 3), _row(3.0, 3.0, 2.5, 4.0, 2, 5),
          _row(3.0, 4.0, 2.0, 6.0, 1, 7)]  # fmt: skip
  (group, _) = windy_rig.pooled([{**r, 'drawn': True, 'table': 't'} for r in rows])
  assert group['median_width_50'] == pytest.approx(0.25)  # of 0.05, 0.25, 0.5
  assert '| 25.0% |' in windy_rig.pool_table([group])


def test_runs_are_pooled_by_fabric_and_table(tmp_path):
  a = _run(tmp_path / 'a.json', [_row(3.0, 3.1, 2.9, 3.3, 2.5, 3.6),
                                 _row(4.0, 3.0, 2.8, 3.2, 2.5, 3.8)], draws=7)  # fmt: skip
  b = _run(tmp_path / 'b.json', [_row(2.5, 2.4, 2.3, 2.6, 2.0, 2.9, 'no cameras')])
  rows = windy_rig.read_rows([a, b])
  groups = {(g['fabric'], g['table']): g for g in windy_rig.pooled(rows)}
  drawn = groups[('drawn over the prior', '0.99-4 cm / 0.79-3.2 deg')]
  assert (drawn['n'], drawn['held_90'], drawn['held_50']) == (2, 1, 1)
  assert drawn['mean_error'] == pytest.approx((0.1 / 3 + 0.25) / 2)
  assert groups[('all', 'all')]['n'] == 3
  assert groups[("the recipe's own", 'no cameras')]['held_50'] == 1


def test_tables_of_the_intakes_errors_are_named_by_their_claims():
  setting = (
    'gibbs likelihood, shape distance, no network, cameras off as 32 measured '
    "intakes erred, each estimate carrying its intake's claim (claims 1.3-3.5 cm / "
    '0.99-2.7 deg)'
  )
  row = _row(3.0, 3.1, 2.9, 3.3, 2.5, 3.6, setting)
  assert (
    windy_rig.table_of_row(row) == 'intake errors, claims 1.3-3.5 cm / 0.99-2.7 deg'
  )
  assert windy_rig.table_of_row(_row(3, 3, 2, 4, 1, 5)) == '0.99-4 cm / 0.79-3.2 deg'


def test_a_file_that_is_no_windy_rig_run_is_named(tmp_path):
  bad = tmp_path / 'bad.json'
  bad.write_text('{"rows": [')
  with pytest.raises(ValueError, match='bad.json: not a windy_rig.json'):
    windy_rig.read_rows([str(bad)])
  other = tmp_path / 'other.json'
  other.write_text('{"n": 3}')
  with pytest.raises(ValueError, match='other.json: not a windy_rig.json'):
    windy_rig.read_rows([str(other)])
  with pytest.raises(ValueError, match='no such files'):
    windy_rig.main(windy_rig.Args(pool=str(tmp_path / 'none*.json')))


def test_main_writes_the_pool_and_its_picture(tmp_path):
  _run(tmp_path / 'a.json', [_row(3.0, 3.1, 2.9, 3.3, 2.5, 3.6)], draws=3)
  _run(tmp_path / 'b.json', [_row(2.5, 2.9, 2.7, 3.0, 2.4, 3.2)])
  out = tmp_path / 'out'
  windy_rig.main(windy_rig.Args(pool=str(tmp_path / '*.json'), workdir=str(out)))
  pooled = json.loads((out / 'pooled.json').read_text())
  assert [g['n'] for g in pooled['groups']] == [1, 1, 2]
  assert pooled['rows'][1]['half_widths'] == pytest.approx(2.0)
  assert (out / 'pooled.png').read_bytes()[:4] == b'\x89PNG'
  # pooled again into the runs' own folder: its earlier pool is not a run
  windy_rig.main(windy_rig.Args(pool=str(tmp_path / '*.json'), workdir=str(tmp_path)))
  windy_rig.main(windy_rig.Args(pool=str(tmp_path / '*.json'), workdir=str(tmp_path)))
  assert len(json.loads((tmp_path / 'pooled.json').read_text())['rows']) == 2
  # and from there into another folder: the runs' folder's pool is skipped too
  windy_rig.main(windy_rig.Args(pool=str(tmp_path / '*.json'), workdir=str(out)))
  assert len(json.loads((out / 'pooled.json').read_text())['rows']) == 2


def test_runs_side_by_side_with_pool_by_run(tmp_path):
  a = _run(tmp_path / 'a.json', [_row(3.0, 3.1, 2.9, 3.3, 2.5, 3.6),
                                 _row(4.0, 3.0, 2.8, 3.2, 2.5, 3.8)], draws=7)  # fmt: skip
  b = _run(tmp_path / 'b.json', [_row(3.0, 3.0, 2.7, 3.3, 2.5, 3.6)], draws=7)
  out = tmp_path / 'pool'
  windy_rig.main(windy_rig.Args(workdir=str(out), pool=f'{a},{b}', pool_by='run'))
  groups = json.loads((out / 'pooled.json').read_text())['groups']
  by_run = {g['fabric']: g for g in groups}
  assert (by_run['a.json']['n'], by_run['a.json']['held_50']) == (2, 1)
  assert by_run['b.json']['median_width_50'] == pytest.approx(0.1)
  assert by_run['all']['n'] == 3
  assert (out / 'pooled.png').stat().st_size > 0
