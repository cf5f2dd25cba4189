"""The shipped protocol check (issue 77): a protocol joint (three fan settings
each with an anemometer, a scale, a bending length, the air free) quotes the
coverage measured on held-out protocol sets, and only where the check's sets
were like it; the line a person reads names what was not measured."""

from __future__ import annotations

import pytest

from experiments.pipeline import objective, protocol_checks, setup, table_notes
from experiments.studies import air_protocol


def _config(**kw):
  readings = dict(
    material='gray_interlock', distance='shape', air_coefficient='free',
    area_weight=0.2, area_weight_sd=0.002, bending_length=0.03,
    bending_length_sd=0.0009, wind_speed=2.0, wind_speed_sd=0.04,
  )  # fmt: skip
  return objective.PRESETS['default'].replace(**{**readings, **kw})


def _check(tmp_path):
  summary = {
    'free': {'sets': 5, 'held_sets': 4, 'air_held_90': 0.8, 'air_held_50': 0.4,
             'held': {'bending_90': 1.0, 'bending_50': 0.5, 'area_weight_90': 0.75,
                      'area_weight_50': 0.25, 'wind_90': 1.0, 'wind_50': 1.0}},
  }  # fmt: skip
  study = air_protocol.Study(
    measured=('bending_scale', 'area_weight', 'air_coefficient')
  )
  record = air_protocol.check_record(study, summary)
  path = tmp_path / 'protocol_checks.json'
  air_protocol.files.write_json(str(path), protocol_checks.with_check(None, record))
  return record, str(path)


def test_the_install_records_each_quantitys_coverage_and_what_it_left_out(tmp_path):
  record, _ = _check(tmp_path)
  assert record['coverage']['bending_scale'] == {
    'interval_90': 1.0,
    'interval_50': 0.5,
    'n': 4,
  }
  assert record['coverage']['air_coefficient']['n'] == 5  # every set's c
  assert record['unmeasured'] == ['wind_speed']
  assert record['recordings'] == 3 and record['readings']['wind_speed'] == 0.02
  with pytest.raises(ValueError, match='--measured'):
    air_protocol.check_record(air_protocol.Study(measured=('colour',)), {
      'free': {'held': {}, 'air_held_90': 1, 'air_held_50': 1}
    })  # fmt: skip


def test_a_protocol_joint_like_the_checks_sets_quotes_it(tmp_path):
  _, path = _check(tmp_path)
  note = protocol_checks.protocol_note(_config(), 3, path)
  assert note['matches'] and note['measured'] and note['shared_discrepancy']
  assert note['coverage']['area_weight']['interval_50'] == 0.25
  line = table_notes.calibration_line(note)
  assert 'measured, not recalibrated' in line and 'indicative' in line
  assert 'weight 75%/25% of 4' in line and 'Not measured: wind' in line


@pytest.mark.parametrize(
  'recordings, change',
  [
    (2, {}),  # the sets had three fan settings
    (3, {'material': 'black_denim'}),  # another fabric's box
    (3, {'area_weight_sd': 0.01}),  # a scale five times as uncertain
    (3, {'bending_length_dof': 4.0}),  # a depth camera's t law
    (3, {'air_coefficient': 'fixed'}),
    (3, {'q': 8}),  # another search budget
  ],
)
def test_a_joint_unlike_the_checks_sets_does_not_quote_it(tmp_path, recordings, change):
  _, path = _check(tmp_path)
  assert protocol_checks.protocol_note(_config(**change), recordings, path) is None


def test_the_shipped_check_is_what_a_protocol_estimates_note_quotes():
  """setup.calibration hands a protocol joint whose every recording was read
  to the shipped check; without every wind read it stays indicative."""
  config = _config()
  net = setup.resolve(config, joint=True, recordings=3).network
  note = setup.calibration(config, net, joint=True, recordings=3, every_wind_read=True)
  assert note['measured'] and note['mode'] == 'protocol joint, 3 fan settings, air free'
  plain = setup.calibration(config, net, joint=True, recordings=3)
  assert not plain['matches']


def test_a_check_of_other_fan_settings_is_kept_beside_and_read_by_its_count(tmp_path):
  record, path = _check(tmp_path)
  two = {**record, 'recordings': 2, 'n': 9}
  shipped = protocol_checks.with_check({'checks': [record]}, two)
  assert [c['recordings'] for c in shipped['checks']] == [2, 3]
  again = protocol_checks.with_check(shipped, {**two, 'n': 11})  # replaced
  assert [c['n'] for c in again['checks']] == [11, 5]
  air_protocol.files.write_json(path, again)
  assert protocol_checks.check_of(2, path)['n'] == 11
  assert protocol_checks.check_of(4, path) is None
  assert protocol_checks.protocol_note(_config(), 4, path) is None
