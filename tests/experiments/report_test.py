"""experiments.pipeline.report: summaries and errors against values worked by hand."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import physsim
from experiments.pipeline import (
  advice,
  calibration_tables,
  measurements,
  objective,
  report,
  search_figures,
  summaries,
  table_notes,
)

# Percent errors and factors are ratios of a few floats: exact to rounding.
TOL = 1e-9


def test_stats_reads_quantiles_of_the_samples():
  samples = np.arange(101, dtype=np.float64)  # 0..100: quantiles are the percent
  s = summaries.stats(np.array([42.0]), samples)
  assert s['value'] == 42.0
  assert s['posterior_median'] == 50.0
  assert s['interval_90'] == pytest.approx([5.0, 95.0], abs=TOL)
  assert s['std'] == pytest.approx(np.sqrt((101**2 - 1) / 12), rel=TOL)


def test_errors_by_hand():
  space = physsim.SearchSpace()  # wind 1-6, area weight 0.1-0.37, bending 0.1-10
  truth = {'bending_scale': 2.0, 'wind_speed': 4.0, 'area_weight': 0.2}
  best = physsim.Params(0.5, 5.0, 0.25)
  e = summaries.errors(best, truth, space)['estimate']
  assert e['wind_speed_pct'] == pytest.approx(25.0, abs=TOL)
  assert e['area_weight_pct'] == pytest.approx(25.0, abs=TOL)
  assert e['bending_factor'] == pytest.approx(4.0, rel=TOL)  # 0.5 vs 2: x4
  # rho v^2 / (w g): (25 / 0.25) / (16 / 0.2) = 100 / 80, 25% high.
  assert e['load_ratio_pct'] == pytest.approx(25.0, rel=TOL)
  centre = summaries.errors(best, truth, space)['range_centre']
  assert centre['wind_speed_pct'] == pytest.approx(100 * abs(3.5 - 4.0) / 4.0, rel=TOL)
  assert centre['bending_factor'] == pytest.approx(2.0, rel=TOL)  # log centre is 1


def test_mean_error_is_geometric_for_the_bending_factor_only():
  assert summaries.mean_error([2.0, 8.0], 'bending_factor') == pytest.approx(4.0)
  assert summaries.mean_error([2.0, 8.0], 'wind_speed_pct') == pytest.approx(5.0)


def test_covered_checks_each_interval_and_the_load_ratio():
  truth = {'bending_scale': 1.0, 'wind_speed': 3.0, 'area_weight': 0.2}
  ratio = float(physsim.load_ratio(3.0, 0.2))
  result = {
    'estimate': {
      'bending_scale': {'interval_90': [0.5, 2.0], 'interval_50': [1.1, 1.5]},
      'wind_speed': {'interval_90': [2.0, 2.9]},
      'area_weight': {'interval_90': [0.2, 0.3]},  # the edge counts as inside
    },
    'load_ratio': {'interval_90': [0.5 * ratio, 2 * ratio]},
  }
  c = summaries.covered(result, truth)
  assert c['bending_scale'] == {'interval_90': True, 'interval_50': False}
  assert c['wind_speed'] == {'interval_90': False}
  assert c['area_weight'] == {'interval_90': True}
  assert c['load_ratio'] == {'interval_90': True}


@pytest.mark.parametrize(
  'wind_sd, weight_sd, joint, mode',
  [
    (0.0, 0.0, False, 'video'),
    (0.1, 0.0, False, 'known wind'),
    (0.0, 0.01, False, 'known area weight'),
    (0.1, 0.01, False, None),
    (0.0, 0.0, True, 'joint pair'),
    (0.1, 0.0, True, 'joint pair, known winds'),
    (0.0, 0.01, True, None),
  ],
)
def test_calibration_mode(wind_sd, weight_sd, joint, mode):
  class Measured:
    wind_speed_sd = wind_sd
    area_weight_sd = weight_sd

  assert calibration_tables.calibration_mode(Measured(), joint=joint) == mode


def test_shape_estimates_quote_their_own_calibration_at_their_size():
  demo = objective.EstimateConfig.preset('demo', distance='shape')
  assert (
    calibration_tables.calibration_file(demo)
    == calibration_tables.SHAPE_CALIBRATION_FILE
  )
  paper = objective.EstimateConfig().replace(distance='shape')
  assert (
    calibration_tables.calibration_file(paper)
    == calibration_tables.SHAPE_PAPER_CALIBRATION_FILE
  )
  config = paper
  config = config.replace(distance='energy')
  assert (
    calibration_tables.calibration_file(config) == calibration_tables.CALIBRATION_FILE
  )
  config = config.replace(calibration='/elsewhere/mine.json')
  assert calibration_tables.calibration_file(config) == '/elsewhere/mine.json'


def test_the_default_estimate_of_every_fabric_quotes_measured_coverage():
  # issue 41: a paper-size estimate with the defaults (the shape distance)
  # quotes the shipped paper tables for each of the 7 fabrics, never
  # "indicative"; through a network it does not (the PSD's tables are demo-size)
  for fabric in sorted(physsim.FABRICS):
    config = objective.EstimateConfig().replace(material=fabric)
    note = calibration_tables.calibration_note(config)
    assert note['matches'] and note['recalibrated'], (fabric, note.get('differs'))
    assert note['mode'] == 'video'
    assert 'indicative' not in table_notes.calibration_line(note)
  psd = objective.EstimateConfig().replace(distance='energy')
  assert 'indicative' in table_notes.calibration_line(
    calibration_tables.calibration_note(psd)
  )


def test_the_distances_table_sets_each_estimate_beside_the_truth():
  shape = _result()
  psd = _result(
    estimate={**shape['estimate'], 'wind_speed': _entry(4.4, 4.2, 4.6, 4.0, 4.9, 3)}
  )
  psd['errors'] = summaries.errors(physsim.Params(0.5, 4.4, 0.25), shape['truth'],
                                   physsim.search_space('gray_interlock'))  # fmt: skip
  table = report.distances_table({'shape (default)': shape, 'PhySNet PSD': psd})
  lines = table.splitlines()
  assert max(map(len, lines)) <= report.WIDTH
  assert 'shape (default)' in lines[0] and 'PhySNet PSD' in lines[0]
  assert "(the point's error against the truth)" in table
  wind = next(x for x in lines if x.startswith('| wind'))
  assert '| 4 ' in wind  # the truth
  assert '5 [4.41, 5.62] (25.0%)' in wind and '4.4 [4, 4.9] (10.0%)' in wind
  bending = next(x for x in lines if x.startswith('| bending'))
  assert '(x4.00)' in bending  # 0.5 against a true 2


def test_iterations_of_counts_the_initial_design_as_iteration_zero():
  it = search_figures.iterations_of(n_evals=10, n_init=4, q=2)
  assert list(it) == [0, 0, 0, 0, 1, 1, 2, 2, 3, 3]


def _entry(value, lo50, hi50, lo90, hi90, narrowing):
  return {
    'value': value, 'posterior_median': value, 'interval_50': [lo50, hi50],
    'interval_90': [lo90, hi90], 'narrowing_90': narrowing,
  }  # fmt: skip


def _result(**extra):
  truth = {'bending_scale': 2.0, 'wind_speed': 4.0, 'area_weight': 0.2}
  best = physsim.Params(0.5, 5.0, 0.25)
  space = physsim.search_space('gray_interlock')
  return {
    'material': 'gray_interlock',
    'point': 'bayes',
    'estimate': {
      'bending_scale': _entry(0.5, 0.3, 0.9, 0.12, 3.1, 1.2),
      'wind_speed': _entry(5.0, 4.7, 5.3, 4.41, 5.62, 4.2),
      'area_weight': _entry(0.25, 0.2, 0.3, 0.15, 0.33, 1.5),
    },
    'load_ratio': _entry(1.02, 0.9, 1.1, 0.81, 1.23, 3.3),
    'truth': truth,
    'errors': summaries.errors(best, truth, space),
    'calibration': {
      'recalibrated': True,
      'mode': 'known wind',
      'n_calibration_recordings': 200,
      'setting': 'gray interlock, demo size, five networks of the shipped recipe '
      'with their own simulations and a long description of what was measured',
      'networks': 5,
      'coverage': {
        k: {'interval_90': 0.9, 'interval_50': 0.5}
        for k in ('bending_scale', 'wind_speed', 'area_weight', 'load_ratio')
      },
    },  # fmt: skip
    **extra,
  }


def test_the_table_fits_the_terminal_and_prints_what_the_result_holds():
  r = {'bending_scale': 1.05, 'wind_speed': 0.4, 'area_weight': 0.95}
  table = report.report_table(_result(network_retrieval_vs_chance=r))
  lines = table.splitlines()
  assert max(map(len, lines)) <= report.WIDTH
  wind = next(x for x in lines if x.startswith('| wind'))
  assert '| 4 ' in wind and '| 5 ' in wind  # the truth, then the point
  assert '[4.7, 5.3]' in wind and '[4.41, 5.62]' in wind and 'x4.2' in wind
  assert '| 0.40 ' in wind  # its retrieval
  ratio = next(x for x in lines if x.startswith('| load ratio'))
  assert f'{float(physsim.load_ratio(4.0, 0.2)):.3g}' in ratio  # the true ratio
  # The errors as a table: wind 25% off (5 vs 4), the centre 3.5 m/s 12.5%.
  err = next(x for x in lines if x.startswith('| wind ') and '%' in x)
  assert '25.0%' in err and '12.5%' in err
  bending = next(x for x in lines if x.startswith('| bending ') and 'x4.00' in x)
  assert 'x2.00' in bending  # the range centre (1) against a true 2
  assert 'least expected error' in table  # the note says what the point is
  assert 'calibration (known wind)' in table
  assert 'the prior holds' not in table  # no reading in this result's config
  # with a wind reading and a strip's bending length: the prior holds them
  measured = {'wind_speed': 4.1, 'wind_speed_sd': 0.08, 'bending_length': 0.02,
              'bending_length_sd': 0.0008, 'area_weight': 0.0, 'area_weight_sd': 0.0}  # fmt: skip
  read = ' '.join(report.report_table(_result(config={'measured': measured})).split())
  assert (
    "the prior holds the wind reading and the strip's bending length: narrower is "
    'what the video added'
  ) in read


def test_the_argmin_table_and_no_truth():
  result = _result(point='argmin', truth=None)
  table = report.report_table(result)
  assert 'point (argmin)' in table and 'GP 90% interval' in table
  assert 'error against the truth' not in table and 'calibration' not in table
  assert max(map(len, table.splitlines())) <= report.WIDTH


def test_the_joint_table_fits_and_sets_each_recording_beside_itself_alone():
  alone = _result()['estimate']
  rec = lambda w: {
    'wind_speed': {'median': w, 'interval_90': [w - 0.2, w + 0.2], 'narrowing_90': 5.0},
    'load_ratio': {'median': 1.0, 'interval_90': [0.9, 1.1], 'narrowing_90': 4.0},
    'alone': {**alone, 'load_ratio': _entry(1.01, 0.9, 1.1, 0.8, 1.2, 3.0)},
  }  # fmt: skip
  shared = {'median': 0.21, 'interval_90': [0.19, 0.23], 'narrowing_90': 6.5}
  joint = {
    'bending_scale': {**shared, 'median': 1.3}, 'area_weight': shared,
    'recordings': [rec(2.0), rec(3.0), rec(3.5)], 'calibration': None,
  }  # fmt: skip
  table = report.joint_table(joint)
  lines = table.splitlines()
  assert max(map(len, lines)) <= report.WIDTH
  assert any(
    x.startswith('| area weight (g/m^2), shared') and '[190, 230]' in x for x in lines
  )
  rec2 = next(x for x in lines if x.startswith('| wind (m/s), rec. 2'))
  assert '| 3.5 ' in rec2 and '[3.3, 3.7]' in rec2 and '[4.41, 5.62]' in rec2
  assert sum(x.startswith('| recording ') for x in lines) == 3


def _texts_inside(fig) -> list[str]:
  """The texts of ``fig`` (titles, labels, ticks, colour-bar labels) drawn
  partly outside its canvas."""
  canvas = FigureCanvasAgg(fig)  # the figure was closed after saving
  canvas.draw()
  renderer = canvas.get_renderer()
  box = fig.bbox
  out = []
  for t in fig.findobj(lambda a: hasattr(a, 'get_text') and a.get_visible()):
    if not t.get_text():
      continue
    e = t.get_window_extent(renderer)
    if e.x0 < box.x0 - 1 or e.y0 < box.y0 - 1 or e.x1 > box.x1 + 1 or e.y1 > box.y1 + 1:
      out.append(t.get_text())
  return out


@pytest.mark.parametrize('n_frames', [2, 6])
def test_the_montage_keeps_its_labels_inside_the_canvas(
  n_frames, tmp_path, monkeypatch
):
  figs = []
  monkeypatch.setattr(
    search_figures.files, 'savefig', lambda fig, path, dpi=100: figs.append(fig)
  )
  depth = np.random.default_rng(0).uniform(1.0, 2.0, (n_frames, 16, 16))
  search_figures.plot_montage(
    depth, depth, 20.0, str(tmp_path / 'montage.png'), n=n_frames
  )
  (fig,) = figs
  assert _texts_inside(fig) == []
  labels = [t.get_text() for t in fig.findobj(lambda a: hasattr(a, 'get_text'))]
  assert any(lbl.startswith('depth (m)') for lbl in labels)


def test_the_next_recording_line_names_what_was_left_at_the_prior():
  config = objective.EstimateConfig()
  told = {'bending_scale': {'narrowing_90': 1.0}, 'area_weight': {'narrowing_90': 1.1}}
  line = advice.next_recording_note(told, config.measured, 'out/e')
  assert line.startswith('next: the recording(s) told little about bending and area')
  assert '--area_weight=' in line and '--bending_length=' in line
  assert 'python -m experiments.plan --workdir=out/e' in line and '\n' not in line
  # a scale's reading and a bending length given: nothing left to advise
  weighed = config.replace(
    measured=measurements.Measured(area_weight=0.18, area_weight_sd=0.004,
                                bending_length=0.02, bending_length_sd=0.002),
  )  # fmt: skip
  assert advice.next_recording_note(told, weighed.measured, 'out/e') is None
  # the strip measured bending (the video adding nothing to it): area weight only
  strip = config.replace(
    measured=measurements.Measured(bending_length=0.02, bending_length_sd=0.002)
  )
  line = advice.next_recording_note(told, strip.measured, 'out/e')
  assert line.startswith('next: the recording(s) told little about area weight;'), line
  assert '--area_weight=' in line and '--bending_length=' not in line
  narrowed = {
    'bending_scale': {'narrowing_90': 3.0},
    'area_weight': {'narrowing_90': 4},
  }
  assert advice.next_recording_note(narrowed, config.measured, 'out/e') is None


def test_a_point_far_from_the_median_gets_the_median_in_a_note():
  # the windy rig's case: a wide right-skewed wind posterior, point 3.60 under
  # a median of 3.99 (11% apart); bending and area weight within 10% of theirs
  result = _result()
  est = result['estimate']
  est['wind_speed'] = {**_entry(3.60, 3.2, 4.4, 2.4, 4.9, 1.3), 'median': 3.99}
  est['bending_scale'] = {**est['bending_scale'], 'median': 0.52}
  est['area_weight'] = {**est['area_weight'], 'median': 0.25}
  table = report.report_table(result)
  assert 'wind (m/s) 3.99 (point 3.6)' in ' '.join(table.split())
  assert 'bending rigidity (uN m)' not in table.split('posterior median where')[1]
  assert max(map(len, table.splitlines())) <= report.WIDTH
  # no note when every point is within 10%, nor for the posterior median point
  est['wind_speed']['median'] = 3.7
  assert 'posterior median where' not in report.report_table(result)
  est['wind_speed']['median'] = 3.99
  assert 'posterior median where' not in report.report_table(
    {**result, 'point': 'median'}
  )


def test_the_table_prints_a_labs_units():
  """Issue 76: bending as rigidity in uN m (the scale times the fabric's
  reference rigidity), area weight in g/m^2, and the point's bending length in
  mm, each derived here by hand from the result's scales; estimate.json's
  scales stay as they are."""
  result = _result()
  d0 = physsim.reference_rigidity('gray_interlock')  # N m
  lines = report.report_table(result).splitlines()
  assert max(map(len, lines)) <= report.WIDTH
  rigidity = next(x for x in lines if x.startswith('| bending rigidity (uN m)'))
  cells = [c.strip() for c in rigidity.split('|')[1:-1]]
  assert cells[1] == f'{2.0 * d0 * 1e6:.3g}' and cells[2] == f'{0.5 * d0 * 1e6:.3g}'
  assert cells[4] == f'[{0.12 * d0 * 1e6:.3g}, {3.1 * d0 * 1e6:.3g}]'
  weight = next(x for x in lines if x.startswith('| area weight (g/m^2)'))
  assert '| 200 ' in weight and '| 250 ' in weight and '[150, 330]' in weight
  length = next(x for x in lines if x.startswith('| bending length (mm)'))
  by_hand = 1e3 * (0.5 * d0 / (0.25 * 9.81)) ** (1 / 3)
  assert f'| {by_hand:.3g} ' in length
  assert result['estimate']['bending_scale']['value'] == 0.5  # the file's scale
  # without a known fabric the bending stays the search's scale
  plain = report.report_table({**result, 'material': None})
  assert 'bending (x)' in plain and 'bending length' not in plain
