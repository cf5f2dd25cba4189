"""Tests for experiments/pipeline/takes.py and estimate's --protocol and
--cloth_sizes: each recording's own set-up read from a protocol file (JSON
or YAML, paths relative to it) or from flags, and every bad entry refused in
one line naming the file, the entry and the key before any recording is read."""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest

from experiments import estimate
from experiments.pipeline import takes, user_recordings
from physsim import overhang_depth
from tests import blocking
from tests.experiments import overhang_fixtures


@pytest.fixture
def folder(tmp_path):
  for name in ('sheet', 'swatch'):
    (tmp_path / name).mkdir()
    (tmp_path / name / 'camera.json').write_text('{}')
  return tmp_path


def _write(path, data):
  path.write_text(json.dumps(data))
  return str(path)


def test_a_protocol_file_gives_each_recording_its_own_set_up(folder):
  path = _write(folder / 'protocol.json', {'recordings': [
    {'recording': 'sheet', 'camera_json': 'sheet/camera.json', 'wind_speed': 2.1,
     'wind_speed_sd': 0.05},
    {'recording': 'swatch', 'camera_json': 'swatch/camera.json', 'cloth_size': 0.25,
     'world_up': 'z'},
  ]})  # fmt: skip
  sheet, swatch = takes.read(path)
  assert sheet == takes.Take(
    str(folder / 'sheet'), str(folder / 'sheet' / 'camera.json'), 0.0, (2.1, 0.05)
  )
  assert (swatch.cloth_size, swatch.wind, swatch.world_up) == (0.25, None, 'z')
  yaml_path = folder / 'protocol.yaml'
  yaml_path.write_text('recordings:\n  - recording: swatch\n    cloth_size: 0.3\n')
  assert takes.read(str(yaml_path)) == [takes.Take(str(folder / 'swatch'), '', 0.3)]


@pytest.mark.parametrize(
  'entry, message',
  [
    ({'recording': 'nowhere'}, r'recordings\[0\]: "recording" .*nowhere: no such'),
    ({'recording': 'sheet', 'size': 1},
     r"recordings\[0\]: unknown key 'size' \(did you mean \"cloth_size\"\?\)"),
    ({'recording': 'sheet', 'cloth_size': 0.01}, r'"cloth_size"=0.01 must be in'),
    ({'recording': 'sheet', 'cloth_size': 'big'}, r'"cloth_size" must be a number'),
    ({'recording': 'sheet', 'wind_speed': 2.0}, r'"wind_speed_sd" come together'),
    ({'recording': 'sheet', 'world_up': 'up'}, r'"world_up"=\'up\' must be one of'),
    ({'recording': 'sheet', 'wind_speed': 2.0, 'wind_speed_sd': 0},
     r'"wind_speed_sd"=0 must be in'),
  ],
)  # fmt: skip
def test_a_bad_entry_is_refused_naming_file_entry_and_key(folder, entry, message):
  path = _write(folder / 'p.json', {'recordings': [entry]})
  with pytest.raises(ValueError, match=message) as e:
    takes.read(path)
  assert str(e.value).startswith(path) and '\n' not in str(e.value)


@pytest.mark.parametrize('text', ['[1, 2', '{"recordings": []}', '[]', '{"a": 1}'])
def test_a_file_that_is_no_protocol_is_refused(folder, text):
  path = folder / 'p.json'
  path.write_text(text)
  with pytest.raises(
    ValueError, match=r'p.json: (not a readable|needs "recordings"|unknown key)'
  ):
    takes.read(str(path))


def test_a_misspelt_top_level_key_is_refused_not_dropped(folder):
  """ "fabrik" would drop the scale's reading without a word."""
  path = _write(folder / 'p.json', {'recordings': [{'recording': 'sheet'}],
                                    'fabrik': {'area_weight': 0.2}})  # fmt: skip
  for read in (takes.read, takes.fabric_readings, takes.fabric_overhang):
    with pytest.raises(ValueError, match=r"unknown key 'fabrik' \(did you mean") as e:
      read(path)
    assert str(e.value).startswith(path)
  path = _write(folder / 'q.json', {'recordings': [{'recording': 'sheet'}],
                                    'fabric': {'area_wieght': 0.2}})  # fmt: skip
  with pytest.raises(ValueError, match=r"q.json: fabric: unknown key 'area_wieght'"):
    takes.fabric_readings(path)


def test_one_recording_listed_twice_is_refused(folder):
  path = _write(folder / 'p.json', {'recordings': [
    {'recording': 'sheet', 'fan': 'low'}, {'recording': 'swatch'},
    {'recording': './sheet/', 'fan': 'low'},
  ]})  # fmt: skip
  with pytest.raises(
    ValueError, match=r'recordings\[2\] "recording" is recordings\[0\]'
  ):
    takes.read(path)


def test_a_yaml_alias_bomb_is_refused_quickly_in_one_short_line(folder):
  lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
  for i in range(1, 9):
    prev, cur = chr(ord('a') + i - 1), chr(ord('a') + i)
    lines.append(f'{cur}: &{cur} [' + ', '.join([f'*{prev}'] * 9) + ']')
  lines.append('recordings: [{recording: sheet, fan: *i}]')
  path = folder / 'p.yaml'
  path.write_text('\n'.join(lines) + '\n')
  assert path.stat().st_size < 700
  t0 = time.perf_counter()
  with pytest.raises(ValueError, match='aliases') as e:
    takes.read(str(path))
  assert time.perf_counter() - t0 < 1.0
  msg = str(e.value)
  assert msg.startswith(str(path)) and '\n' not in msg and len(msg) <= 300


@pytest.mark.parametrize(
  'entry',
  [{'recording': 'sheet', 'fan': 'x' * 100_000},
   {'recording': 'sheet', 'world_up': ['z'] * 50_000},
   {'recording': 'sheet', 'cloth_size': 10**400},
   {'recording': 'sheet', 'x' * 50_000: 1},
   {'recording': 'y' * 5000}],
)  # fmt: skip
def test_a_long_value_is_shown_by_its_type_and_size(folder, entry):
  path = _write(folder / 'p.json', {'recordings': [entry]})
  with pytest.raises(ValueError) as e:
    takes.read(path)
  msg = str(e.value)
  assert msg.startswith(path) and '\n' not in msg and len(msg) <= 300, msg


def test_a_fifo_is_refused_by_name_never_opened(folder):
  fifo = str(folder / 'p.json')
  os.mkfifo(fifo)
  with pytest.raises(ValueError, match='FIFO') as e:
    blocking.in_thread(lambda: takes.read(fifo))
  assert str(e.value).startswith(fifo)
  os.mkfifo(folder / 'sheet' / 'cam.json')
  path = _write(folder / 'q.json', {'recordings': [
    {'recording': 'sheet', 'camera_json': 'sheet/cam.json'}]})  # fmt: skip
  with pytest.raises(ValueError, match=r'recordings\[0\]: "camera_json" .*FIFO'):
    blocking.in_thread(lambda: takes.read(path))


def test_flags_give_one_size_per_recording():
  got = takes.from_flags(('a', 'b'), 'c.json', (1.0, 0.25), [(2.0, 0.1), (3.0, 0.1)])
  assert [(t.path, t.camera_json, t.cloth_size, t.wind) for t in got] == [
    ('a', 'c.json', 1.0, (2.0, 0.1)), ('b', 'c.json', 0.25, (3.0, 0.1)),
  ]  # fmt: skip
  with pytest.raises(ValueError, match=r'--cloth_sizes=1.0: need one size for each'):
    takes.from_flags(('a', 'b'), cloth_sizes=(1.0,))
  with pytest.raises(ValueError, match=r'--cloth_sizes: "cloth_size"=9.0 must be in'):
    takes.from_flags(('a', 'b'), cloth_sizes=(1.0, 9.0))


def test_estimate_takes_a_protocol_or_recordings_not_both(folder):
  path = _write(folder / 'p.json', {'recordings': [{'recording': 'sheet'}]})
  both = estimate.Args(protocol=path, recording=('x',))
  with pytest.raises(ValueError, match=r'give it without --recording'):
    estimate.recording_takes(both)
  with pytest.raises(ValueError, match=r'missing --recording or --protocol'):
    estimate.recording_takes(estimate.Args())
  with pytest.raises(ValueError, match=r'--cloth_sizes is for several recordings'):
    estimate.recording_takes(estimate.Args(recording=('a',), cloth_sizes=(0.3,)))
  (take,) = estimate.recording_takes(estimate.Args(protocol=path))
  flags = estimate.Args()
  settings = lambda t: user_recordings.take_settings(flags.intake, flags.search, t)
  ik, config = settings(take._replace(cloth_size=0.3))
  assert config.simulation.cloth_size == 0.3 and ik == flags.intake
  ik, config = settings(take._replace(world_up='-y', wind=(2.0, 0.1)))
  assert ik.world_up == '-y' and config.measured.wind_speed == 2.0
  _, config = settings(take._replace(hem_mass=0.3))
  assert config.simulation.hem_mass == 0.3
  # the joint's per-recording settings: a hem is one of them, no hem none
  assert user_recordings.own_settings(config)['hem_mass'] == 0.3
  assert 'hem_mass' not in user_recordings.own_settings(flags.search)


def test_a_protocol_file_gives_the_fabrics_own_readings(folder):
  fabric = {'area_weight': 0.185, 'area_weight_sd': 0.003,
            'bending_length': 0.016, 'bending_length_sd': 0.001}  # fmt: skip
  path = _write(folder / 'p.json', {'recordings': [{'recording': 'sheet'}],
                                    'fabric': fabric})  # fmt: skip
  assert takes.fabric_readings(path) == fabric
  args = estimate.with_fabric_readings(estimate.Args(protocol=path))
  m = args.search.measured
  assert (m.area_weight, m.bending_length_sd) == (0.185, 0.001)
  args.search.check()  # gray interlock: both readings inside its box
  # the same reading as a flag too: refused, naming both places
  flagged = estimate.Args(protocol=path).search.replace(area_weight=0.2,
                                                        area_weight_sd=0.01)  # fmt: skip
  with pytest.raises(
    ValueError, match=r"gives the fabric's area_weight.*--area_weight"
  ):
    estimate.with_fabric_readings(estimate.Args(protocol=path, search=flagged))
  # none given: the flags' own
  bare = _write(folder / 'q.json', {'recordings': [{'recording': 'sheet'}]})
  assert takes.fabric_readings(bare) == {}
  # a depth camera's reading with its t law (experiments.overhang prints it)
  t = _write(folder / 't.json', {'recordings': [{'recording': 'sheet'}],
                                 'fabric': {**fabric, 'bending_length_dof': 4}})  # fmt: skip
  m = estimate.with_fabric_readings(estimate.Args(protocol=t)).search.measured
  assert m.bending_length_dof == 4.0


def test_a_protocol_files_overhang_recording_gives_the_bending_length(folder):
  """The fabric's strip filmed over a table's edge, named in the file: read
  once, at the edge, into the estimate's bending length."""
  overhang_fixtures.write_overhang_recording(str(folder), 0.02, 0.04)
  strip = {'recording': 'strip', 'camera_json': 'strip_camera.json', 'length': 0.04}
  path = _write(folder / 'p.json', {'recordings': [{'recording': 'sheet'}],
                                    'fabric': {'overhang': strip}})  # fmt: skip
  spec = takes.fabric_overhang(path)
  assert spec.path == str(folder / 'strip') and spec.length_sd == 0.001
  m = estimate.with_fabric_readings(estimate.Args(protocol=path)).search.measured
  assert m.bending_length == pytest.approx(0.02, rel=0.02)
  # the reader's t law: at least its floor and half the ruler's 1 mm share of
  # c (the spec's 4 cm overhang), times sqrt(dof / (dof - 2))
  assert m.bending_length_dof == overhang_depth.DOF
  least = max(overhang_depth.FLOOR, 0.5 * 0.001 / 0.04) * m.bending_length
  assert m.bending_length_sd >= least * np.sqrt(
    m.bending_length_dof / (m.bending_length_dof - 2)
  )
  # the overhang beside a bending length, a missing file, a bad key
  for fabric, message in (
    ({'overhang': strip, 'bending_length': 0.02, 'bending_length_sd': 0.001},
     'not both'),
    ({'overhang': {**strip, 'recording': 'nowhere'}}, 'no such file'),
    ({'overhang': {**strip, 'reach': 0.03}}, r"unknown key 'reach'"),
    ({'overhang': {k: v for k, v in strip.items() if k != 'length'}}, 'needs "length"'),
  ):  # fmt: skip
    bad = _write(folder / 'b.json', {'recordings': [{'recording': 'sheet'}],
                                     'fabric': fabric})  # fmt: skip
    with pytest.raises(ValueError, match=message):
      takes.fabric_overhang(bad)


@pytest.mark.parametrize(
  ('fabric', 'message'),
  [
    ({'area_weight': 0.2}, r'"area_weight" and "area_weight_sd" come together'),
    ({'weight': 0.2}, r"unknown key 'weight'"),
    ({'bending_length': 5.0, 'bending_length_sd': 0.1}, r'"bending_length"=5.0 must be in'),
    ([0.2], r'must be an object of readings'),
    ({'bending_length_dof': 4}, r'"bending_length_dof" without "bending_length"'),
    ({'bending_length': 0.02, 'bending_length_sd': 0.001, 'bending_length_dof': 1.5},
     r'"bending_length_dof"=1.5: 0 \(Gaussian\) or more than 2'),
    ({'bending_length': 0.02, 'bending_length_sd': 0.001, 'bending_length_dof': 'x'},
     r'"bending_length_dof" must be a number'),
  ],
)  # fmt: skip
def test_a_bad_fabric_reading_is_refused_naming_file_and_key(folder, fabric, message):
  path = _write(folder / 'p.json', {'recordings': [{'recording': 'sheet'}],
                                    'fabric': fabric})  # fmt: skip
  with pytest.raises(ValueError, match=message) as e:
    takes.fabric_readings(path)
  assert str(e.value).startswith(path) and '\n' not in str(e.value)
