"""experiments.validate: an exported fabric simulated in the set-up of a
recording it was not estimated from (a rig's, made by another recipe), its
shape distance read against the gusts' noise floor; a recording of another
cloth size, or without a camera file, refused in one line each."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from experiments import validate as script
from experiments.pipeline import fabric_files, intake, rig, validation

_SETTINGS = validation.Settings(frames=16, warmup=0.5, seeds=3, image_size=32)


def _entry(v):
  return {'value': v, 'median': v, 'interval_90': [0.9 * v, 1.1 * v]}


@pytest.fixture(scope='module')
def made(tmp_path_factory):
  """A rig's recording of a 1 m sheet, and an estimate's fabric exported
  for a 1 m and a 0.5 m sheet."""
  root = tmp_path_factory.mktemp('validate')
  paths = rig.write(rig.SMOKE, str(root / 'rec'))
  est = root / 'est'
  est.mkdir()
  (est / 'estimate.json').write_text(json.dumps({
    'material': 'gray_interlock',
    'config': {'cloth_size': 1.0, 'cloth_resolution': 10, 'fps': 20.0},
    'estimate': {'bending_scale': _entry(1.0), 'area_weight': _entry(0.185)},
  }))  # fmt: skip
  whole = fabric_files.write(str(est), str(root / 'whole'), draws=0)
  half = fabric_files.write(str(est), str(root / 'half'), draws=0, cloth_size=0.5)
  assert whole['mesh']['size_m'] == 1.0 and half['mesh']['size_m'] == 0.5
  return {
    'depth': paths['depth'], 'camera': paths['camera'],
    'whole': str(root / 'whole'), 'half': str(root / 'half'),
  }  # fmt: skip


def _args(made, **kw):
  fields = dict(
    fabric=made['whole'], recording=made['depth'], camera_json=made['camera'],
    cloth_size=1.0, wind_speed=rig.SMOKE.wind_speed, settings=_SETTINGS,
    intake=intake.IntakeConfig(world_up='z'),
  )  # fmt: skip
  fields.update(kw)
  return script.Args(**fields)


def _one_line(e) -> str:
  text = str(e.value)
  assert '\n' not in text and len(text) <= 300, text
  return text


def test_a_recording_without_a_camera_file_is_refused_in_one_line(made):
  with pytest.raises(ValueError) as e:
    script.main(_args(made, camera_json=''))
  assert _one_line(e).startswith(f'{made["depth"]}: no camera file (--camera_json)')


def test_a_recording_of_another_cloth_size_is_refused_in_one_line(made):
  # said to be another size than the export's sheet: refused before reading it
  with pytest.raises(ValueError) as e:
    script.main(_args(made, fabric=made['half'], cloth_size=1.0))
  text = _one_line(e)
  assert 'a sheet of 1 m (--cloth_size)' in text and 'a 0.5 m sheet' in text
  # said to be the export's size, but its pins are a 1 m sheet's: the intake
  with pytest.raises(ValueError) as e:
    script.main(_args(made, fabric=made['half'], cloth_size=0.5))
  text = _one_line(e)
  assert text.startswith(made['depth']) and 'the pins are' in text and '0.500 m' in text
  assert not any(n.startswith('validate') for n in os.listdir(made['half']))


def test_the_recording_the_estimate_was_made_from_is_refused(made, tmp_path):
  est = tmp_path / 'est'
  est.mkdir()
  (est / 'estimate.json').write_text(json.dumps({
    'material': 'gray_interlock', 'recording': made['depth'],
    'config': {'cloth_size': 1.0, 'cloth_resolution': 10, 'fps': 20.0},
    'estimate': {'bending_scale': _entry(1.0), 'area_weight': _entry(0.185)},
  }))  # fmt: skip
  fabric_files.write(str(est), str(tmp_path / 'f'), draws=0)
  with pytest.raises(ValueError) as e:
    script.main(_args(made, fabric=str(tmp_path / 'f')))
  assert 'was made from it' in _one_line(e)


@pytest.mark.parametrize(
  'kw, message',
  [({'wind_speed': 0.0}, '--wind_speed=0.0'), ({'wind_speed': 90.0}, '--wind_speed'),
   ({'settings': validation.Settings(seeds=1)}, '--seeds=1'),
   ({'settings': validation.Settings(frames=10**9)}, '--frames=1000000000')],
)  # fmt: skip
def test_bad_settings_are_refused_by_flag(made, kw, message):
  with pytest.raises(ValueError, match=message):
    script.main(_args(made, **kw))


def test_a_folder_that_is_no_export_is_refused_naming_the_file(made, tmp_path):
  with pytest.raises(ValueError, match='fabric.json: no such file'):
    script.main(_args(made, fabric=str(tmp_path)))
  (tmp_path / 'fabric.json').write_text('{"material": "gray_interlock"}')
  (tmp_path / 'fabric.xml').write_text('<mujoco/>')
  with pytest.raises(ValueError, match='fabric.json: not an export of this version'):
    script.main(_args(made, fabric=str(tmp_path)))


@pytest.mark.slow
def test_the_export_is_read_against_the_recordings_noise_floor(made, tmp_path, capsys):
  record = script.main(_args(made, out=str(tmp_path / 'v')))
  out = capsys.readouterr().out
  assert 'noise floor' in out and 'library fabric' in out and 'placement' in out
  assert record['alignment_sd']['m'] > 0
  assert os.path.isfile(tmp_path / 'v' / validation.RESULT_FILE)
  assert os.path.getsize(tmp_path / 'v' / validation.FIGURE_FILE) > 1000
  assert len(record['predicted_summaries_mm']) == _SETTINGS.seeds
  # the recording's own fabric and wind, by another recipe (finer mesh,
  # gustier): as close as a few floors, the floor itself some millimetres
  assert 1 < record['floor_mm'] < 200
  assert record['distance_over_floor'] < 3, record
  assert np.isfinite(record['library_over_floor'])
