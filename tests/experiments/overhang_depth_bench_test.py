"""benchmarks/overhang_depth.py: the floor it fits, by hand, and the protocol
set's joint estimate on a sheet whose video says nothing (a flat likelihood):
the overhang's bending length and the anemometer alone."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from benchmarks import overhang_depth as bench
from experiments.pipeline import report


def test_the_fitted_floor_is_the_smallest_holding_nine_in_ten():
  # ten readings off by 1..10% with no fit spread: a 90% interval of
  # +-1.645 f c_hat holds nine of them once 1.645 f 1.09 >= 0.09
  rows = [
    {'c': 1.0, 'c_hat': 1.0 + e / 100, 'read': {'fit_sd': 0.0}} for e in range(1, 11)
  ]
  f = bench.fitted_floor(rows)
  want = 0.09 / (1.6448536269514722 * 1.09)
  assert want <= f < want + 0.0025  # the 0.25% steps it tries


def test_a_flat_sheet_and_a_strip_give_the_bending_and_the_wind():
  material = 'gray_interlock'
  space = physsim.search_space(material)
  b, w, v = 2.0, 0.19, 3.0
  c = float(physsim.params.bending_length(b, w, space.rigidity))
  g = int(np.prod(bench.Args().grid))
  run = {
    'seq': 0, 'material': material,
    'truth': {'bending_scale': b, 'area_weight': w, 'wind_speed': v},
    'gp_mean': np.zeros(g), 'gp_var': np.full(g, 1e-4), 'floor': 0.0, 'noise_sd': 1.0,
  }  # fmt: skip
  reading = {'c_hat': c, 'sd': 0.03 * c}
  tables = bench.shipped_tables(report.shipped_calibration('shape', 'paper'))
  assert set(tables) == set(bench.MODE_OF_SET)  # the shipped file calibrates both
  out = bench.joint_estimate(run, reading, bench.Args(), seed=0, tables=tables)
  for how in ('raw', 'printed'):  # nominal levels, and as an estimate prints it
    alone = out['sheet, anemometer'][how]
    both = out['sheet, anemometer, overhang'][how]
    assert alone['bending_scale']['narrowing_90'] == pytest.approx(1.0, abs=0.2), how
    # w unknown over its box (0.15-0.22) and c to 3%: b = w g c^3 / D0 to
    # about sqrt(11%^2 + 9%^2): a 90% interval of about x1.4 in a box of x100
    assert both['bending_scale']['narrowing_90'] > 6, how
    assert both['bending_scale']['held_90'] and both['bending_scale']['error'] < 1.15
    assert both['wind_speed']['held_90'] and both['wind_speed']['error'] < 0.06


def test_the_protocol_sets_figure_is_written(tmp_path):
  cell = lambda t, held: {'point': t * 1.1, 'interval_90': [t * 0.9, t * 1.3],
                          'held_90': held}  # fmt: skip
  sets = []
  for k, t in enumerate((0.5, 2.0)):
    truth = {'bending_scale': t, 'area_weight': 0.2, 'wind_speed': 2.0}
    row = {f: cell(v, k == 0) for f, v in truth.items()}
    sets.append({'truth': truth, 'joint': {
      'sheet, anemometer': {'raw': row}, 'sheet, anemometer, overhang': {'raw': row},
    }})  # fmt: skip
  path = tmp_path / 'sets.png'
  bench.plot_sets(sets, str(path))
  assert path.stat().st_size > 10_000


def test_a_protocol_set_is_written_for_a_sheet_recording(tmp_path):
  """benchmarks/protocol_set.py: the sheet's truth gives the strip's, and the
  protocol file names both, the estimate's edge reading the strip back."""
  import json

  from benchmarks import protocol_set
  from experiments.pipeline import takes
  from physsim import overhang_depth

  seq = tmp_path / 'seq'
  seq.mkdir()
  truth = {'bending_scale': 1.3, 'area_weight': 0.19, 'wind_speed': 2.5}
  (seq / 'meta.json').write_text(json.dumps(truth))
  out = tmp_path / 'set'
  protocol_set.main(protocol_set.Args(sequence=str(seq), out=str(out)))
  path = str(out / 'protocol.json')
  (take,) = takes.read(path)
  assert take.path == str(seq) and abs(take.wind[0] / 2.5 - 1) < 0.1
  strip = takes.fabric_overhang(path)
  space = physsim.search_space('gray_interlock')
  c = float(physsim.params.bending_length(1.3, 0.19, space.rigidity))
  r = overhang_depth.read_recording(strip.path, strip.camera_json, strip.length)
  assert r.bending_length == pytest.approx(c, rel=0.03)
