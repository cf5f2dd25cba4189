"""benchmarks/overhang_depth.py: the reader's error law it fits, by hand, and the protocol
set's joint estimate on a sheet whose video says nothing (a flat likelihood):
the overhang's bending length and the anemometer alone."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from benchmarks import overhang_depth as bench
from experiments.pipeline import calibration_tables
from experiments.studies import (
  overhang_joint,
  overhang_law,
  overhang_report,
  overhang_setups,
)


def test_the_law_scales_the_fit_and_floor_and_counts_holds_by_t_quantiles():
  row = {'c': 1.0, 'c_hat': 1.05, 'read': {'fit_sd': 0.03}}
  r = overhang_law.with_law(row, floor=0.04, dof=4.0)
  # scale: 0.03 and 0.04 x 1.05 in quadrature; sd: x sqrt(4 / 2)
  scale = float(np.hypot(0.03, 0.042))
  assert r['scale'] == pytest.approx(scale, rel=1e-12)
  assert r['sd'] == pytest.approx(scale * np.sqrt(2.0), rel=1e-12)
  assert r['z'] == pytest.approx(0.05 / scale, rel=1e-12)
  # t4's 50% and 90% quantiles by hand: 0.7407 and 2.1318
  rows = [{'z': z, 'c_hat': 1.0} for z in (0.7, 0.75, 2.1, 2.2)]
  assert (
    overhang_law.held(rows, 0.5, 4.0) == 0.25
    and overhang_law.held(rows, 0.9, 4.0) == 0.75
  )
  assert overhang_law.with_law({'c': 1.0, 'refused': 'x'}, 0.01, 4.0) == {
    'c': 1.0,
    'refused': 'x',
  }
  with pytest.raises(ValueError, match='abridged'):
    overhang_law.with_law({'c': 1.0, 'c_hat': 1.0}, 0.01, 4.0)


def test_the_fitted_law_recovers_the_law_readings_were_drawn_from():
  # 400 readings, no fit spread, errors exactly at the quantiles of a t of
  # 5 dof and scale 2%: the fit finds a law whose intervals hold as they say
  from scipy import stats

  q = (np.arange(400) + 0.5) / 400
  err = stats.t.ppf(q, 5.0) * 0.02
  rows = [{'c': 1.0, 'c_hat': 1.0 + e, 'read': {'fit_sd': 0.0}} for e in err]
  dof, floor = overhang_law.fitted_law(rows)
  law = [overhang_law.with_law(r, floor, dof) for r in rows]
  for level in overhang_law.FIT_LEVELS:
    assert abs(overhang_law.held(law, level, dof) - level) < 0.02, (dof, floor, level)
  assert 4.0 <= dof <= 6.0 and floor == pytest.approx(0.02, abs=0.0015)


def test_short_and_long_bending_lengths_are_reported_apart():
  # two short readings (one outside its 90% interval), three long (all in),
  # a refusal: coverage per group by t4's 90% quantile (2.1318)
  short, long_ = 0.5 * overhang_law.SHORT_C, 2.0 * overhang_law.SHORT_C
  rows = [
    {'c': short, 'c_hat': short, 'error': 0.1, 'z': 3.0},
    {'c': short, 'c_hat': short, 'error': -0.02, 'z': -0.5},
    *({'c': long_, 'c_hat': long_, 'error': 0.01, 'z': z} for z in (0.1, 1.0, 2.0)),
    {'c': short, 'refused': 'too few pixels'},
  ]
  g = overhang_law.by_length(rows, 4.0)
  assert g['short']['readings'] == 2 and g['long']['readings'] == 3
  assert g['short']['held_90'] == 0.5 and g['long']['held_90'] == 1.0
  assert g['short']['mean_abs_error'] == pytest.approx(0.06)
  assert g['long']['held_50'] == pytest.approx(1 / 3)


@pytest.mark.parametrize('ranges', sorted(overhang_setups.SETUPS))
def test_set_ups_are_drawn_inside_their_ranges(ranges):
  r = overhang_setups.SETUPS[ranges]
  rng = np.random.default_rng(0)
  for c in (0.006, 0.02, 0.035):
    for _ in range(40):
      s = overhang_setups.draw_setup(rng, c, ranges)
      cam, strip = s['camera'], s['strip']
      assert r['distance'][0] <= cam['distance'] <= r['distance'][1]
      assert r['elevation'][0] <= cam['elevation_deg'] <= r['elevation'][1]
      assert abs(cam['azimuth_deg']) <= r['azimuth']
      assert r['width'][0] <= strip['width'] <= r['width'][1]
      # the overhang: the ruler's marks and its 1 mm error around 2 c x range
      lo, hi = 2 * c * r['overhang'][0], 2 * c * r['overhang'][1]
      assert max(0.015, lo) - 0.01 < strip['overhang'] < hi + 0.01


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
  reading = {'c_hat': c, 'sd': 0.03 * c, 'dof': 4.0}
  tables = overhang_joint.shipped_tables(
    calibration_tables.shipped_calibration('shape', 'paper')
  )
  assert set(tables) == set(
    overhang_joint.MODE_OF_SET
  )  # the shipped file calibrates both
  out = overhang_joint.joint_estimate(run, reading, bench.Args(), seed=0, tables=tables)
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
  overhang_report.plot_sets(sets, str(path))
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


def test_the_results_file_keeps_what_reads_the_readings_again():
  """``compact``: a reading keeps its fit's spread, so a results file can be
  read again under another law (``--readings``), to 4 digits."""
  row = overhang_law.with_law(
    {'c': 0.0123456, 'c_hat': 0.0125, 'read': {'fit_sd': 0.000321, 'ratio': 2.0},
     'setup': {'big': list(range(100))}, 'profile': np.zeros((5, 2)),
     'told_overhang': 0.03, 'error': 0.0125 / 0.0123456 - 1},
    0.008, 4.0,
  )  # fmt: skip
  out = {'args': {'seed': 1}, 'floor': 0.008, 'dof': 4.0, 'summary': {'setups': 1},
         'rows': [row, {'c': 0.02, 'refused': 'no strip'}], 'sets': []}  # fmt: skip
  small = overhang_report.compact(out)
  kept = small['rows'][0]
  assert (
    'setup' not in kept
    and 'profile' not in kept
    and kept['read'] == {'fit_sd': 0.000321}
  )
  again = overhang_law.with_law(kept, 0.008, 4.0)
  assert again['z'] == pytest.approx(row['z'], rel=1e-3)
  assert small['rows'][1] == {'c': 0.02, 'refused': 'no strip'}
