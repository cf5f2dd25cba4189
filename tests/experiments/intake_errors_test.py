"""Calibration tables whose cameras are off as the intake actually errs.

The intake claims more alignment error than it makes
(``benchmarks.alignment_error``), so tables whose recordings' cameras are
displaced by the full claim are too wide at 50% for its estimates. With
``--camera_errors`` the calibration study puts a measured intake's actual
error (in its camera's frame) on each recording's camera and lets the
estimate carry that intake's claim; such tables hold for the intake's own
claims (``Scoring.camera_sd_from='intake'``) and never for an error a user
gave.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import types

import numpy as np
import pytest

import physsim
from benchmarks import alignment_error
from experiments.pipeline import (
  calibration_tables,
  carried_errors,
  resume,
  table_notes,
  user_recordings,
)
from experiments.pipeline import simulation as simulation_lib
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import (
  calibration,
  calibration_config,
  calibration_report,
  told_cameras,
)
from tests.experiments.calibration_camera_test import _write  # one table file

PINS = simulation_lib.pin_centre(EstimateConfig().simulation)
# Two cameras looking at the cloth from different sides.
POSES = (
  physsim.camera.look_at(np.array([0.3, -1.6, 1.4]), PINS - np.array([0, 0, 0.4])),
  physsim.camera.look_at(np.array([-0.9, -1.1, 0.9]), PINS - np.array([0, 0, 0.5])),
)
TOL = 1e-4  # float32 poses: metres and radians


def _row(i: int, rng) -> dict:
  shift = rng.normal(0, 0.02, 3)
  rot = np.radians(rng.normal(0, 0.6, 3))
  return {
    'wind': 3.0, 'seed': i, 'mode': 'world_up',
    'sd_m': 0.03 + 0.01 * i, 'sd_deg': 1.5 + 0.5 * i,
    'shift_m': float(np.linalg.norm(shift)),
    'rotation_deg': float(np.degrees(np.linalg.norm(rot))),
    'shift_camera_m': shift.tolist(), 'rotation_camera_rad': rot.tolist(),
  }  # fmt: skip


@pytest.fixture
def errors_file(tmp_path):
  rng = np.random.default_rng(0)
  rows = [_row(i, rng) for i in range(9)] + [{'wind': 4.5, 'seed': 9, 'refused': 'x'}]
  path = tmp_path / 'intake_errors.json'
  path.write_text(json.dumps({'rows': rows}))
  return str(path)


def test_a_measured_error_put_on_a_camera_is_read_back_in_its_frame(errors_file):
  """``intake_pose`` against the benchmark's own (float64 NumPy) split of a
  placement into a rotation about the pins and a shift."""
  for e in told_cameras.read_intake_errors((errors_file,))[:4]:
    moved = []
    for pose in POSES:
      told = told_cameras.intake_pose(pose, e, PINS)
      shift, rot = alignment_error.placement_vectors(told, pose, PINS)
      np.testing.assert_allclose(shift, e.shift, atol=TOL)
      np.testing.assert_allclose(rot, e.rotation, atol=TOL)
      moved.append(np.asarray(told.position) - np.asarray(pose.position))
    # the same error in each camera's frame moves the two cameras differently
    assert np.linalg.norm(moved[0] - moved[1]) > 1e-3


def test_the_errors_file_is_read_or_refused_by_name(errors_file, tmp_path):
  errors = told_cameras.read_intake_errors((errors_file,))
  assert len(errors) == 9  # the refused intake is no error
  assert errors[2].claim == (0.05, 2.5)
  old = tmp_path / 'old.json'  # a file from before the vectors were recorded
  rows = json.loads(open(errors_file).read())['rows']
  old.write_text(json.dumps({'rows': [
    {k: v for k, v in r.items() if k != 'shift_camera_m'} for r in rows
  ]}))  # fmt: skip
  with pytest.raises(ValueError, match=f'{old}: a row without the error vectors'):
    told_cameras.read_intake_errors((str(old),))
  with pytest.raises(ValueError, match='missing.json: no alignment errors'):
    told_cameras.read_intake_errors((str(tmp_path / 'missing.json'),))
  few = tmp_path / 'few.json'
  few.write_text(json.dumps({'rows': rows[:3]}))
  with pytest.raises(ValueError, match='3 placed intakes .* at least 8'):
    told_cameras.read_intake_errors((str(few),))
  bad = tmp_path / 'bad.json'
  bad.write_text(json.dumps({'rows': [{**rows[0], 'sd_m': 0.0}] + rows[1:]}))
  with pytest.raises(ValueError, match='bad.json: a row out of range'):
    told_cameras.read_intake_errors((str(bad),))


def _study(errors_file, **fields):
  return calibration.with_intake_errors(
    dataclasses.replace(
      calibration.PRESETS['paper'], camera_errors=(errors_file,), **fields
    )
  )


def test_each_recording_carries_a_measured_intakes_claim_and_is_off_as_it_erred(
  errors_file,
):
  study = _study(errors_file)
  est = calibration.study_configs(study)[3]
  assert est.scoring.camera_sd_from == 'intake'
  errors = told_cameras.read_intake_errors((errors_file,))
  m, deg, spread = carried_errors.table_of(
    {'config': calibration_config.estimate_record(study, est)}
  )
  assert spread == study.camera_sd_spread > 0
  lo = np.array([min(e.claim[k] for e in errors) for k in (0, 1)]) * math.exp(-0.25)
  hi = np.array([max(e.claim[k] for e in errors) for k in (0, 1)]) * math.exp(0.25)
  for c, lo_k, hi_k in zip(
    (m, deg), lo, hi, strict=True
  ):  # the range: inside the draws
    a, b = carried_errors.spread_range(c, spread)
    assert lo_k * (1 - 1e-6) <= a < b <= hi_k * (1 + 1e-6)
  used = set()
  for seq in range(40):
    claim = calibration.camera_sd_of(study, est, seq)
    assert claim == calibration.camera_sd_of(study, est, seq)  # from (seed, seq)
    (e,) = [
      e for e in errors
      if all(abs(math.log(c / o)) <= 0.25 + 1e-6 for c, o in zip(claim, e.claim, strict=True))
      and np.allclose(
        alignment_error.placement_vectors(
          calibration.told_pose(study, est, POSES[0], seq), POSES[0], PINS
        )[0], e.shift, atol=TOL)
    ]  # fmt: skip
    used.add(e)
  assert len(used) >= 6  # drawn over the measured intakes


def test_camera_errors_beside_a_given_error_or_jitter_out_of_range_are_refused(
  errors_file,
):
  with pytest.raises(ValueError, match='drop --camera_sd_m'):
    _study(errors_file, camera_sd_spread=0.5)
  with pytest.raises(ValueError, match='--camera_errors_jitter=2.0'):
    _study(errors_file, camera_errors_jitter=2.0)
  assert _study(errors_file) == calibration.with_intake_errors(_study(errors_file))
  study = _study(errors_file)
  words = calibration_report._camera_text(study)
  assert words.startswith(', cameras off as 9 measured intakes erred')


@pytest.fixture
def shipped(tmp_path, monkeypatch):
  """Paper-size shape tables: exact cameras, a range displaced by the full
  claim (1-9 cm / 0.67-6 deg) and one displaced as the intake errs (2-8 cm
  / 1-4 deg)."""
  base = tmp_path / 'calibration_shape_paper.json'
  monkeypatch.setattr(calibration_tables, 'SHAPE_PAPER_CALIBRATION_FILE', str(base))
  monkeypatch.setattr(
    calibration_tables, 'SHAPE_CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  config = EstimateConfig().replace(distance='shape')
  _write(base, config, 'exact cameras', 0.0)
  for sd, spread, source in (((0.03, 2.0), math.log(3), 'given'),
                             ((0.04, 2.0), math.log(2), 'intake')):  # fmt: skip
    path = calibration_tables.shipped_calibration('shape', 'paper', sd, spread, source)
    assert os.path.dirname(path) == str(tmp_path)
    mine = config.replace(camera_sd_m=sd[0], camera_sd_deg=sd[1], camera_sd_from=source)
    _write(tmp_path / os.path.basename(path), mine, source, spread)
  assert (
    os.path.basename(path) == 'calibration_shape_paper_camera_intake_2-8cm_1-4deg.json'
  )
  return config


def test_the_intakes_claims_quote_its_tables_and_a_given_error_never_does(shipped):
  for sd, source, setting in (
    ((0.04, 2.0), 'intake', 'intake'),  # both cover: the intake's own
    ((0.021, 1.1), 'intake', 'intake'),
    ((0.04, 2.0), 'given', 'given'),  # a user's: the full claim's tables
    ((0.085, 5.0), 'intake', 'given'),  # past the intake's: the full claim's
  ):
    config = shipped.replace(
      camera_sd_m=sd[0], camera_sd_deg=sd[1], camera_sd_from=source
    )
    note = calibration_tables.calibration_note(config)
    assert note['matches'] and note['setting'] == setting, (sd, source, note)
  # a given error only the intake's tables' range holds: named, never quoted
  mine = shipped.replace(camera_sd_m=0.075, camera_sd_deg=3.9)
  for path in calibration_tables.shipped_calibrations('shape'):
    cal = calibration_tables.read_calibration(path)
    if cal['setting'] == 'intake':
      assert calibration_tables.differing_fields(mine, cal) == ['camera_sd_from']
      ok = mine.replace(camera_sd_from='intake')
      assert calibration_tables.differing_fields(ok, cal) == []
  mine = shipped.replace(camera_sd_m=0.12, camera_sd_deg=3.9)
  note = calibration_tables.calibration_note(mine)
  assert not note['matches']
  assert 'indicative' in table_notes.calibration_line(note)


def test_the_intakes_claim_is_marked_and_changes_no_search():
  config = EstimateConfig().replace(distance='shape')
  ik = types.SimpleNamespace(alignment_sd=(0.05, 2.0))
  carried, line = user_recordings.with_alignment_error(config, [ik])
  assert carried.scoring.camera_sd_from == 'intake' and line
  assert carried.flat()['camera_sd_from'] == 'intake'
  assert 'camera_sd_from' not in config.flat()  # a user's: files as before
  assert EstimateConfig.from_flat(carried.flat()) == carried
  assert 'camera_sd_from' in resume._RESUMABLE_FIELDS
  # an error the user gave stays theirs
  mine = config.replace(camera_sd_m=0.02, camera_sd_deg=1.0)
  assert user_recordings.with_alignment_error(mine, [ik])[0].scoring.camera_sd_from == (
    'given'
  )
  with pytest.raises(ValueError, match="camera_sd_from must be one of .* got 'user'"):
    config.replace(camera_sd_from='user').check()


@pytest.mark.slow
def test_a_study_of_the_intakes_errors_runs_and_ships_beside_the_others(
  errors_file, tmp_path, monkeypatch
):
  """A paper-size study at the smallest size a CPU runs (as
  calibration_camera_test's): each estimate is told the camera its drawn
  intake placed and carries that intake's claim; installed, its tables are
  what the intake's claims quote."""
  from experiments import calibrate
  from experiments.pipeline import datasets as gen
  from experiments.pipeline import estimation

  monkeypatch.setitem(
    gen.PRESETS, 'eval', dataclasses.replace(
      gen.PRESETS['eval'], frames=8, cloth_resolution=10, resolution=32,
      timestep=1 / 240,
    ),
  )  # fmt: skip
  jobs = []
  estimate_many = estimation.estimate_many
  monkeypatch.setattr(
    estimation,
    'estimate_many',
    lambda b, **kw: jobs.extend(b) or estimate_many(b, **kw),
  )
  base = tmp_path / 'shipped' / 'calibration_shape_paper.json'
  os.makedirs(base.parent)
  monkeypatch.setattr(calibration_tables, 'SHAPE_PAPER_CALIBRATION_FILE', str(base))
  monkeypatch.setattr(
    calibration_tables, 'SHAPE_CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  study = calibration.Config(
    size='paper', pairs=2, folds=2, backend='c', sharpness_grid=(0.5,), batch_size=4,
    camera_errors=(errors_file,),
    estimate=EstimateConfig().replace(
      distance='shape', cloth_resolution=8, frames=8, warmup=0.25, q=2, n_init=4,
      max_iter=1, posterior_grid=(4, 8, 4),
    ),
  )  # fmt: skip
  calibrate.main(
    calibrate.Args(workdir=str(tmp_path / 'cal'), install=True, study=study)
  )
  resolved = calibration.with_intake_errors(study)
  errors = told_cameras.read_intake_errors((errors_file,))
  assert len(jobs) == 4
  for job in jobs:
    assert job.config.scoring.camera_sd_from == 'intake'
    claim = carried_errors.camera_of(job.config.flat())
    assert any(
      all(
        abs(math.log(c / o)) <= 0.25 + 1e-6 for c, o in zip(claim, e.claim, strict=True)
      )
      for e in errors
    )
  (dest,) = calibration_tables.shipped_calibrations('shape')
  assert '_camera_intake_' in os.path.basename(dest)
  cal = calibration_tables.read_calibration(dest)
  assert 'cameras off as 9 measured intakes erred' in cal['setting']
  assert carried_errors.table_source(cal) == 'intake'
  est = calibration.study_configs(resolved)[3]
  mine = est.replace(point='bayes')
  assert calibration_tables.calibration_file(mine) == dest
  assert calibration_tables.calibration_note(mine)['matches']
  user = mine.replace(camera_sd_from='given')  # a user's error: not these tables
  assert calibration_tables.differing_fields(user, cal) == ['camera_sd_from']
