"""EstimateConfig's sections: the same flags, flat replace, and the flat files.

The config was one flat dataclass until issue 42; its command line, its
``replace`` and ``preset`` keywords and the config that run.json, estimate.json
and calibration files hold keep the flat names.
"""

from __future__ import annotations

import dataclasses
import json
import os
import types

import numpy as np
import pytest

import physsim
from experiments import estimate
from experiments.pipeline import (
  cli,
  evaluation,
  files,
  layout,
  objective,
  resume,
  search,
  searcher,
)
from experiments.pipeline.posterior import Measured
from experiments.studies import tables

# The flags of the flat EstimateConfig before the split (``--fps`` of the
# config was always ``--sim_fps``), with the bending-length reading (and its law) and the
# joint's shared discrepancy and a hem's known mass added since.
FLAT_FLAGS = [
  'air_coefficient', 'area_weight', 'area_weight_sd', 'backend', 'bending_length', 'bending_length_dof', 'bending_length_sd', 'box', 'calibration', 'camera_sd_deg',
  'camera_sd_m', 'cameras', 'cloth_resolution', 'cloth_size', 'distance', 'frames',
  'garment', 'garment_spacing', 'gusts', 'hem_mass', 'likelihood', 'material', 'max_iter',
  'min_iter', 'model_error', 'n_init', 'point', 'posterior_grid', 'q', 'replicates', 'seed',
  'sensor_noise', 'shared_bias', 'sharpness', 'sim_fps', 'stop_rel_change', 'stop_window', 'warmup',
  'wind_speed', 'wind_speed_sd', 'workers',
]  # fmt: skip
# experiments.estimate's flags before the split (and the bending length's, the
# hem's, the air coefficient's).
ESTIMATE_FLAGS = [
  'air_coefficient', 'alignment_sd', 'allow_guessed_up', 'allow_no_camera', 'allow_other_material',
  'area_weight', 'area_weight_sd', 'backend', 'bending_length', 'bending_length_dof', 'bending_length_sd',
  'box', 'calibration', 'camera_json',
  'camera_sd_deg', 'camera_sd_m', 'cameras', 'cloth_resolution', 'cloth_size',
  'cloth_sizes', 'depth_range', 'depth_scale', 'depth_topic', 'distance', 'fps',
  'frame_glob', 'frames', 'garment', 'garment_spacing', 'gusts', 'hem_mass', 'image_size',
  'imu_topic', 'info_topic', 'intake_only', 'likelihood', 'mask', 'material',
  'max_iter', 'min_iter', 'min_overlap', 'model', 'model_error', 'n_init', 'pins', 'plane_tol',
  'point', 'posterior_grid', 'protocol', 'q', 'recording', 'remove_planes',
  'replicates', 'seed', 'sensor_noise', 'shared_bias', 'sharpness', 'sim_fps', 'start',
  'stop_rel_change', 'stop_window', 'up', 'warmup', 'wind_speed', 'wind_speed_sd',
  'wind_speed_sds', 'wind_speeds', 'wind_toward_camera', 'workdir', 'workers',
  'world_up',
]  # fmt: skip
# ``dataclasses.asdict`` of the flat smoke preset: the config of the run.json
# and estimate.json files written before the split.
OLD_SMOKE = {
  'point': 'bayes', 'material': 'gray_interlock', 'garment': '',
  'cloth_resolution': 10, 'cloth_size': 1.0, 'garment_spacing': 0.04, 'frames': 16,
  'fps': 20.0, 'warmup': 0.5, 'gusts': 0.2, 'cameras': 2, 'q': 8, 'n_init': 16,
  'max_iter': 3, 'stop_rel_change': 0.05, 'stop_window': 2, 'min_iter': 2,
  'posterior_grid': [8, 32, 16], 'likelihood': 'gibbs', 'sharpness': 0.5,
  'model_error': 0.0, 'replicates': 1, 'distance': 'energy', 'camera_sd_m': 0.0, 'camera_sd_deg': 0.0,
  'backend': 'auto', 'workers': 0, 'sensor_noise': True, 'seed': 0,
  'measured': {
    'wind_speed': 0.0, 'wind_speed_sd': 0.0, 'area_weight': 0.0, 'area_weight_sd': 0.0
  },
  'calibration': '',
}  # fmt: skip
SMOKE = objective.PRESETS['smoke']
# The files above were written when the PSD was the default distance; the
# shape is now (it reads more): an old file is read as the PSD it says.
OLD_SMOKE_CONFIG = SMOKE.replace(distance='energy')
TODAYS_SMOKE = {**OLD_SMOKE, 'distance': 'shape'}


def test_the_flags_are_the_flat_configs():
  assert (
    sorted(leaf.flag for leaf in cli.leaves(objective.EstimateConfig)) == FLAT_FLAGS
  )
  assert sorted(leaf.flag for leaf in cli.leaves(estimate.Args)) == ESTIMATE_FLAGS
  # every flag sets its own field, and shows the preset's value
  args = cli.parse(
    estimate.Args, estimate.PRESETS,
    ['x', '--preset=demo', '--q=5', '--sim_fps=12', '--material=black_denim',
     '--wind_speed=3', '--wind_speed_sd=0.1', '--workers=2', '--sharpness=0.7'],
  )  # fmt: skip
  want = objective.PRESETS['demo'].replace(
    q=5, fps=12.0, material='black_denim', wind_speed=3.0, wind_speed_sd=0.1,
    workers=2, sharpness=0.7,
  )  # fmt: skip
  assert args.search == want


def test_replace_routes_flat_names_to_their_sections():
  c = SMOKE.replace(q=5, material='black_denim', fps=12.0, workers=2, seed=3)
  assert (c.search.q, c.simulation.material, c.simulation.fps) == (
    5,
    'black_denim',
    12.0,
  )
  assert (c.hardware.workers, c.seed) == (2, 3)
  assert c.scoring == SMOKE.scoring and c.measured == SMOKE.measured
  m = SMOKE.replace(wind_speed=3.0, wind_speed_sd=0.1).measured
  assert m == Measured(wind_speed=3.0, wind_speed_sd=0.1)
  # a whole section, and a flat name on top of the section given with it
  s = SMOKE.replace(search=objective.Search(q=3), replicates=0)
  assert s.search == objective.Search(q=3, replicates=0)
  given = SMOKE.replace(measured=Measured(area_weight=0.2, area_weight_sd=0.01))
  assert given.measured.area_weight == 0.2
  assert objective.EstimateConfig.preset('demo', q=5).search.q == 5
  assert SMOKE.replace() == SMOKE


def test_replace_refuses_an_unknown_name():
  with pytest.raises(ValueError, match="no setting 'qq'"):
    SMOKE.replace(qq=3)
  with pytest.raises(ValueError, match="no setting 'sim_fps'"):
    SMOKE.replace(sim_fps=12.0)  # the flag's name, not the field's
  with pytest.raises(ValueError, match="no setting 'bogus'"):
    objective.EstimateConfig.preset('smoke', bogus=1)


def test_the_flat_form_is_the_old_files():
  for name, config in objective.PRESETS.items():
    flat = json.loads(json.dumps(config.flat()))
    assert sorted(flat) == sorted(OLD_SMOKE), name
    assert objective.EstimateConfig.from_flat(flat) == config, name
  assert json.loads(json.dumps(SMOKE.flat())) == TODAYS_SMOKE
  assert objective.EstimateConfig.from_flat(TODAYS_SMOKE) == SMOKE
  assert objective.EstimateConfig.from_flat(OLD_SMOKE) == OLD_SMOKE_CONFIG
  # a hem is written where there is one, and read back
  hemmed = json.loads(json.dumps(SMOKE.replace(hem_mass=0.3).flat()))
  assert hemmed == {**TODAYS_SMOKE, 'hem_mass': 0.3}
  assert objective.EstimateConfig.from_flat(hemmed) == SMOKE.replace(hem_mass=0.3)
  # a file from before cloth_size and the camera's error were settings
  older = {
    k: v for k, v in OLD_SMOKE.items()
    if k not in ('cloth_size', 'camera_sd_m', 'camera_sd_deg')
  }  # fmt: skip
  assert objective.EstimateConfig.from_flat(older) == OLD_SMOKE_CONFIG


def test_a_model_given_to_the_default_distance_gets_a_note():
  args = estimate.Args(recording='r', model='out/m')
  assert '--model=out/m' in estimate.model_note(args)
  assert '--distance=energy' in estimate.model_note(args)
  psd = dataclasses.replace(args, search=args.search.replace(distance='energy'))
  assert estimate.model_note(psd) == ''
  assert estimate.model_note(estimate.Args(recording='r')) == ''


def test_a_design_is_scored_in_calls_of_q_only_on_mujoco_c():
  # the C backend: time grows with the worlds, a second program shape compiles
  # for seconds; a GPU scores 48 as fast as 24 (BENCHMARKS.md)
  paper = objective.EstimateConfig().replace(q=24, n_init=48)
  assert evaluation._call_size([paper.replace(backend='c')], 48) == 24
  assert evaluation._call_size([paper.replace(backend='c')], 24) == 24
  assert evaluation._call_size([paper.replace(backend='c')], 1) == 1
  assert evaluation._call_size([paper.replace(backend='warp')], 48) == 48
  assert evaluation._call_size([paper.replace(backend='mjx')], 48) == 48
  mixed = [paper.replace(backend='c'), paper.replace(backend='c', q=8)]
  assert evaluation._call_size(mixed, 48) == 24


def test_a_small_gpu_call_is_padded_to_the_design_but_a_lockstep_is_not():
  # one estimate on a GPU: its steps of q and a resumed search's one
  # candidate run the design's program shape (within FLAT_WORLDS worlds)
  paper = objective.EstimateConfig().replace(q=24, n_init=48, backend='warp')
  assert evaluation.FLAT_WORLDS == 48
  assert evaluation._call_size([paper], 24) == 48
  assert evaluation._call_size([paper], 1) == 48
  assert evaluation._call_size([paper], 48) == 48
  # two searches' rows: 2 x 48 worlds is past the flat cost, no padding
  assert evaluation._call_size([paper, paper], 24, rows=2) == 24
  small = paper.replace(q=4, n_init=8)
  assert evaluation._call_size([small], 4, rows=4) == 8
  assert evaluation._call_size([small], 4, rows=8) == 4
  # MuJoCo C never pads past q
  assert evaluation._call_size([paper.replace(backend='c')], 1) == 1


def test_the_default_distance_is_the_shape_and_the_papers_the_psd():
  assert objective.EstimateConfig().scoring.distance == 'shape'
  assert objective.PRESETS['default'].scoring.distance == 'shape'
  assert objective.PRESETS['paper'].scoring.distance == 'energy'
  assert objective.PRESETS['paper'].search.point == 'argmin'
  with pytest.raises(ValueError, match="no setting 'nonsense'"):
    objective.EstimateConfig.from_flat({**OLD_SMOKE, 'nonsense': 1})


def test_a_script_config_reads_its_nested_and_its_flat_estimate(tmp_path):
  # files.resume compares a study's saved config: today's (nested, as
  # dataclasses.asdict writes it) and one from before the split (flat).
  config = tables.Config(estimate=SMOKE.replace(backend='c', q=5))
  path = str(tmp_path / 'result.json')
  files.write_json(path, {'config': dataclasses.asdict(config), 'done': 1})
  assert files.resume(path, config)['done'] == 1
  old = objective.record(config)  # what the study's files hold of it
  assert old == {**dataclasses.asdict(config), 'estimate': config.estimate.flat()}
  files.write_json(path, {'config': old, 'done': 2})
  assert files.resume(path, config)['done'] == 2
  assert files.resume(path, dataclasses.replace(config, estimate=SMOKE)) == {}


def test_check_numbers_names_the_flag_in_every_section():
  for name, flag in (
    ('fps', 'sim_fps'), ('sharpness', 'sharpness'), ('stop_rel_change', 'stop_rel_change'),
    ('wind_speed', 'wind_speed'), ('camera_sd_m', 'camera_sd_m'),
  ):  # fmt: skip
    with pytest.raises(ValueError, match=f'--{flag}=nan'):
      SMOKE.replace(**{name: float('nan')}).check()
  with pytest.raises(ValueError, match='--posterior_grid'):
    SMOKE.replace(posterior_grid=(8, 2000, 16)).check()


def _fake_problem():
  """What ``resume.check_run`` reads of a problem and its recording."""
  pose = physsim.Pose(rotation=np.eye(3)[None], position=np.zeros((1, 3)))
  problem = types.SimpleNamespace(
    data=types.SimpleNamespace(poses=pose),
    intr=physsim.Intrinsics(width=8, height=8),
    net=types.SimpleNamespace(modality='depth'),
  )
  rec = types.SimpleNamespace(depth=np.ones((4, 8, 8), np.float32), rgb=None)
  return problem, rec


def test_an_old_workdirs_run_resumes(tmp_path):
  problem, rec = _fake_problem()
  workdir = str(tmp_path)
  resume.check_run(search.Job(SMOKE, rec, '', workdir), problem)
  path = os.path.join(workdir, layout.RUN_FILE)
  with open(path) as f:
    run = json.load(f)
  resumable = ('workers', 'calibration')
  assert run['config'] == {k: v for k, v in TODAYS_SMOKE.items() if k not in resumable}
  # run.json as the flat config wrote it, when the PSD was the default: the
  # same run for that distance; today's default is another, named
  run['config'] = {k: v for k, v in OLD_SMOKE.items() if k not in resumable}
  files.write_json(path, run)
  resume.check_run(
    search.Job(OLD_SMOKE_CONFIG.replace(workers=3), rec, '', workdir), problem
  )
  with pytest.raises(ValueError, match=r'config\.gusts'):
    resume.check_run(
      search.Job(OLD_SMOKE_CONFIG.replace(gusts=0.3), rec, '', workdir), problem
    )
  with pytest.raises(ValueError, match=r'config\.distance'):
    resume.check_run(search.Job(SMOKE, rec, '', workdir), problem)


def test_a_bending_length_enters_the_files_only_when_given():
  flat = SMOKE.flat()
  assert 'bending_length' not in flat['measured']  # old files and runs unchanged
  given = SMOKE.replace(bending_length=0.02, bending_length_sd=0.002)
  read = json.loads(json.dumps(given.flat()))
  assert read['measured']['bending_length'] == 0.02
  assert objective.EstimateConfig.from_flat(read) == given


def test_the_model_error_reaches_the_search_and_is_checked():
  config = objective.EstimateConfig().replace(model_error=0.3)
  assert searcher.posterior_config(config.search, config.scoring).model_error == 0.3
  for bad in (-0.1, float('nan'), float('inf')):
    with pytest.raises(ValueError, match='model_error'):
      config.replace(model_error=bad).check()
  with pytest.raises(ValueError, match='synthetic'):
    config.replace(distance='shape', likelihood='synthetic', sharpness=1.0).check()
