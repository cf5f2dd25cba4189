"""The calibration study over several fabrics at the estimate's own size.

Issue 41: a paper-size estimate of any fabric must quote measured coverage.
The study then gives every fabric its own pairs drawn over its own search
box, estimates all of them in one lockstep, pools the tables (ranks are in
each posterior's own CDF) and reports each fabric's held-out coverage; the
shipped file is quoted by estimates of every fabric it holds, at its size,
while demo-size estimates keep the demo's file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest

import physsim
from experiments.pipeline import calibration_tables, table_notes
from experiments.pipeline import datasets as gen
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import (
  calibration,
  calibration_analysis,
  calibration_check,
  calibration_report,
  calibration_scores,
)
from physsim.overhang_depth import DOF

FABRICS = ('gray_interlock', 'black_denim')
# The paper size's structure (its own recordings, the estimate's cloth and
# clock, no network) at the smallest size that still fits a GP on a CPU.
TINY = calibration.Config(
  materials=FABRICS,
  size='paper',
  pairs=1,
  folds=2,
  backend='c',
  sharpness_grid=(0.5,),
  batch_size=4,
  estimate=EstimateConfig().replace(
    distance='shape', cloth_resolution=8, frames=8, warmup=0.25, q=2, n_init=4,
    max_iter=1, posterior_grid=(4, 8, 4),
  ),
)  # fmt: skip
TINY_RECORDINGS = dataclasses.replace(
  gen.PRESETS['eval'], frames=8, cloth_resolution=10, resolution=32, timestep=1 / 240
)


def test_each_fabric_draws_over_its_own_box_and_the_first_keeps_its_stream():
  one = dataclasses.replace(TINY, materials=(), material=FABRICS[0])
  np.testing.assert_array_equal(
    np.asarray(calibration.truths(TINY, material=FABRICS[0]).wind_speed),
    np.asarray(calibration.truths(one).wind_speed),
  )  # a one-fabric study's truths do not move
  for m in FABRICS:
    t = calibration.truths(TINY, material=m)
    (b0, b1), (v0, v1), (w0, w1) = physsim.search_space(m).bounds()
    assert np.all((np.asarray(t.area_weight) >= w0) & (np.asarray(t.area_weight) <= w1))
    # pairs share bending and area weight
    np.testing.assert_array_equal(t.area_weight[0::2], t.area_weight[1::2])
  a = calibration.truths(TINY, material=FABRICS[0]).wind_speed
  b = calibration.truths(TINY, material=FABRICS[1]).wind_speed
  assert not np.allclose(np.asarray(a), np.asarray(b))
  assert calibration.first_seq(TINY, FABRICS[1]) == 2 * TINY.pairs


@pytest.mark.parametrize(
  ('change', 'words'),
  [
    ({'materials': ('gray_interlock', 'silk')}, ("'silk'", '--materials')),
    ({'materials': ('black_denim', 'black_denim')}, ('a fabric twice',)),
    ({'pairs': 0}, ('--pairs=0',)),
    ({'length_sd': 0.0}, ('--length_sd=0.0', '(0, 0.5]')),
    ({'measured_sd': 0.9}, ('--measured_sd=0.9',)),
    ({'length_dof': 2.0}, ('--length_dof=2.0', 'more than 2')),
    ({'length_sd_spread': -0.1}, ('--length_sd_spread=-0.1',)),
    ({'length_dof': float('nan')}, ('--length_dof=nan',)),
    ({'estimate': TINY.estimate.replace(distance='energy')}, ('--distance=energy',)),
    ({'size': 'demo', 'estimate': TINY.estimate.replace(distance='energy')},
     ('a study with networks calibrates one fabric',)),
  ],
)  # fmt: skip
def test_a_study_that_cannot_run_is_refused_naming_the_setting(change, words):
  with pytest.raises(ValueError) as e:
    calibration.check_config(dataclasses.replace(TINY, **change))
  for w in words:
    assert w in str(e.value)


def test_the_paper_preset_is_every_fabric_at_the_estimates_own_size():
  p = calibration.PRESETS['paper']
  calibration.check_config(p)
  assert set(calibration.study_materials(p)) == set(physsim.FABRICS)
  est = calibration.study_configs(p)[3]
  default = EstimateConfig()
  for f in ('cloth_resolution', 'frames', 'warmup', 'q', 'n_init', 'max_iter',
            'posterior_grid', 'sharpness', 'fps', 'gusts'):  # fmt: skip
    assert est.flat()[f] == default.flat()[f], f
  rec = calibration.study_configs(p)[1]
  assert rec.cloth_resolution == gen.PRESETS['eval'].cloth_resolution
  assert rec.sequences == 2 * p.pairs and rec.materials == p.materials
  assert rec.physics == 'own'
  # recordings unlike the estimator's simulator; the estimates keep their own
  other = dataclasses.replace(p, physics='mismatched')
  assert calibration.study_configs(other)[1].physics == 'mismatched'
  assert calibration.study_configs(other)[3] == est


@pytest.fixture(scope='module')
def study(tmp_path_factory):
  workdir = str(tmp_path_factory.mktemp('cal_fabrics'))
  with pytest.MonkeyPatch.context() as mp:
    mp.setitem(gen.PRESETS, 'eval', TINY_RECORDINGS)
    out = calibration.run(TINY, workdir)
  return workdir, out


@pytest.mark.slow
def test_every_fabric_is_estimated_as_itself_and_reported(study):
  workdir, out = study
  assert out['materials'] == list(FABRICS) and out['size'] == 'paper'
  assert out['n'] == 2 * TINY.pairs * len(FABRICS)
  runs = calibration.saved_runs(workdir)
  assert sorted(r['material'] for r in runs) == sorted(FABRICS * 2)
  for r in runs:
    (b0, b1), (v0, v1), (w0, w1) = physsim.search_space(r['material']).bounds()
    assert w0 <= r['truth']['area_weight'] <= w1, r
    with open(os.path.join(r['workdir'], 'estimate.json')) as f:
      assert json.load(f)['material'] == r['material']
  by = out['analysis']['cross_validated_by_material']['gibbs']
  assert set(by) == set(FABRICS) and all(by[m]['n'] == 2 for m in FABRICS)
  with open(os.path.join(workdir, 'calibration.md')) as f:
    text = f.read()
  assert "each fabric's recordings" in text and all(m in text for m in FABRICS)
  # packed for an analysis elsewhere: the fabrics travel with the GPs
  calibration.pack_runs(runs, workdir)
  packed = calibration.packed_runs(workdir)
  assert sorted(r['material'] for r in packed) == sorted(FABRICS * 2)


@pytest.mark.slow
def test_a_recording_estimated_alone_matches_itself_in_the_lockstep(study, tmp_path):
  from benchmarks import estimate_latency

  workdir, _ = study
  out = str(tmp_path / 'svb.json')
  seq = f'{calibration.first_seq(TINY, FABRICS[1]):04d}'  # a black denim recording
  estimate_latency.main(estimate_latency.Args(
    against=workdir, image_size=TINY_RECORDINGS.resolution, seqs=(seq,), out=out,
  ))  # fmt: skip
  with open(out) as f:
    (row,) = json.load(f)
  assert row['material'] == FABRICS[1] and row['recordings_in_batch'] == 4
  # MuJoCo C is deterministic: the same simulations, the same posterior
  for field, alone in row['alone'].items():
    np.testing.assert_allclose(alone, row['batched'][field], rtol=1e-9, err_msg=field)


@pytest.mark.slow
def test_paper_estimates_of_its_fabrics_quote_it_and_demo_ones_do_not(
  study, tmp_path, monkeypatch
):
  workdir, out = study
  demo, paper = tmp_path / 'calibration_shape.json', tmp_path / 'shape_paper.json'
  monkeypatch.setattr(calibration_tables, 'SHAPE_CALIBRATION_FILE', str(demo))
  monkeypatch.setattr(calibration_tables, 'SHAPE_PAPER_CALIBRATION_FILE', str(paper))
  demo_study = dataclasses.replace(
    calibration.PRESETS['smoke'], estimate=TINY.estimate.replace(
      q=8, n_init=16, max_iter=6, posterior_grid=(12, 64, 24))
  )  # fmt: skip
  demo_cfg = calibration.study_configs(demo_study)[3]
  demo.write_text(json.dumps({
    'n': 1, 'setting': 'demo', 'sharpness': 0.5, 'coverage': {},
    'config': {'estimate': demo_cfg.flat()},
  }))  # fmt: skip
  with open(os.path.join(workdir, calibration.RESULT_FILE)) as f:
    paper.write_text(f.read())  # what --install --size=paper does
  assert calibration_tables.shipped_calibration('shape', 'paper') == str(paper)
  searched = calibration.study_configs(TINY)[3].replace(point='bayes')
  for m in FABRICS:
    mine = searched.replace(material=m)
    assert calibration_tables.calibration_file(mine) == str(paper)
    note = calibration_tables.calibration_note(mine)
    assert note['matches'] and note['recalibrated'], (m, note)
  other = calibration_tables.calibration_note(
    searched.replace(material='white_tablecloth')
  )
  assert not other['matches'] and 'material' in other['differs'], other
  assert calibration_tables.calibration_file(demo_cfg) == str(demo)
  with pytest.raises(ValueError, match='size'):
    calibration_tables.shipped_calibration('shape', 'poster')


# The shipped paper-size file holds 30 recordings per fabric (210): a 90%
# coverage measured on 210 has a binomial standard error of about 2 points and
# a 50% one about 3.5, so issue 41's targets themselves are the bands.
PAPER_BANDS = {'interval_90': (0.85, 0.95), 'interval_50': (0.40, 0.60)}


@pytest.mark.parametrize('material', sorted(physsim.FABRICS))
def test_a_default_paper_size_shape_estimate_of_any_fabric_quotes_measured_coverage(
  material,
):
  config = EstimateConfig().replace(distance='shape', material=material)
  assert (
    calibration_tables.calibration_file(config)
    == calibration_tables.SHAPE_PAPER_CALIBRATION_FILE
  )
  note = calibration_tables.calibration_note(config)
  assert note['matches'] and note['recalibrated'], note  # never "indicative"
  assert note['n_calibration_recordings'] >= 210
  for field, cov in note['coverage'].items():  # held out from the tables
    for level, (lo, hi) in PAPER_BANDS.items():
      assert lo <= cov[level] <= hi, (field, level, cov)
  # with an anemometer, and jointly with a second recording, too
  wind = config.replace(wind_speed=3.0, wind_speed_sd=0.06)
  assert calibration_tables.calibration_note(wind)['mode'] == 'known wind'
  assert calibration_tables.calibration_note(config, joint=True, recordings=2)[
    'matches'
  ]
  # the protocol set (issue 39): with an overhang's bending length read to
  # 3.5% under the depth reader's t law, with and without the anemometer
  space = physsim.search_space(material)
  c = float(
    physsim.params.bending_length(1.0, np.mean(space.area_weight), space.rigidity)
  )
  for readings, mode in (
    (config, 'bending length'),
    (wind, 'known wind, bending length'),
  ):
    strip = readings.replace(
      bending_length=c, bending_length_sd=0.035 * c, bending_length_dof=DOF
    )
    note = calibration_tables.calibration_note(strip)
    assert note['matches'] and note['recalibrated'] and note['mode'] == mode, note
    for field, cov in note['coverage'].items():
      for level, (lo, hi) in PAPER_BANDS.items():
        assert lo <= cov[level] <= hi, (mode, field, level, cov)
  loose = wind.replace(
    bending_length=c, bending_length_sd=0.12 * c, bending_length_dof=DOF
  )
  assert (
    'bending_length reading uncertainty'
    in calibration_tables.calibration_note(loose)['differs'][0]
  )
  # the reader's errors vary with the strip: the tables were fitted over a
  # range of them (a short strip's 5.8%, the benchmark's largest, inside it)
  lo, hi = cal_range = calibration.length_sd_range(calibration.PRESETS['paper'])
  assert lo < 0.025 < 0.058 < hi < 0.12, cal_range
  short = wind.replace(
    bending_length=c, bending_length_sd=0.058 * c, bending_length_dof=DOF
  )
  assert calibration_tables.calibration_note(short)['matches']
  # a ruler's Gaussian reading quotes the ruler's modes; a depth reading of
  # another t law than the tables drew is told so
  for readings, mode in ((config, 'bending length (ruler)'),
                         (wind, 'known wind, bending length (ruler)')):  # fmt: skip
    ruler = readings.replace(bending_length=c, bending_length_sd=0.035 * c)
    note = calibration_tables.calibration_note(ruler)
    assert note['matches'] and note['mode'] == mode, note
    for field, cov in note['coverage'].items():
      for level, (lo, hi) in PAPER_BANDS.items():
        assert lo <= cov[level] <= hi, (mode, field, level, cov)
  other = wind.replace(
    bending_length=c, bending_length_sd=0.035 * c, bending_length_dof=4.0
  )
  (why,) = calibration_tables.calibration_note(other)['differs']
  assert why == (
    "bending length error law (Student's t, 4 degrees of freedom; calibrated: "
    "Student's t, 10 degrees of freedom)"
  )


def test_the_paper_tables_were_checked_on_another_physics_and_estimates_say_so(
  tmp_path,
):
  """The shipped paper-size tables on recordings of ``physsim.mismatch.WORLD``
  (fan off the normal, other gusts, drag, damping, softer edges), recorded by
  ``calibrate --check --install``: every mode held out, at least 50
  recordings, 90% intervals never under 85% and 50% intervals at least 40%
  over each mode's quantities as an estimate quotes them, its seeds pooled
  (wider is allowed, confidently wrong is not); a single 50% cell at least
  35%: on 56 recordings a 50% coverage is known to +-6.7 points (one binomial
  SE), and one seed alone has read 82% at 90% where the pool of four read 90%
  (docs/studies/calibration.md). An estimate's calibration line quotes the check of its
  own mode: with a wind reading, the check whose searches a reading steered
  (``--check_reading=wind_speed``) where the file has one, else the video
  searches' ``known wind`` reading."""
  config = EstimateConfig().replace(distance='shape')
  cal = json.load(open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE))
  mine = [c for c in cal['checks'] if c['physics'] == 'mismatched']
  checks = {c['searched']: c for c in mine}
  assert 'video' in checks and set(checks) <= {'video', 'known wind'}
  video = [c for c in mine if c['searched'] == 'video']
  assert len({c['seed'] for c in video}) == len(video)  # one check a seed
  for check in mine:
    assert check['n'] >= 50 and check['seed'] != cal['config']['seed']
  for mode in cal['recalibration']['modes']:
    assert all(mode in c['coverage'] for c in video), mode
    # what an estimate in this mode quotes: its seeds pooled
    (quoted,) = calibration_tables.quoted_checks(cal, mode)
    for field, cov in quoted['coverage'].items():
      assert cov['interval_90'] >= 0.85, (mode, field, cov)
      assert cov['interval_50'] >= 0.35, (mode, field, cov)
    cells = quoted['coverage'].values()
    assert np.mean([c['interval_50'] for c in cells]) >= 0.40, mode
  line = table_notes.calibration_line(calibration_tables.calibration_note(config))
  assert f'On {sum(c["n"] for c in video)} recordings of another physics' in line
  reading = dict(wind_speed=3.0, wind_speed_sd=0.06)
  (quoted,) = calibration_tables.calibration_note(config.replace(**reading))['checks']
  want = checks.get('known wind', checks['video'])['coverage']['known wind']
  assert quoted['coverage']['load_ratio'] == want['load_ratio']
  # a file with both: the steered searches' check is the one quoted
  both = _shipped_with_a_steered_check()
  steered = next(c for c in both['checks'] if c['searched'] == 'known wind')
  steered = json.loads(json.dumps(steered))
  steered['coverage']['known wind']['load_ratio']['interval_90'] = 0.8765
  both['checks'] = [steered] + [c for c in both['checks'] if c['searched'] == 'video']
  path = tmp_path / 'both.json'
  path.write_text(json.dumps(both))
  (quoted,) = calibration_tables.calibration_note(
    config.replace(calibration=str(path), **reading)
  )['checks']
  assert quoted['coverage']['load_ratio']['interval_90'] == 0.8765


def test_a_check_is_recorded_in_the_file_it_checked_and_replaced_by_a_rerun(tmp_path):
  path = str(tmp_path / 'cal.json')
  with open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE) as f:
    cal = {k: v for k, v in json.load(f).items() if k != 'checks'}
  with open(path, 'w') as f:
    json.dump(cal, f)
  cells = {f: {'interval_50': 0.5, 'interval_90': 0.9} for f in calibration.FIELDS}
  out = {
    'seed': 3, 'physics': 'mismatched', 'n': 10, 'printed_mode': 'video',
    'shipped': {'setting': cal['setting']},
    'printed': {f: {**c, 'interval_90': 0.7} for f, c in cells.items()},
    'modes': {'video': {f: dict(c) for f, c in cells.items()}},
  }  # fmt: skip
  record = calibration_check.check_record(out)
  # the video's coverage is what the estimates printed
  assert record['coverage']['video']['wind_speed']['interval_90'] == 0.7
  calibration_tables.record_check(path, record)
  calibration_tables.record_check(path, {**record, 'n': 12})  # the same check, rerun
  calibration_tables.record_check(path, {**record, 'seed': 4})  # another
  checks = json.load(open(path))['checks']
  assert [(c['seed'], c['n']) for c in checks] == [(3, 12), (4, 10)]
  with pytest.raises(ValueError, match='the check was of'):
    calibration_tables.record_check(path, {**record, 'setting': 'another calibration'})
  assert json.load(open(path))['checks'] == checks  # unchanged
  note = calibration_tables.calibration_note(
    EstimateConfig().replace(distance='shape', calibration=path)
  )
  # one per physics: its seeds pooled, each coverage the recordings' mean
  assert [(c['n'], c['seeds']) for c in note['checks']] == [(22, [3, 4])]
  line = table_notes.calibration_line(note)
  assert 'On 22 recordings of another physics' in line
  assert 'they held it in bending 70%/50%' in line
  other = json.loads(json.dumps(record))
  other['coverage']['video']['bending_scale']['interval_90'] = 1.0
  calibration_tables.record_check(path, {**other, 'seed': 5, 'n': 8})
  (pooled,) = calibration_tables.calibration_note(
    EstimateConfig().replace(distance='shape', calibration=path)
  )['checks']
  assert pooled['n'] == 30
  assert pooled['coverage']['bending_scale']['interval_90'] == pytest.approx(
    (22 * 0.7 + 8 * 1.0) / 30
  )
  assert pooled['coverage']['wind_speed']['interval_90'] == pytest.approx(0.7)


def test_a_check_of_refitted_modes_replaces_their_coverage_alone(tmp_path):
  """``calibrate --check --install --install_modes``: the named modes'
  coverage goes into the earlier check of the same recordings, which keeps
  what it measured of the other (unchanged) tables; with no such check, or
  a mode the check did not read, nothing is written."""
  path = str(tmp_path / 'cal.json')
  shipped = json.load(open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE))
  with open(path, 'w') as f:
    json.dump(shipped, f)
  earlier = next(c for c in shipped['checks'] if c['searched'] == 'video')
  cells = {f: {'interval_50': 0.123, 'interval_90': 0.9} for f in calibration.FIELDS}
  rerun = {**earlier, 'coverage': {m: cells for m in earlier['coverage']}}
  rerun.pop('rechecked', None)
  calibration_tables.record_check(path, rerun, ('bending length',))
  checks = json.load(open(path))['checks']
  mine = next(
    c for c in checks if c['searched'] == 'video' and c['seed'] == earlier['seed']
  )
  assert mine['coverage']['bending length'] == cells
  for mode in set(earlier['coverage']) - {'bending length'}:
    assert mine['coverage'][mode] == earlier['coverage'][mode], mode
  assert 'bending length' in mine['rechecked'] and len(checks) == len(shipped['checks'])
  before = open(path).read()
  for check, modes, message in (
    ({**rerun, 'seed': 9}, ('bending length',), 'no earlier check'),
    ({**rerun, 'coverage': {'video': cells}}, ('bending length',), 'did not read'),
  ):
    with pytest.raises(ValueError, match=message):
      calibration_tables.record_check(path, check, modes)
    assert open(path).read() == before


def _installing(tmp_path, monkeypatch, refit: dict, shipped: dict):
  """A workdir holding ``refit`` as its result and a copy of ``shipped`` that
  ``calibrate --install`` writes to (the study itself not run)."""
  workdir, dest = tmp_path / 'w', tmp_path / 'shipped.json'
  workdir.mkdir()
  (workdir / calibration.RESULT_FILE).write_text(json.dumps(refit))
  dest.write_text(json.dumps(shipped))
  monkeypatch.setattr(calibration_tables, 'shipped_calibration', lambda *a: str(dest))
  monkeypatch.setattr(calibration, 'run', lambda *a, **k: {})
  return workdir, dest


def _shipped_with_a_steered_check() -> dict:
  """The shipped paper-size file with a check of searches steered by a wind
  reading (what ``--check --check_reading=wind_speed --install`` records: the
  ``known wind`` mode's cells alone); where the file holds none, one is made
  of the video check's ``known wind`` cells, so that the install logic is
  tested against both kinds of check whatever the shipped file holds."""
  shipped = json.load(open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE))
  if not any(c['searched'] == 'known wind' for c in shipped['checks']):
    video = next(c for c in shipped['checks'] if c['searched'] == 'video')
    steered = {k: v for k, v in video.items() if k != 'rechecked'}
    steered.update(
      searched='known wind', coverage={'known wind': video['coverage']['known wind']}
    )
    shipped['checks'] = [steered, *shipped['checks']]
  return shipped


def test_a_refit_keeps_the_checks_of_the_tables_it_left_alone(tmp_path, monkeypatch):
  """``calibrate --install``: a refit that adds a mode keeps the shipped
  file's checks; one that moves a checked mode's table drops that check."""
  shipped = _shipped_with_a_steered_check()
  video_checks = [c for c in shipped['checks'] if c['searched'] == 'video']
  wind_check = next(c for c in shipped['checks'] if c['searched'] == 'known wind')
  refit = {k: v for k, v in shipped.items() if k != 'checks'}
  keep, drop = calibration_tables.still_valid_checks(shipped, refit)
  assert keep == shipped['checks'] and drop == []
  moved = json.loads(json.dumps(refit))
  moved['recalibration']['modes']['joint pair'][1][0] += (
    0.01  # a table the video check read
  )
  keep, drop = calibration_tables.still_valid_checks(shipped, moved)
  assert keep == [wind_check] and drop == video_checks  # every seed's
  other = {**refit, 'sharpness': 0.7}
  assert calibration_tables.still_valid_checks(shipped, other)[0] == []
  # the command: the refit's file installed with the checks it kept
  from experiments import calibrate

  workdir, dest = _installing(tmp_path, monkeypatch, moved, shipped)
  calibrate.main(calibrate.Args(workdir=str(workdir), install=True, analyse_only=True,
                                study=calibration.PRESETS['paper']))  # fmt: skip
  installed = json.load(open(dest))
  assert installed['checks'] == [wind_check]
  assert installed['recalibration'] == moved['recalibration']
  assert 'fabric_checks' not in installed  # the video checks it pooled are gone


def test_each_recordings_length_error_is_its_own_over_the_calibrated_range():
  """``length_sd_of``: a recording's simulated bending-length error, drawn
  from (seed, seq) alone, log-normal about ``length_sd`` with the reader's
  spread and inside ``length_sd_range``; no spread, every one the same."""
  config = calibration.PRESETS['paper']
  sds = np.array([calibration.length_sd_of(config, k) for k in range(4000)])
  lo, hi = calibration.length_sd_range(config)
  assert sds.min() >= lo * (1 - 1e-12) and sds.max() <= hi * (1 + 1e-12)
  assert np.median(sds) == pytest.approx(config.length_sd, rel=0.05)
  # the log error's spread: a standard normal's, clipped at 2.5 (0.99 of it)
  assert np.log(sds).std() == pytest.approx(0.99 * config.length_sd_spread, rel=0.06)
  assert calibration.length_sd_of(config, 7) == calibration.length_sd_of(config, 7)
  flat = dataclasses.replace(config, length_sd_spread=0.0)
  assert calibration.length_sd_of(flat, 7) == config.length_sd
  assert calibration.length_sd_range(flat) == (config.length_sd, config.length_sd)


def test_a_refit_of_some_modes_installs_their_tables_alone(tmp_path, monkeypatch):
  """``calibrate --install --install_modes``: the named modes' tables (and
  the readings they simulate) come from the refit, every other table and
  the checks that read only those stay as shipped; a mode the refit lacks,
  another setting, or the flag without --install are refused."""
  from experiments import calibrate

  shipped = _shipped_with_a_steered_check()
  refit = json.loads(json.dumps({k: v for k, v in shipped.items() if k != 'checks'}))
  for mode in refit['recalibration']['modes']:  # every table moved
    refit['recalibration']['modes'][mode][1][0] += 0.01
  refit['recalibration']['length_sd'] = 0.123
  refit['held_out']['bending length']['bending_scale']['interval_50'] = 0.4242
  modes = ('bending length', 'known wind, bending length')
  merged = calibration_tables.with_modes_of(shipped, refit, modes)
  rec, old = merged['recalibration'], shipped['recalibration']
  for mode in rec['modes']:
    want = refit if mode in modes else shipped
    assert rec['modes'][mode] == want['recalibration']['modes'][mode], mode
  assert rec['length_sd'] == 0.123 and set(modes) <= set(rec['refitted'])
  assert merged['held_out']['bending length']['bending_scale']['interval_50'] == 0.4242
  assert merged['held_out']['video'] == shipped['held_out']['video']
  assert old['length_sd'] != 0.123  # the shipped file's own dict untouched
  keep, drop = calibration_tables.still_valid_checks(shipped, merged)
  assert [c['searched'] for c in keep] == ['known wind']  # read no length table
  wind_check = keep[0]
  video_checks = [c for c in shipped['checks'] if c['searched'] == 'video']
  with pytest.raises(ValueError, match='another sharpness'):
    calibration_tables.with_modes_of(shipped, {**refit, 'sharpness': 0.7}, modes)
  lacking = json.loads(json.dumps(refit))
  del lacking['recalibration']['modes']['bending length']
  with pytest.raises(ValueError, match=r"no tables for \['bending length'\]"):
    calibration_tables.with_modes_of(shipped, lacking, modes)
  # the command
  workdir, dest = _installing(tmp_path, monkeypatch, refit, shipped)
  args = calibrate.Args(workdir=str(workdir), install=True, analyse_only=True,
                        install_modes='; '.join(modes),
                        study=calibration.PRESETS['paper'])  # fmt: skip
  calibrate.main(args)
  installed = json.load(open(dest))
  assert installed['recalibration'] == rec
  # the checks keep what they measured of the tables left as they were; the
  # refitted modes wait for --check --install_modes
  (kept_wind,) = [c for c in installed['checks'] if c['searched'] == 'known wind']
  assert kept_wind == wind_check
  kept = [c for c in installed['checks'] if c['searched'] == 'video']
  assert [c['seed'] for c in kept] == [c['seed'] for c in video_checks]
  for mine, video_check in zip(kept, video_checks, strict=True):
    assert set(mine['coverage']) == set(video_check['coverage']) - set(modes)
    for mode, cov in mine['coverage'].items():
      assert cov == video_check['coverage'][mode], mode
  # the video's tables unchanged, its checks kept: their pool by fabric too
  assert installed['fabric_checks'] == shipped['fabric_checks']
  for bad, message in (
    (dataclasses.replace(args, install_modes='bending'), r"no mode \['bending'\]"),
    (dataclasses.replace(args, install=False), 'give it with --install'),
  ):
    dest.write_text(json.dumps(shipped))
    with pytest.raises(ValueError, match=message):
      calibrate.main(bad)
    assert json.load(open(dest)) == shipped  # nothing written


def test_tables_fitted_with_a_model_error_apply_only_with_that_error(tmp_path):
  """A calibration fitted with the likelihood's discrepancy term: an estimate
  without it is told its intervals are indicative, naming the setting; one
  with it applies the tables. Files from before the term count as 0."""
  with open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE) as f:
    cal = json.load(f)
  cal['config']['estimate']['model_error'] = 0.5
  path = str(tmp_path / 'cal.json')
  with open(path, 'w') as f:
    json.dump(cal, f)
  config = EstimateConfig().replace(distance='shape', calibration=path)
  note = calibration_tables.calibration_note(config)
  assert not note['matches'] and 'model_error' in note['differs']
  assert calibration_tables.calibration_note(config.replace(model_error=0.5))['matches']
  del cal['config']['estimate']['model_error']
  with open(path, 'w') as f:
    json.dump(cal, f)
  assert calibration_tables.calibration_note(config)['matches']
  assert not calibration_tables.calibration_note(config.replace(model_error=0.5))[
    'matches'
  ]


def _wilson_upper(k: int, n: int, z: float = 1.959964) -> float:
  """Wilson's 95% upper bound, by its formula (the reference for
  ``bo.calibration.binomial_interval``'s)."""
  p = k / n
  centre = p + z * z / (2 * n)
  spread = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
  return (centre + spread) / (1 + z * z / n)


def test_an_estimate_quotes_its_own_fabrics_coverage_and_says_where_it_fell_short(
  tmp_path,
):
  """``pooled_check``'s pool of two seeds' checks, kept by fabric in the
  calibration file (``calibration_tables.record_fabric_checks``): an estimate of a fabric
  whose wind intervals held 11 times in 16 on the other physics quotes its
  own coverage beside the pooled one and calls them too narrow (Wilson's upper
  bound 0.89 < 0.9); a fabric that held 16 in 16 is quoted without it. A pool
  of other checks, of another calibration, or whose checks were replaced, is
  refused or not quoted; nothing is written on a refusal."""
  from benchmarks import pooled_check

  shipped = json.load(open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE))
  cal = {k: v for k, v in shipped.items() if k not in ('checks', 'fabric_checks')}
  path = str(tmp_path / 'cal.json')
  with open(path, 'w') as f:
    json.dump(cal, f)
  cells = {f: {'interval_50': 0.5, 'interval_90': 0.9} for f in calibration.FIELDS}

  def fabrics(held90):
    short = {'interval_50': 0.5, 'interval_90': held90}
    return {
      'white_tablecloth': {'n': 8, **cells, 'wind_speed': short},
      'black_denim': {'n': 8, **{q: {**c, 'interval_90': 1.0} for q, c in cells.items()}},
    }  # fmt: skip

  docs = []
  for seed, held in ((1, 6 / 8), (2, 5 / 8)):
    cell = {**cells['wind_speed'], 'point_error_pct': 5.0, 'centre_error_pct': 50.0,
            'point_error_factor': 1.1, 'centre_error_factor': 3.0}  # fmt: skip
    docs.append({
      'seed': seed, 'n': 16, 'physics': 'mismatched',
      'shipped': {'setting': cal['setting']}, 'config': {'estimate': {'q': 40}},
      'modes': {'video': {**{q: cell for q in pooled_check.FIELDS},
                          'by_material': fabrics(held)}},
    })  # fmt: skip
    record = {'physics': 'mismatched', 'seed': seed, 'searched': 'video', 'n': 16,
              'setting': cal['setting'], 'coverage': {'video': cells}}  # fmt: skip
    calibration_tables.record_check(path, record)
  files = []
  for d in docs:
    files.append(str(tmp_path / f'check{d["seed"]}.json'))
    with open(files[-1], 'w') as f:
      json.dump(d, f)
  pool = pooled_check.pool_checks(files)
  before = open(path).read()
  for bad, message in (
    ({**pool, 'calibration': 'another'}, 'the pool was of'),
    ({**pool, 'seeds': [1, 3]}, 'record those checks first'),
    ({**pool, 'modes': {}}, 'no .video. coverage by fabric'),
  ):
    with pytest.raises(ValueError, match=message):
      calibration_tables.record_fabric_checks(path, bad)
    assert open(path).read() == before
  calibration_tables.record_fabric_checks(
    path, pool
  )  # 0.9 of a seed's 8 counts 7: 88% of 16
  calibration_tables.record_fabric_checks(path, pool)  # the same pool again: replaced
  assert len(json.load(open(path))['fabric_checks']) == 1
  config = EstimateConfig().replace(distance='shape', calibration=path)
  white = calibration_tables.calibration_note(
    config.replace(material='white_tablecloth')
  )
  (quoted,) = white['checks']
  mine = quoted['this_fabric']
  assert mine['n'] == 16 and mine['coverage']['wind_speed']['interval_90'] == 11 / 16
  assert _wilson_upper(11, 16) < 0.9 and mine['short'] == ['wind_speed']
  line = table_notes.calibration_line(white)
  assert (
    'This fabric alone (white tablecloth, 16 of them): bending 88%/50%, wind 69%/50%'
    in line
  )
  assert 'Its wind 90% intervals held the truth less often than promised' in line
  denim = calibration_tables.calibration_note(config.replace(material='black_denim'))
  assert denim['checks'][0]['this_fabric']['short'] == []
  assert 'too narrow' not in table_notes.calibration_line(denim)
  assert (
    'this_fabric'
    not in calibration_tables.calibration_note(config.replace(material='pink_nylon'))[
      'checks'
    ][0]
  )
  # a check pooled there rerun on more recordings: the pool is no longer of them
  calibration_tables.record_check(path, {**record, 'n': 24})
  assert (
    'this_fabric'
    not in calibration_tables.calibration_note(
      config.replace(material='white_tablecloth')
    )['checks'][0]
  )
  checks = json.load(open(path))['checks']
  assert (
    calibration_tables.pools_of(json.load(open(path))['fabric_checks'], checks[:1])
    == []
  )


def test_the_shipped_file_quotes_each_fabric_its_own_coverage_on_another_physics():
  """Every fabric of the shipped paper-size file has its own coverage of the
  pooled video checks, of exactly their recordings; its shortfalls are the
  cells whose Wilson upper bound, by hand from their counts, is under 90%."""
  cal = json.load(open(calibration_tables.SHAPE_PAPER_CALIBRATION_FILE))
  (pool,) = cal['fabric_checks']
  video = [
    c
    for c in cal['checks']
    if c['searched'] == 'video' and c['physics'] == pool['physics']
  ]
  assert pool['seeds'] == sorted(c['seed'] for c in video)
  assert pool['n'] == sum(c['n'] for c in video)
  by = pool['coverage']['video']
  assert (
    set(by) == set(physsim.FABRICS) and sum(v['n'] for v in by.values()) == pool['n']
  )
  for material in physsim.FABRICS:
    config = EstimateConfig().replace(distance='shape', material=material)
    (quoted,) = calibration_tables.calibration_note(config)['checks']
    mine = quoted['this_fabric']
    n = by[material]['n']
    want = [q for q, v in by[material].items() if q != 'n'
            and _wilson_upper(round(v['interval_90'] * n), n) < 0.9]  # fmt: skip
    assert mine['short'] == want, material


def test_the_50pct_half_width_is_read_beside_the_median():
  """Posteriors uniform on median x (1 -+ h): the 50% interval's half-width
  is h / 2 of the median (worked by hand), the median over recordings."""
  space = physsim.search_space('gray_interlock')
  grid = np.linspace(0.0, 1.0, 1001)[:, None]
  scores = []
  for k, h in enumerate((0.1, 0.2, 0.4)):
    centre = np.array([2.0, 3.0, 0.2, 1.5]) * (1 + k)  # per field
    qf = centre * (1 - h + 2 * h * grid)  # (1001, fields): uniform quantiles
    scores.append({'truth': centre, 'qf': qf, 'rank': np.full(4, 0.5)})
  cell = calibration.summarise(scores, space, bayes=False)
  for f in calibration.FIELDS:  # a log-scaled field: half the log width
    log = f in calibration_scores.LOG_FIELDS
    want = math.log(1.1 / 0.9) / 2 if log else 0.2 / 2
    assert cell[f]['half_width_50'] == pytest.approx(want, rel=1e-3), f
  out = {'held_out': {'video': cell}}
  (line,) = [
    x for x in calibration_report._half_width_line(out['held_out']['video']) if x
  ]
  assert 'wind_speed 10.0%' in line and 'bending_scale x1.11' in line


def test_recordings_are_grouped_by_where_their_wind_lies_in_the_prior():
  """Thirds of the fabric's 1-6 m/s: 2.66 is the lowest, 2.7 the middle, 6
  (the box's top) the highest; a group's coverage is its own recordings'."""
  space = physsim.search_space('gray_interlock')
  assert space.wind_speed == (1.0, 6.0)
  grid = np.linspace(0.0, 1.0, 1001)[:, None]
  held = []
  for wind, inside in ((2.66, True), (2.7, False), (4.0, True), (6.0, True)):
    truth = np.array([1.0, wind, 0.2, 1.0])
    centre = truth if inside else truth * 2  # this one's 50% interval misses
    held.append({'truth': truth, 'qf': centre * (0.8 + 0.4 * grid),
                 'rank': np.full(4, 0.5), 'material': 'gray_interlock',
                 'prior_point': truth})  # fmt: skip
  bands = [calibration_analysis.wind_band(s, space) for s in held]
  assert bands == [0, 1, 1, 2]
  by = calibration_analysis.by_wind_place(held, space)
  assert list(by) == ['lowest third', 'middle third', 'highest third']
  assert by['middle third']['n'] == 2
  assert by['middle third']['wind_speed']['interval_50'] == 0.5
  assert by['lowest third']['wind_speed']['interval_50'] == 1.0
