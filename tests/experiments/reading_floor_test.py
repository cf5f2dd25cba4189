"""A reading more precise than any calibration's is carried at their lowest
(``reading_floor``, issue 77): a scale read to 0.8% and a ruler's bending
length read to 1% quote measured coverage, printed with what was raised; a
reading far more precise, or one already covered, is carried as given.

The shipped files fix the ranges: the paper tables drew the area weight at
2% (covered from 1%), the protocol check's sets a ruler's bending length at
3% (from 1.5%) and a scale's area weight at 1% (from 0.5%).
"""

from __future__ import annotations

import dataclasses
import types

import pytest

from experiments import estimate
from experiments.pipeline import (
  intake,
  joint,
  objective,
  reading_floor,
  rig,
  setup,
  table_notes,
  takes,
  user_recordings,
)


def _net(config):
  return setup.network('', config.scoring.distance, 64, config.simulation.material)


def _measured(**kw):
  base = dict(wind_speed=0.0, wind_speed_sd=0.0, area_weight=0.0, area_weight_sd=0.0,
              bending_length=0.0, bending_length_sd=0.0)  # fmt: skip
  return types.SimpleNamespace(**{**base, **kw})


def test_raises_go_up_to_twice_the_given_error_the_least_first():
  m = _measured(
    area_weight=0.2, area_weight_sd=0.0016, wind_speed=3.0, wind_speed_sd=0.09
  )
  lows = {'area_weight': [0.005, 0.01, 0.02], 'wind_speed': [0.01]}
  ways = reading_floor.raises(m, lows)
  # 0.8%: 1% (x1.25) is within twice; 2% (x2.5) is not, nor 0.5% (a lowering);
  # the wind's 3% is above every floor: never touched
  assert ways == [{}, {'area_weight_sd': pytest.approx(0.002)}]
  m2 = _measured(area_weight=0.2, area_weight_sd=0.0012, bending_length=0.03,
                 bending_length_sd=0.0004)  # fmt: skip
  ways = reading_floor.raises(m2, {'area_weight': [0.01], 'bending_length': [0.015]})
  factors = [
    max(
      [
        w.get('area_weight_sd', 0.0012) / 0.0012,
        w.get('bending_length_sd', 0.0004) / 0.0004,
      ]
    )  # fmt: skip
    for w in ways
  ]
  assert len(ways) == 4 and factors == sorted(factors)
  assert reading_floor.raises(m2, {}) == [{}]


def test_carried_takes_the_least_raise_that_a_calibration_covers():
  m = _measured(area_weight=0.2, area_weight_sd=0.001)
  lows = {'area_weight': [0.006, 0.008]}
  asked = []

  def covered(r):  # only 0.8% is covered
    asked.append(r)
    return r.get('area_weight_sd') == pytest.approx(0.0016)

  raised, line = reading_floor.carried(m, lows, covered)
  assert raised == {'area_weight_sd': pytest.approx(0.0016)}
  assert asked[0] == {} and len(asked) == 3  # as given, 0.6%, then 0.8%
  assert 'area weight 0.5% as 0.8%' in line
  # already covered as given: nothing raised, no line
  assert reading_floor.carried(m, lows, lambda r: True) == ({}, None)
  assert reading_floor.carried(m, lows, lambda r: False) == ({}, None)


@pytest.mark.parametrize(
  'sd, carried',
  [(0.0016, 0.002), (0.0012, 0.002), (0.0006, None), (0.004, None)],
)
def test_a_precise_scale_quotes_the_tables_at_their_lowest(sd, carried):
  """0.8% and 0.6% are carried as 1% and quote the tables; 0.3% (over
  twice under) stays, and the note names it; 2% was covered as given."""
  config = estimate.Args().search.replace(area_weight=0.2, area_weight_sd=sd)
  net = _net(config)
  take = takes.Take('rec')
  raised, line = user_recordings.carried_readings([take], [config], net)
  note = setup.estimate_note(config.replace(**raised), net)
  if carried is None:
    assert raised == {} and line is None
    assert note['matches'] == (sd > 0.002)
    return
  assert raised == {'area_weight_sd': pytest.approx(carried)}
  assert f'area weight {100 * sd / 0.2:.2g}% as 1%' in line
  assert not setup.estimate_note(config, net)['matches']  # as given: indicative
  assert note['matches'] and note['recalibrated']
  assert 'indicative' not in table_notes.calibration_line(note)


def test_a_protocol_joints_precise_ruler_quotes_the_protocol_check():
  """Three fan settings, each wind read, a scale at 1% and a ruler's
  bending length at 1%: below the check's 1.5-6%, raised to 1.5%; its
  joint note then the shipped check's measured coverage."""
  config = objective.PRESETS['default'].replace(
    material='gray_interlock', distance='shape', air_coefficient='free',
    area_weight=0.2, area_weight_sd=0.002, bending_length=0.03,
    bending_length_sd=0.0003,
  )  # fmt: skip
  winds = (2.0, 2.6, 3.2)
  configs = [config.replace(wind_speed=w, wind_speed_sd=0.02 * w) for w in winds]
  recorded = [takes.Take(f'r{k}', wind=(w, 0.02 * w)) for k, w in enumerate(winds)]
  net = _net(config)
  raised, line = user_recordings.carried_readings(recorded, configs, net)
  assert raised == {'bending_length_sd': pytest.approx(0.00045)}
  assert 'bending length 1% as 1.5%' in line
  assert not joint.joint_note(configs, net, None)['matches']
  note = joint.joint_note([c.replace(**raised) for c in configs], net, None)
  assert note['matches'] and note['measured']
  # recordings sharing a fan setting: no check covers them, raised or not
  shared = [t._replace(fan='one') for t in recorded]
  assert user_recordings.carried_readings(shared, configs, net) == ({}, None)


@pytest.mark.slow
def test_a_users_recording_through_the_intake_carries_a_precise_scale_raised(tmp_path):
  """The windy rig's recording (another physics, an OpenCV camera file)
  taken in with a scale at 0.8%: the prepared estimate carries 1%, keeps
  what was given, and says so before the answer."""
  recipe = dataclasses.replace(rig.MISMATCHED, seed=3, wind_speed=3.0)
  paths = rig.write(recipe, str(tmp_path / 'recording'), 'c')
  config = estimate.Args().search.replace(area_weight=0.2, area_weight_sd=0.0016)
  prepared = user_recordings.prepare(
    takes.from_flags([paths['depth']], paths['camera']),
    intake.IntakeConfig(world_up='z'),
    config,
    _net(config),
    str(tmp_path / 'estimate'),
  )
  assert prepared.readings == {'area_weight_sd': pytest.approx(0.002)}
  assert prepared.given == {'area_weight_sd': pytest.approx(0.0016)}
  assert prepared.configs[0].measured.area_weight_sd == pytest.approx(0.002)
  assert any('area weight 0.8% as 1%' in line for line in prepared.lines)
  note = setup.estimate_note(prepared.configs[0], _net(config))
  assert note['matches'] and note['recalibrated']
