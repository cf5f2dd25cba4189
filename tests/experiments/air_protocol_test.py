"""experiments.studies.air_protocol's sets and summary (its runs are GPU-sized:
BENCHMARKS.md): the truths stay in their ranges, one fan setting a third, and
the summary's measures are the rows' own, by hand."""

from __future__ import annotations

import os

import numpy as np
import pytest

from experiments.studies import air_protocol


def test_each_set_has_its_own_air_and_a_fan_setting_per_third():
  study = air_protocol.Study(sets=50, seed=3)
  sets = air_protocol.truths(study)
  c = np.array([t['air_coefficient'] for t in sets])
  assert c.min() >= 0.4 and c.max() <= 1.25 and len(set(c)) == 50
  third = (4.0 - 1.5) / 3
  for t in sets:
    for k, v in enumerate(t['winds']):
      assert 1.5 + k * third < v < 1.5 + (k + 1) * third
  assert air_protocol.truths(study) == sets  # seeded


def test_the_summary_is_the_rows_own_by_hand():
  row = lambda c, air, held, flagged, mode='free': {  # noqa: E731
    'mode': mode, 'c': c, 'air': air, 'air_pct': 100 * abs(air / c - 1),
    'air_in_90': held, 'air_in_50': False, 'bending_factor': 1.1,
    'area_weight_pct': 1.0, 'wind_pct': [1.0, 2.0, 3.0], 'flagged': flagged,
  }  # fmt: skip
  rows = [row(0.5, 0.55, True, True), row(1.0, 0.9, False, False),
          row(0.6, 0.6, True, True, 'fixed'), row(1.05, 1.0, True, True, 'fixed')]  # fmt: skip
  s = air_protocol.summarise(rows)
  assert s['free']['air_pct_mean'] == pytest.approx(10.0)
  assert s['free']['air_held_90'] == 0.5 and s['free']['wind_pct_mean'] == 2.0
  assert s['free']['flagged_c_below_0.7'] == [1, 1]
  assert s['fixed']['flagged_c_below_0.7'] == [1, 1]
  assert s['fixed']['flagged_c_0.9_1.1'] == [1, 1]


def test_a_written_set_reads_back_as_the_protocol_it_was(tmp_path):
  """write_set's folder is a protocol file the estimate's readers take: each
  recording's depth, camera and reading, and the fabric's readings, as given."""
  import physsim
  from experiments.pipeline import recording as recording_lib
  from experiments.pipeline import takes
  from physsim import camera_files

  intr = physsim.Intrinsics(width=8, height=6)
  pose = physsim.Pose(np.eye(3, dtype=np.float32), np.array([0, -2, 0.5], np.float32))
  rng = np.random.default_rng(0)
  recs = [
    recording_lib.Recording(
      rng.uniform(1, 3, (4, 6, 8)).astype(np.float32), 30.0, intr, pose, f'f{j}', None
    )
    for j in range(2)
  ]
  shared = {'area_weight': 0.2, 'area_weight_sd': 0.002,
            'bending_length': 0.03, 'bending_length_sd': 0.001}  # fmt: skip
  winds = [(2.0, 0.04), (3.1, 0.06)]
  path = air_protocol.write_set(str(tmp_path / 'set'), recs, shared, winds)
  got = takes.read(path)
  assert [t.wind for t in got] == winds
  assert takes.fabric_readings(path) == pytest.approx(shared)
  for t, rec in zip(got, recs, strict=True):
    cam = camera_files.read_camera(t.camera_json)  # the intake's reader
    assert cam.fps == 30.0 and cam.intrinsics == intr
    np.testing.assert_allclose(cam.pose.position, pose.position)
    back = physsim.video.load_depth_video(
      t.path, source_fps=cam.fps, fps=30.0, size=None
    )
    np.testing.assert_array_equal(back.depth, rec.depth)
  assert not [p for p in os.listdir(tmp_path / 'set') if p.startswith('.')]


def test_intervals_held_reads_each_printed_interval():
  out = {
    'bending_scale': {'interval_90': (0.5, 2.0), 'interval_50': (0.9, 1.1)},
    'area_weight': {'interval_90': (0.1, 0.3), 'interval_50': (0.25, 0.3)},
    'recordings': [
      {'wind_speed': {'interval_90': (1.0, 2.0), 'interval_50': (1.4, 1.6)}},
      {'wind_speed': {'interval_90': (3.0, 4.0), 'interval_50': (3.0, 3.1)}},
    ],
  }
  truth = {'bending_scale': 1.0, 'area_weight': 0.2, 'winds': [1.5, 3.5]}
  h = air_protocol.intervals_held(out, truth)
  assert h['bending_90'] and h['bending_50'] and h['area_weight_90']
  assert not h['area_weight_50']
  assert h['wind_90'] == [True, True] and h['wind_50'] == [True, False]


def test_fan_settings_one_per_equal_share_of_the_range():
  for fans in (2, 3, 4):
    share = (4.0 - 1.5) / fans
    for t in air_protocol.truths(air_protocol.Study(sets=20, seed=4, fans=fans)):
      assert len(t['winds']) == fans
      for k, v in enumerate(t['winds']):
        assert 1.5 + k * share < v < 1.5 + (k + 1) * share
  for fans in (1, 5):  # one recording is no joint; refused before recording
    with pytest.raises(ValueError, match=f'--fans={fans}'):
      air_protocol.run(air_protocol.Study(fans=fans))


def test_pooled_runs_must_share_the_studys_settings(tmp_path):
  path = tmp_path / 'a.json'
  run = {'args': {'fans': 2}, 'rows': [{'mode': 'free'}]}
  air_protocol.files.write_json(str(path), run)
  with pytest.raises(ValueError, match='fans=2'):
    air_protocol.pooled((str(path),), air_protocol.Study())
  assert air_protocol.pooled((f'{path}:fixed',)) == []
  air_protocol.files.write_json(str(path), {'args': {}, 'rows': [{'mode': 'free'}]})
  assert len(air_protocol.pooled((str(path),), air_protocol.Study())) == 1  # defaults
  # sets whose cameras or strips were read otherwise are another check's
  for ran, name in (({'camera_sd_m': 0.03}, 'camera_sd_m'), ({'length_dof': 10.0},
                    'length_dof')):  # fmt: skip
    air_protocol.files.write_json(str(path), {'args': ran, 'rows': [{'mode': 'free'}]})
    with pytest.raises(ValueError, match=name):
      air_protocol.pooled((str(path),), air_protocol.Study())


def test_pooled_interval_checks_of_named_quantities_only(tmp_path):
  """A run from before a change of the wind's interval pools its bending and
  area weight checks only: the wind's coverage and its count come from the
  other run, the others' from both."""
  held = lambda b, w: {  # noqa: E731
    'bending_90': b, 'bending_50': b, 'area_weight_90': b, 'area_weight_50': b,
    'wind_90': [w, w, w], 'wind_50': [w, w, w],
  }  # fmt: skip
  row = lambda h: {  # noqa: E731
    'mode': 'free', 'c': 1.0, 'air': 1.0, 'air_pct': 0.0, 'air_in_90': True,
    'air_in_50': True, 'bending_factor': 1.0, 'area_weight_pct': 0.0,
    'wind_pct': [0.0, 0.0, 0.0], 'flagged': False, 'held': h,
  }  # fmt: skip
  old, new = tmp_path / 'old.json', tmp_path / 'new.json'
  air_protocol.files.write_json(str(old), {'args': {}, 'rows': [row(held(True, True))]})
  air_protocol.files.write_json(
    str(new), {'args': {}, 'rows': [row(held(False, False))]}
  )
  rows = air_protocol.pooled((f'{old}:free:bending+area_weight', str(new)))
  s = air_protocol.summarise(rows)['free']
  assert s['held']['wind_90'] == 0.0 and s['held_n']['wind_90'] == 1
  assert s['held']['bending_90'] == 0.5 and s['held_n']['bending_90'] == 2
  with pytest.raises(ValueError, match='air'):
    air_protocol.pooled((f'{old}:free:air',))


def test_printed_keeps_each_interval_beside_its_truth():
  iv = lambda m, a, b, c, d: {  # noqa: E731
    'median': m,
    'interval_90': (a, b),
    'interval_50': (c, d),
  }
  out = {
    'bending_scale': iv(1.1, 0.5, 2.0, 0.9, 1.2),
    'area_weight': iv(0.2, 0.1, 0.3, 0.15, 0.25),
    'air_coefficient': iv(0.8, 0.6, 1.0, 0.7, 0.9),
    'recordings': [{'wind_speed': iv(2.0, 1.5, 2.5, 1.8, 2.2)}] * 2,
  }
  truth = {'bending_scale': 1.0, 'area_weight': 0.2, 'air_coefficient': 0.75,
           'winds': [1.9, 2.4]}  # fmt: skip
  p = air_protocol.printed(out, truth)
  assert p['air_coefficient']['truth'] == 0.75
  assert p['bending_scale']['interval_50'] == (0.9, 1.2)
  assert [w['truth'] for w in p['wind_speed']] == [1.9, 2.4]
  assert 'air_coefficient' not in air_protocol.printed(
    {k: v for k, v in out.items() if k != 'air_coefficient'}, truth
  )
