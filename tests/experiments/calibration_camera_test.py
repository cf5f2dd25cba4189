"""Calibration for estimates that carry the intake's alignment error.

An estimate of a user's recording carries the camera's placement error in
its posterior (``camera_sd_m`` / ``camera_sd_deg``). A calibration study
whose estimates carry one tells each recording's estimate a camera displaced
from the true one by an error of that size (``told_pose``); its tables
apply to estimates carrying an error within a factor of two of theirs, and
an estimate no table covers is told which error is outside and what the
tables were measured at.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest

import physsim
from experiments.pipeline import (
  calibration_tables,
  carried_errors,
  estimation,
  table_notes,
)
from experiments.pipeline import datasets as gen
from experiments.pipeline import recording as recording_lib
from experiments.pipeline import simulation as simulation_lib
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import calibration, calibration_analysis

STUDY = calibration.PRESETS['paper']
POSE = physsim.Pose(
  np.eye(3)[:, [0, 2, 1]] * np.array([1.0, -1.0, 1.0]), np.array([0.1, -2.0, 1.2])
)
DRAWS = 2000


def _told(
  sd_m: float, sd_deg: float, seed: int = 0, n: int = DRAWS
) -> list[physsim.Pose]:
  est = calibration.study_configs(STUDY)[3].replace(
    camera_sd_m=sd_m, camera_sd_deg=sd_deg
  )
  study = dataclasses.replace(STUDY, seed=seed)
  return [calibration.told_pose(study, est, POSE, seq) for seq in range(n)]


def _tilt_deg(rotation: np.ndarray) -> np.ndarray:
  """The axis-angle vector (degrees) of a rotation (small angles)."""
  r = rotation @ POSE.rotation.T
  w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2
  angle = np.arcsin(np.clip(np.linalg.norm(w), 0.0, 1.0))
  return np.degrees(w / max(np.linalg.norm(w), 1e-12) * angle)


def test_the_told_camera_is_shifted_with_the_named_sd():
  told = _told(0.03, 0.0)
  shift = np.stack([t.position for t in told]) - POSE.position  # (DRAWS, 3)
  # 2,000 draws know an sd to about 1.6% (1 sd): 10% is six of those
  np.testing.assert_allclose(shift.std(0), 0.03, rtol=0.1)
  np.testing.assert_allclose(shift.mean(0), 0.0, atol=0.005)
  for t in told[:5]:  # a shift alone: the camera looks the same way
    np.testing.assert_allclose(t.rotation, POSE.rotation, atol=1e-6)


def test_the_told_camera_is_tilted_about_the_pins_with_the_named_sd():
  told = _told(0.0, 2.0)
  tilt = np.stack([_tilt_deg(np.asarray(t.rotation, np.float64)) for t in told])
  np.testing.assert_allclose(tilt.std(0), 2.0, rtol=0.1)
  np.testing.assert_allclose(tilt.mean(0), 0.0, atol=0.3)
  # turned about the estimate's pins: the camera keeps its distance to them
  pins = simulation_lib.pin_centre(calibration.study_configs(STUDY)[3].simulation)
  far = np.linalg.norm(POSE.position - pins)
  for t in told[:20]:
    assert abs(np.linalg.norm(t.position - pins) - far) < 1e-5


def test_each_recordings_camera_error_is_its_own_and_from_the_seed():
  a, again, other = (
    _told(0.03, 2.0, n=50),
    _told(0.03, 2.0, n=50),
    _told(0.03, 2.0, 1, 50),
  )
  for x, y in zip(a, again, strict=True):  # explicit keys: the same each time
    np.testing.assert_array_equal(x.position, y.position)
  positions = np.stack([t.position for t in a])
  assert len({tuple(p) for p in positions.round(9)}) == 50  # each its own
  assert not np.allclose(positions, np.stack([t.position for t in other]))
  # an estimate that trusts its camera is told the true one
  exact = calibration.study_configs(STUDY)[3]
  assert calibration.told_pose(STUDY, exact, POSE, 3) is POSE


@pytest.mark.parametrize(
  ('mine', 'covered'),
  [(0.03, True), (0.02, True), (0.05, True), (0.015, True), (0.06, True),
   (0.07, False), (0.014, False), (0.0, False)],
)  # fmt: skip
def test_a_table_covers_a_camera_error_within_a_factor_of_two(mine, covered):
  assert carried_errors.covers(0.03, mine) is covered
  cal = {'sharpness': 0.5, 'config': {'estimate': {
    **EstimateConfig().flat(), 'camera_sd_m': 0.03, 'camera_sd_deg': 2.0}}}  # fmt: skip
  config = EstimateConfig().replace(camera_sd_m=mine, camera_sd_deg=2.0)
  differs = calibration_tables.differing_fields(config, cal)
  assert ('camera_sd_m' not in differs) is covered, differs


def test_exact_cameras_match_only_exact_tables():
  assert carried_errors.covers(0.0, 0.0)
  assert not carried_errors.covers(0.0, 0.01)
  assert not carried_errors.covers(2.0, 0.0)  # tilted tables: an exact tilt is not


SPREAD = math.log(3.0)  # each component from a third to three times the centre


def test_each_recordings_camera_error_size_is_drawn_over_the_range():
  study = dataclasses.replace(STUDY, camera_sd_spread=SPREAD)
  est = calibration.study_configs(STUDY)[3].replace(camera_sd_m=0.03, camera_sd_deg=2.0)
  sds = np.array([calibration.camera_sd_of(study, est, seq) for seq in range(DRAWS)])
  u = np.log(sds / [0.03, 2.0]) / SPREAD  # uniform in [-1, 1], per component
  assert np.all(np.abs(u) <= 1 + 1e-4)
  # 2,000 uniform draws: the mean within 0.026 (2 sd), the sd 1/sqrt(3)
  np.testing.assert_allclose(u.mean(0), 0.0, atol=0.03)
  np.testing.assert_allclose(u.std(0), 1 / math.sqrt(3), rtol=0.05)
  assert abs(np.corrcoef(u.T)[0, 1]) < 0.1  # shift and tilt drawn apart
  again = calibration.camera_sd_of(study, est, 7)
  assert again == tuple(sds[7]) != calibration.camera_sd_of(study, est, 8)
  assert calibration.camera_sd_of(STUDY, est, 7) == (0.03, 2.0)  # no spread


def test_recordings_fall_in_thirds_of_the_camera_error_range_by_their_draw():
  study = dataclasses.replace(STUDY, camera_sd_spread=SPREAD)
  est = calibration.study_configs(study)[3]
  study = dataclasses.replace(
    study, estimate=est.replace(camera_sd_m=0.03, camera_sd_deg=2.0)
  )
  est = calibration.study_configs(study)[3]
  for seq in range(300):
    m, deg = calibration.camera_sd_of(study, est, seq)
    place = (math.log(m / 0.03) + math.log(deg / 2.0)) / 2 / SPREAD  # -1 .. 1
    want = 0 if place < -1 / 3 else 1 if place < 1 / 3 else 2
    assert calibration_analysis.camera_band(study, seq) == want, (seq, place)


def test_a_camera_spread_the_estimate_cannot_carry_is_refused():
  est = calibration.study_configs(STUDY)[3]
  for spread, sd, match in (
    (2.5, (0.03, 2.0), 'in .0, 2.'),
    (1.0, (0.0, 0.0), 'no camera error to spread'),
    (2.0, (0.03, 3.0), 'reaches 22.2 cm / 22.2 deg'),
  ):
    study = dataclasses.replace(
      STUDY,
      camera_sd_spread=spread,
      estimate=est.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1]),
    )
    with pytest.raises(ValueError, match=f'--camera_sd_spread={spread}: .*{match}'):
      calibration.check_config(study)


def _write(path, config: EstimateConfig, setting: str, spread: float = 0.0) -> None:
  path.write_text(json.dumps({
    'n': 4, 'setting': setting, 'sharpness': 0.5,
    'coverage': {'wind_speed': {'interval_90': 0.9, 'interval_50': 0.5}},
    'config': {'estimate': config.flat(), 'camera_sd_spread': spread},
  }))  # fmt: skip


def _exact_tables(tmp_path, monkeypatch) -> EstimateConfig:
  """The shape distance's paper-size tables at exact cameras, in ``tmp_path``
  (where the tables beside them go), and its estimate's settings."""
  base = tmp_path / 'calibration_shape_paper.json'
  monkeypatch.setattr(calibration_tables, 'SHAPE_PAPER_CALIBRATION_FILE', str(base))
  monkeypatch.setattr(
    calibration_tables, 'SHAPE_CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  config = EstimateConfig().replace(distance='shape')
  _write(base, config, 'exact cameras')
  return config


@pytest.fixture
def shipped(tmp_path, monkeypatch):
  """Paper-size shape tables at exact cameras, 2 cm / 2 deg and 4 cm / 3 deg."""
  config = _exact_tables(tmp_path, monkeypatch)
  for sd in ((0.02, 2.0), (0.04, 3.0)):
    path = calibration_tables.shipped_calibration('shape', 'paper', sd)
    assert os.path.dirname(path) == str(tmp_path)
    _write(
      tmp_path / os.path.basename(path),
      config.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1]),
      f'cameras off by {carried_errors.camera_words(sd)}',
    )
  return config


def test_an_estimate_quotes_the_nearest_table_that_covers_its_camera_error(shipped):
  for sd, setting in (
    ((0.0, 0.0), 'exact cameras'),
    ((0.015, 1.5), 'cameras off by 2 cm / 2 deg'),
    ((0.025, 2.0), 'cameras off by 2 cm / 2 deg'),
    ((0.035, 3.0), 'cameras off by 4 cm / 3 deg'),
    ((0.08, 6.0), 'cameras off by 4 cm / 3 deg'),
  ):
    config = shipped.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    note = calibration_tables.calibration_note(config)
    assert note['matches'] and note['setting'] == setting, (sd, note)
    assert 'indicative' not in table_notes.calibration_line(note)


def test_an_error_no_table_covers_is_named_with_what_the_tables_measured(shipped):
  # the intake's widest claims: 8.5 cm, and a tilt past every table's
  for sd in ((0.085, 3.0), (0.03, 7.0), (0.0, 2.0)):
    config = shipped.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    note = calibration_tables.calibration_note(config)
    assert not note['matches'], note
    (why,) = note['differs']
    assert why == (
      f'camera alignment error {carried_errors.camera_words(sd)}, 1 sd (tables '
      'measured at exact cameras; 2 cm / 2 deg; 4 cm / 3 deg; each holds from half '
      'to twice its own)'
    )
    line = table_notes.calibration_line(note)
    assert 'indicative' in line and carried_errors.camera_words(sd) in line, line
  assert carried_errors.camera_words((0.085, 3.0)) == '8.5 cm / 3 deg'
  assert carried_errors.camera_difference((0.0, 0.0), [(0.02, 2.0)]) == (
    'camera known exactly (tables measured at 2 cm / 2 deg; each holds from half '
    'to twice its own)'
  )


@pytest.fixture
def ranged(shipped, tmp_path):
  """``shipped``'s tables and one drawn per recording over 1-9 cm and 0.67-6
  deg (3 cm / 2 deg, each a third to three times)."""
  path = calibration_tables.shipped_calibration('shape', 'paper', (0.03, 2.0), SPREAD)
  assert path.endswith('calibration_shape_paper_camera_1-9cm_0.67-6deg.json')
  config = shipped.replace(camera_sd_m=0.03, camera_sd_deg=2.0)
  _write(tmp_path / os.path.basename(path), config, 'cameras off by a range', SPREAD)
  return shipped


def test_a_table_drawn_over_a_range_covers_every_error_in_it(ranged):
  # inside the range, outside the levels' factor of two: its tables
  for sd in ((0.012, 0.7), (0.085, 1.0), (0.09, 6.0), (0.011, 5.9)):
    note = calibration_tables.calibration_note(
      ranged.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    )
    assert note['matches'] and note['setting'] == 'cameras off by a range', sd
  # where a level covers it too, the nearest centre: the level's
  note = calibration_tables.calibration_note(
    ranged.replace(camera_sd_m=0.04, camera_sd_deg=3.0)
  )
  assert note['setting'] == 'cameras off by 4 cm / 3 deg'
  # outside the range and every level: named with both kinds of tables
  (why,) = calibration_tables.calibration_note(
    ranged.replace(camera_sd_m=0.12, camera_sd_deg=1.0)
  )['differs']
  assert why == (
    'camera alignment error 12 cm / 1 deg, 1 sd (tables measured at exact cameras; '
    '2 cm / 2 deg; 1-9 cm / 0.67-6 deg; 4 cm / 3 deg; each holds from half to twice '
    'its own)'
  )


@pytest.mark.parametrize('mine', [(0.03, 2.0), (0.012, 4.0), (0.05, 0.5), (0.2, 2.0)])
def test_recordings_gap_is_the_mean_log_distance_to_the_tables_draws(mine):
  # the mean |log ratio| to errors drawn as the study draws them (centre x
  # exp(spread u), u uniform in [-1, 1]), by the midpoint rule on a fine grid
  table = (0.03, 2.0, 1.1)
  u = (np.arange(200_000) + 0.5) / 100_000 - 1.0
  want = sum(
    np.mean(np.abs(np.log(x / (c * np.exp(table[2] * u)))))
    for c, x in zip(table[:2], mine, strict=True)
  )
  assert carried_errors.recordings_gap(table, mine) == pytest.approx(want, rel=1e-6)
  # one error for every recording: camera_gap's
  assert carried_errors.recordings_gap(table[:2], mine) == pytest.approx(
    carried_errors.camera_gap(table[:2], mine)
  )


def test_an_estimate_quotes_the_table_whose_recordings_were_most_like_it(
  tmp_path, monkeypatch
):
  """Two ranged tables cover 3 cm / 2 deg: one of 1-9 cm centred on it, one of
  1-4 cm off its centre; the narrow one's recordings were more like it."""
  config = _exact_tables(tmp_path, monkeypatch)
  for sd, spread, name in (((0.03, 2.0), SPREAD, 'wide'), ((0.02, 1.6), 0.7, 'narrow')):
    path = calibration_tables.shipped_calibration('shape', 'paper', sd, spread)
    mine = config.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    _write(tmp_path / os.path.basename(path), mine, name, spread)
  for sd, setting in (((0.03, 2.0), 'narrow'), ((0.015, 1.0), 'narrow'),
                      ((0.05, 2.0), 'wide'), ((0.03, 4.0), 'wide')):  # fmt: skip
    note = calibration_tables.calibration_note(
      config.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    )
    assert note['matches'] and note['setting'] == setting, (sd, note['setting'])


# A paper-size study's structure at the smallest size a CPU runs in a minute
# or two (as calibration_fabrics_test's), its estimates carrying 3 cm / 2 deg,
# each recording its own error within exp(+-0.5) of that.
TINY = calibration.Config(
  size='paper', pairs=2, folds=2, backend='c', sharpness_grid=(0.5,), batch_size=4,
  camera_sd_spread=0.5,
  estimate=EstimateConfig().replace(
    distance='shape', cloth_resolution=8, frames=8, warmup=0.25, q=2, n_init=4,
    max_iter=1, posterior_grid=(4, 8, 4), camera_sd_m=0.03, camera_sd_deg=2.0,
  ),
)  # fmt: skip
TINY_RECORDINGS = dataclasses.replace(
  gen.PRESETS['eval'], frames=8, cloth_resolution=10, resolution=32, timestep=1 / 240
)


@pytest.mark.slow
def test_a_study_carrying_a_camera_error_runs_and_records_it(tmp_path, monkeypatch):
  monkeypatch.setitem(gen.PRESETS, 'eval', TINY_RECORDINGS)
  true, jobs = {}, []
  load, estimate_many = recording_lib.load_recordings, estimation.estimate_many

  def loaded(paths, **kw):  # the recordings as filmed
    recs = load(paths, **kw)
    true.update((r.source, r) for r in recs)
    return recs

  def estimated(batch, **kw):  # ... and as their estimates are told
    jobs.extend(batch)
    return estimate_many(batch, **kw)

  monkeypatch.setattr(recording_lib, 'load_recordings', loaded)
  monkeypatch.setattr(estimation, 'estimate_many', estimated)
  out = calibration.run(TINY, str(tmp_path))
  assert out['n'] == 4 and len(jobs) == 4
  centre = calibration.study_configs(TINY)[3]
  carried = set()
  for job in jobs:
    pose, seq = true[job.recording.source].pose, int(os.path.basename(job.workdir))
    sd = carried_errors.camera_of(job.config.flat())  # its own, drawn for it
    assert sd == calibration.camera_sd_of(TINY, centre, seq)
    assert all(
      carried_errors.covers(c, m, 0.5) for c, m in zip((0.03, 2.0), sd, strict=True)
    )
    carried.add(sd)
    told = calibration.told_pose(TINY, job.config, pose, seq)
    np.testing.assert_array_equal(job.recording.pose.position, told.position)
    assert 0 < np.linalg.norm(told.position - pose.position) < 0.5
  assert len(carried) == 4
  with open(os.path.join(tmp_path, 'calibration.md')) as f:
    assert 'recordings by the camera error each carried' in f.read()
  words = carried_errors.table_words((0.03, 2.0, 0.5))
  assert words == '1.8-4.9 cm / 1.2-3.3 deg'
  assert f'cameras off by {words} (1 sd, each recording its own)' in out['setting']
  assert carried_errors.table_of(out) == (0.03, 2.0, 0.5)
  # the same estimates read again with tables of the width alone: every
  # mode's levels symmetric about the median, and the setting says so
  cen = calibration.run(
    dataclasses.replace(TINY, centred_levels=True), str(tmp_path), analyse_only=True
  )
  assert cen['setting'] == out['setting'] + ', levels centred on the median'
  for table in cen['recalibration']['modes'].values():
    lv = np.asarray(table)
    np.testing.assert_allclose(lv + lv[::-1], 1.0, atol=1e-12)
  with open(os.path.join(tmp_path, calibration.RESULT_FILE)) as f:
    assert json.load(f)['setting'] == cen['setting']
  out = calibration.run(TINY, str(tmp_path), analyse_only=True)  # back to shifts
  # installed beside the exact cameras' tables, it is what such estimates quote
  base = tmp_path / 'shipped' / 'calibration_shape_paper.json'
  monkeypatch.setattr(calibration_tables, 'SHAPE_PAPER_CALIBRATION_FILE', str(base))
  monkeypatch.setattr(
    calibration_tables, 'SHAPE_CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  dest = calibration_tables.shipped_calibration('shape', 'paper', (0.03, 2.0), 0.5)
  assert dest == str(base).removesuffix('.json') + '_camera_1.8-4.9cm_1.2-3.3deg.json'
  os.makedirs(os.path.dirname(dest))
  with open(os.path.join(tmp_path, calibration.RESULT_FILE)) as f, open(dest, 'w') as g:
    g.write(f.read())
  est = calibration.study_configs(TINY)[3].replace(point='bayes')
  for sd in ((0.03, 2.0), (0.045, 1.3), (0.02, 3.2)):
    mine = est.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    assert calibration_tables.calibration_file(mine) == dest
    assert calibration_tables.calibration_note(mine)['matches'], sd
  for sd in ((0.0, 0.0), (0.055, 2.0)):  # exact, or past the range drawn
    mine = est.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
    assert not calibration_tables.calibration_note(mine)['matches'], sd
