"""The calibration study with the shape distance: no network, its own file.

The shape distance reads the sheet's place from the depth frames, so its
calibration must train no network, estimate every recording without one, say
so in its setting, and be quoted by shape estimates from its own shipped file
while estimates with a network keep the default file.
"""

from __future__ import annotations

import dataclasses
import json
import os

import pytest

from experiments.pipeline import calibration_tables
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import calibration

pytestmark = pytest.mark.slow  # the shape calibration study end to end

# Two pairs of recordings at the demo's size, searched with the smallest budget
# that still fits a GP (MuJoCo C on this CPU): the whole study end to end.
SMOKE = dataclasses.replace(
  calibration.PRESETS['smoke'],
  pairs=2,
  folds=2,
  backend='c',
  sharpness_grid=(0.5, 1.0),
  estimate=EstimateConfig().replace(
    q=2, n_init=4, max_iter=1, posterior_grid=(4, 8, 4), distance='shape'
  ),
)


def test_the_shape_distance_trains_no_network():
  assert not calibration.uses_networks(SMOKE)
  assert calibration.network_seeds(SMOKE) == ()
  with_net = dataclasses.replace(
    SMOKE, estimate=SMOKE.estimate.replace(distance='energy')
  )
  assert calibration.uses_networks(with_net)
  assert calibration.network_seeds(with_net) == (0,)


@pytest.fixture(scope='module')
def study(tmp_path_factory):
  workdir = str(tmp_path_factory.mktemp('cal_shape'))
  out = calibration.run(SMOKE, workdir)
  return workdir, out


def test_the_study_estimates_without_a_network_and_says_so(study):
  workdir, out = study
  for made in ('data', 'model', 'networks', calibration.NETWORKS_FILE):
    assert not os.path.exists(os.path.join(workdir, made)), made
  assert out['n'] == 2 * SMOKE.pairs
  assert out['setting'].endswith('shape distance, no network')
  assert 'network' not in out
  assert out['config']['estimate']['distance'] == 'shape'
  estimates = os.path.join(workdir, 'estimates')
  for seq in sorted(os.listdir(estimates)):
    with open(os.path.join(estimates, seq, 'run.json')) as f:
      assert json.load(f)['model_dir'] == '', seq
  with open(os.path.join(workdir, 'calibration.md')) as f:
    assert 'shape distance, no network' in f.read()


def test_shape_estimates_quote_the_shape_calibration(study, tmp_path, monkeypatch):
  workdir, out = study
  default = tmp_path / 'calibration.json'  # stands in for the shipped default
  default.write_text(json.dumps({'n': 1, 'setting': 'the networks', 'sharpness': 1.0,
                                 'coverage': {}}))  # fmt: skip
  shape_file = tmp_path / 'calibration_shape.json'
  monkeypatch.setattr(calibration_tables, 'CALIBRATION_FILE', str(default))
  monkeypatch.setattr(calibration_tables, 'SHAPE_CALIBRATION_FILE', str(shape_file))
  monkeypatch.setattr(
    calibration_tables, 'SHAPE_PAPER_CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  # the settings the study searched with, read at the sharpness it chose
  searched = calibration.study_configs(SMOKE)[3].replace(sharpness=out['sharpness'])
  # None shipped for the shape yet: the default file, whose note names the distance.
  assert calibration_tables.calibration_file(searched) == str(default)
  assert calibration_tables.shipped_calibration('shape') == str(shape_file)
  assert calibration_tables.shipped_calibration('energy') == str(default)
  with open(os.path.join(workdir, calibration.RESULT_FILE)) as f:
    shape_file.write_text(f.read())  # what --install does for the shape
  assert calibration_tables.calibration_file(searched) == str(shape_file)
  note = calibration_tables.calibration_note(searched)
  assert note['matches'] and note['recalibrated'], note
  assert note['setting'].endswith('no network')
  assert note['n_calibration_recordings'] == 2 * SMOKE.pairs
  # An estimate that embeds keeps the default file, and one given a file uses it.
  energy = searched.replace(distance='energy')
  assert calibration_tables.calibration_file(energy) == str(default)
  mine = searched.replace(calibration=str(default))
  assert calibration_tables.calibration_file(mine) == str(default)
  # The shape calibration does not apply to another shape setting.
  other = calibration_tables.calibration_note(
    searched.replace(sharpness=3 * out['sharpness'])
  )
  assert not other['matches'] and 'sharpness' in ' '.join(other['differs'])


def test_the_shipped_shape_calibration_holds_for_demo_size_shape_estimates():
  config = dataclasses.replace(
    calibration.Config(),
    estimate=calibration.Config().estimate.replace(distance='shape'),
  )
  searched = calibration.study_configs(config)[3].replace(point='bayes')
  assert (
    calibration_tables.calibration_file(searched)
    == calibration_tables.SHAPE_CALIBRATION_FILE
  )
  note = calibration_tables.calibration_note(searched)
  assert note['matches'] and note['recalibrated'], note
  assert note['n_calibration_recordings'] >= 100  # the minimum
  for field, cov in note['coverage'].items():  # held out from the tables
    assert 0.85 <= cov['interval_90'] <= 0.95, (field, cov)
    assert 0.40 <= cov['interval_50'] <= 0.60, (field, cov)
