"""Property-based fuzzing of what a user hands the estimate (issue 40, item 5):
camera files, frame folders, arrays and flags.

* the readers (``camera_files.read_camera``, ``video.load_depth_video``,
  the configs' checks) on arbitrary inputs: each either reads it or raises a
  ``ValueError`` naming the file or flag, never another exception;
* the intake through ``experiments.estimate.main`` (in-process) on inputs
  made surely bad by one mutation of a good recording: refused by name, and
  the workdir (holding an earlier intake of the same recording) unchanged;
* a few through the real command line: exit status 2 and one line on stderr.

Derandomized, no example database: every run tries the same inputs.
``N_EXAMPLES`` counts them (>= 500 in all).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile

import cv2
import numpy as np
import pytest
from absl import flags as absl_flags
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from experiments import estimate
from experiments.pipeline import cli, intake, objective
from physsim import bags, camera_files, video
from tests.experiments.bad_inputs_test import png_header_only, tree_digest

_ROOT = pathlib.Path(__file__).resolve().parents[2]
_SMOKE = objective.PRESETS['smoke']
N_EXAMPLES = {
  'camera': 400,
  'camera_text': 150,
  'array': 300,
  'folder': 120,
  'flags': 300,
  'pipeline': 250,
  'command_line': 6,
  'bag': 60,
}


def _settings(name):
  return settings(
    max_examples=N_EXAMPLES[name], deadline=None, derandomize=True, database=None,
    suppress_health_check=list(HealthCheck),
  )  # fmt: skip


def one_line(e: BaseException) -> str:
  return cli.one_line(e)


def assert_names(e: BaseException, *names: str) -> None:
  line = one_line(e)
  assert '\n' not in line and any(n in line for n in names), (line, names)


# --- values ----------------------------------------------------------------

_NUMBERS = st.one_of(
  st.integers(-(10**20), 10**20),
  st.floats(allow_nan=True, allow_infinity=True),
  st.sampled_from([0, -1, 1e-300, 1e300, 10**400]),
)
_SCALARS = st.one_of(
  _NUMBERS,
  st.text(max_size=8),
  st.booleans(),
  st.none(),
)
_VALUES = st.recursive(
  _SCALARS,
  lambda inner: st.one_of(
    st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=6), inner, max_size=4)
  ),
  max_leaves=20,
)

_GOOD_CAMERA = {
  'width': 160, 'height': 120, 'fx': 140.0, 'fy': 140.0, 'cx': 80.0, 'cy': 60.0,
  'fps': 20, 'cam_to_world': np.eye(4).tolist(),
}  # fmt: skip
_CAMERA_KEYS = [
  *_GOOD_CAMERA, 'K', 'k', 'D', 'camera_matrix', 'image_width', 'image_height',
  'distortion', 'distortion_coefficients', 'ppx', 'ppy', 'coeffs',
  'intrinsic_matrix', 'world_to_cam', 'axes', 'intrinsics', 'extrinsics',
  'gravity', 'notes',
]  # fmt: skip


@st.composite
def camera_dicts(draw):
  """A valid camera with a few keys set to anything, added or removed."""
  d = dict(_GOOD_CAMERA)
  for _ in range(draw(st.integers(1, 4))):
    key = draw(st.sampled_from(_CAMERA_KEYS))
    if draw(st.booleans()) and key in d:
      del d[key]
    else:
      d[key] = draw(_VALUES)
  return d


def _write(path, text: str | bytes) -> str:
  mode = 'wb' if isinstance(text, bytes) else 'w'
  with open(path, mode) as f:
    f.write(text)
  return str(path)


@pytest.fixture(scope='module')
def scratch():
  with tempfile.TemporaryDirectory(prefix='fuzz-') as d:
    yield d


# --- readers ----------------------------------------------------------------


@_settings('camera')
@given(d=camera_dicts(), yaml=st.booleans())
def test_camera_files_are_read_or_refused_by_name(scratch, d, yaml):
  path = os.path.join(scratch, 'camera.yaml' if yaml else 'camera.json')
  _write(path, json.dumps(d))  # JSON is YAML too
  try:
    cam = camera_files.read_camera(path)
  except ValueError as e:
    assert_names(e, path)
    return
  assert cam.intrinsics.width >= 1 and math.isfinite(cam.intrinsics.fx)


@_settings('camera_text')
@given(
  raw=st.one_of(
    st.binary(max_size=200),
    st.text(max_size=200),
    st.integers(1, 20_000).map(lambda n: '{"a":' * n + '1' + '}' * n),
    st.integers(1, 20_000).map(lambda n: 'a:\n' + '- ' * n + '1'),
  ),
  yaml=st.booleans(),
)
def test_camera_file_bytes_are_read_or_refused_by_name(scratch, raw, yaml):
  path = os.path.join(scratch, 'raw.yaml' if yaml else 'raw.json')
  _write(path, raw)
  try:
    camera_files.read_camera(path)
  except ValueError as e:
    assert_names(e, path)


_DTYPES = st.sampled_from(['<f4', '<f8', '<f2', '<i2', '<u2', '|u1', '|b1', '<c8'])


@st.composite
def arrays(draw):
  shape = draw(
    st.lists(st.integers(0, 6), min_size=0, max_size=4).map(tuple)
    | st.sampled_from([(3, 48, 64), (2, 24, 32), (1, 3, 4)])
  )
  dtype = np.dtype(draw(_DTYPES))
  fill = draw(st.sampled_from(['good', 'nan', 'inf', 'neg', 'mm', 'zero', 'random']))
  a = (
    np.full(shape, 2.0)
    if fill != 'random'
    else np.random.default_rng(draw(st.integers(0, 9))).uniform(-1, 30, shape)
  )
  if a.size and fill != 'good' and fill != 'random':
    a.flat[draw(st.integers(0, a.size - 1))] = {
      'nan': np.nan, 'inf': np.inf, 'neg': -1.0, 'mm': 2000.0, 'zero': 0.0,
    }[fill]  # fmt: skip
  with np.errstate(invalid='ignore', over='ignore'):
    return a.astype(dtype)


@_settings('array')
@given(
  depth=arrays(),
  fps=st.one_of(st.none(), _NUMBERS, st.lists(st.floats(0, 100), max_size=3)),
  npz=st.booleans(),
  extra=st.booleans(),
)
def test_arrays_are_read_or_refused_by_name(scratch, depth, fps, npz, extra):
  path = os.path.join(scratch, 'rec.npz' if npz else 'rec.npy')
  if npz:
    arrays_ = {'depth': depth}
    if fps is not None:
      try:
        arrays_['fps'] = np.asarray(fps)
      except OverflowError:
        arrays_['fps'] = np.asarray(str(fps))
    if extra:
      arrays_['other'] = np.zeros(2)
    np.savez(path, **arrays_)
  else:
    np.save(path, depth)
  try:
    vid = video.load_depth_video(path, source_fps=None, fps=None, size=None)
  except ValueError as e:
    assert_names(e, path)
    return
  assert np.isfinite(vid.depth).all() and (vid.depth >= 0).all()
  assert vid.depth.ndim == 3 and (vid.depth > 0).any(axis=(1, 2)).all()


@st.composite
def frame_folders(draw, root):
  folder = tempfile.mkdtemp(dir=root)
  n = draw(st.integers(0, 4))
  for t in range(n):
    kind = draw(
      st.sampled_from(['mm', 'mm', 'u8', 'rgb16', 'header', 'bytes', 'other_size'])
    )
    name = os.path.join(folder, f'{t}.png')
    if kind == 'header':
      png_header_only(name, draw(st.integers(1, 20_000)), draw(st.integers(1, 20_000)))
    elif kind == 'bytes':
      _write(name, draw(st.binary(max_size=64)))
    else:
      h, w = (30, 40) if kind == 'other_size' else (48, 64)
      value = draw(st.sampled_from([0, 1, 2000, 60000]))
      img = np.full((h, w), value, np.uint16)
      if kind == 'u8':
        img = img.astype(np.uint8)
      elif kind == 'rgb16':
        img = np.stack([img] * 3, -1)
      assert cv2.imwrite(name, img)
  if draw(st.booleans()):
    _write(os.path.join(folder, 'fps.txt'), draw(st.sampled_from(['20', 'x', '0', ''])))
  return folder


@_settings('folder')
@given(data=st.data())
def test_frame_folders_are_read_or_refused_by_name(scratch, data):
  folder = data.draw(frame_folders(scratch))
  try:
    vid = video.load_depth_video(folder, fps=None, size=None)
  except ValueError as e:
    assert_names(e, folder)
    return
  assert np.isfinite(vid.depth).all() and vid.depth.ndim == 3


_FLAG_VALUES = st.one_of(
  st.sampled_from(['nan', 'inf', '-inf', '-1', '0', '1e300', '-1e300', '3', '']),
  st.floats(allow_nan=True, allow_infinity=True).map(repr),
  st.integers(-(10**12), 10**12).map(str),
  st.text(alphabet='0123456789.,-eEnaif', max_size=12),
)
_NUMERIC_FLAGS = [
  leaf.flag
  for leaf in cli.leaves(estimate.Args)
  if cli._parser(leaf.type, leaf.flag)[0] in ('int', 'float')
  or cli._parser(leaf.type, leaf.flag)[1] in (int, float)
]


def _check_all(args: estimate.Args) -> None:
  """What ``estimate.main`` checks before reading anything."""
  cli.check_numbers(args)
  args.search.check()
  args.intake.check()
  estimate.recording_takes(args)


@_settings('flags')
@given(
  chosen=st.lists(
    st.tuples(st.sampled_from(_NUMERIC_FLAGS), _FLAG_VALUES), min_size=1, max_size=3
  )
)
def test_numeric_flags_are_taken_or_refused_by_name(chosen):
  argv = ['estimate', '--recording=a'] + [f'--{n}={v}' for n, v in chosen]
  try:
    args = cli.parse(estimate.Args, estimate.PRESETS, argv)
    _check_all(args)
  except absl_flags.Error as e:  # cli.run prints it as one line (exit 2)
    assert_names(e, *(n for n, _ in chosen))
    return
  except ValueError as e:
    fields = [n for n, _ in chosen] + ['fps', 'replicates', 'q', 'frames', 'grid']
    assert_names(e, *fields, 'wind_speed', 'sharpness', 'gusts', 'max_iter')
    return
  for name, _ in chosen:
    leaf = next(leaf for leaf in cli.leaves(estimate.Args) if leaf.flag == name)
    value = cli._get(args, leaf.path)
    for v in value if isinstance(value, tuple) else (value,):
      assert math.isfinite(v), (name, value)


# --- the intake through estimate.main: surely bad, workdir unchanged ---------


def _good_recording(root) -> tuple[str, str]:
  folder = os.path.join(root, 'frames')
  os.makedirs(folder, exist_ok=True)
  depth = np.full((48, 64), 2500, np.uint16)
  depth[8:40, 16:48] = 2000
  for t in range(4):
    cv2.imwrite(os.path.join(folder, f'{t}.png'), depth)
  cam = os.path.join(root, 'camera.json')
  _write(cam, json.dumps(dict(_GOOD_CAMERA, width=64, height=48, cx=32, cy=24, fx=56,
                              fy=56)))  # fmt: skip
  return folder, cam


_BAD_CAMERA_VALUES = {
  'width': [0, -4, 'wide', None, 10**6, 1e400, [64]],
  'fx': [0, -56.0, 'f', None, float('nan'), float('inf')],
  'fps': [0, -20, 'x', 1e9, float('nan'), [20]],
  'cam_to_world': [np.zeros((4, 4)).tolist(), [[1, 0], [0, 1]], 'eye', [[float('nan')] * 4] * 4],
  'height': [0, 7, 10**7],
}  # fmt: skip


@st.composite
def bad_runs(draw, root):
  """(args, the names a refusal must mention): one surely bad mutation."""
  frames, cam = _good_recording(root)
  kind = draw(st.sampled_from(['camera', 'camera_bytes', 'frames', 'array', 'flag']))
  base = dict(recording=(frames,), camera_json=cam)
  names = []
  if kind == 'camera':
    key = draw(st.sampled_from(sorted(_BAD_CAMERA_VALUES)))
    d = json.loads(open(cam).read())
    d[key] = draw(st.sampled_from(_BAD_CAMERA_VALUES[key]))
    bad = os.path.join(root, 'bad_camera.json')
    _write(bad, json.dumps(d))
    base['camera_json'], names = bad, [bad]
  elif kind == 'camera_bytes':
    bad = os.path.join(root, 'bad_camera.json')
    _write(bad, draw(st.sampled_from([b'', b'\xff\xfe', b'[]', b'{', b'null'])) + draw(
      st.binary(max_size=4)).replace(b'}', b''))  # fmt: skip
    base['camera_json'], names = bad, [bad]
  elif kind == 'frames':
    folder = tempfile.mkdtemp(dir=root)
    how = draw(st.sampled_from(['tiny', 'header', 'bytes', 'empty', 'u8', 'aspect']))
    for t in range(3):
      name = os.path.join(folder, f'{t}.png')
      if how == 'tiny':
        cv2.imwrite(name, np.full((3, 4), 2000, np.uint16))
      elif how == 'header':
        png_header_only(name, 12000, 9000)
      elif how == 'bytes':
        _write(name, draw(st.binary(max_size=32)))
      elif how == 'u8':
        cv2.imwrite(name, np.full((48, 64), 200, np.uint8))
      elif how == 'aspect':
        cv2.imwrite(name, np.full((64, 64), 2000, np.uint16))
    base['recording'], names = (folder,), [folder, cam]
  elif kind == 'array':
    path = os.path.join(root, 'rec.npz')
    depth = np.full((4, 48, 64), 2.0, np.float32)
    how = draw(st.sampled_from(['nan', 'neg', 'mm', 'rank', 'fps', 'zero']))
    fps = 20.0
    if how in ('nan', 'neg', 'mm', 'zero'):
      depth[draw(st.integers(0, 3)), 5, 5] = {
        'nan': np.nan, 'neg': -1, 'mm': 2500.0, 'zero': 0.0
      }[how]  # fmt: skip
      if how == 'zero':
        depth[1] = 0
    elif how == 'rank':
      depth = depth[0]
    else:
      fps = draw(st.sampled_from([np.array([20.0, 30.0]), np.array('x'), np.zeros(0)]))
    np.savez(path, depth=depth, fps=fps)
    base['recording'], names = (path,), [path]
  else:
    name = draw(st.sampled_from(
      ['sharpness', 'camera_sd_m', 'depth_scale', 'plane_tol', 'min_overlap', 'fps',
       'gusts', 'warmup']))  # fmt: skip
    value = draw(st.sampled_from([float('nan'), float('inf'), float('-inf'), -1e9]))
    if name in ('depth_scale', 'plane_tol', 'min_overlap', 'fps'):
      base['intake'] = dataclasses.replace(intake.IntakeConfig(), **{name: value})
    else:
      base['search'] = _SMOKE.replace(**{name: value})
    names = [name]
  return dict({'search': _SMOKE}, **base), names


@_settings('pipeline')
@given(data=st.data())
def test_bad_intakes_are_refused_and_change_no_workdir(scratch, data):
  root = tempfile.mkdtemp(dir=scratch)
  kw, names = data.draw(bad_runs(root))
  workdir = os.path.join(root, 'work')
  os.makedirs(os.path.join(workdir, 'intake'))
  # An earlier intake of the same recording, which a refused one must keep.
  _write(
    os.path.join(workdir, 'intake.json'),
    json.dumps({'source': os.path.abspath(kw['recording'][0])}),
  )
  _write(os.path.join(workdir, 'overlay.png'), b'earlier overlay')
  _write(os.path.join(workdir, 'intake', '0000.png'), b'earlier frame')
  before = tree_digest(workdir)
  args = estimate.Args(workdir=workdir, intake_only=True, **kw)
  with pytest.raises(ValueError) as e:
    estimate.main(args)
  assert_names(e.value, *names)
  assert tree_digest(workdir) == before


# --- the real command line ---------------------------------------------------


@_settings('command_line')
@given(data=st.data())
def test_the_command_line_says_one_line_and_exits_2(scratch, data):
  root = tempfile.mkdtemp(dir=scratch)
  kw, names = data.draw(bad_runs(root))
  workdir = os.path.join(root, 'work')
  os.makedirs(workdir)
  _write(os.path.join(workdir, 'notes.txt'), 'mine')
  before = tree_digest(workdir)
  argv = [f'--recording={kw["recording"][0]}', f'--camera_json={kw["camera_json"]}',
          f'--workdir={workdir}', '--intake_only', '--preset=smoke']  # fmt: skip
  for name in names:
    if name in ('sharpness', 'camera_sd_m', 'gusts', 'warmup'):
      argv.append(f'--{name}={getattr(kw["search"], name)}')
    elif name in ('depth_scale', 'plane_tol', 'min_overlap', 'fps'):
      argv.append(f'--{name}={getattr(kw["intake"], name)}')
  out = subprocess.run(
    [sys.executable, '-m', 'experiments.estimate', *argv], cwd=_ROOT,
    env=dict(os.environ, PYTHONPATH=str(_ROOT), JAX_PLATFORMS='cpu'),
    capture_output=True, text=True, timeout=300,
  )  # fmt: skip
  lines = out.stderr.strip().splitlines()
  assert out.returncode == 2, out.stderr
  assert len(lines) == 1 and lines[0].startswith('error: '), lines
  assert any(n in lines[0] for n in names), (lines, names)
  assert tree_digest(workdir) == before


def test_the_suite_tries_500_inputs_or_more():
  assert sum(N_EXAMPLES.values()) >= 500


# --- bags ---------------------------------------------------------------------


@pytest.fixture(scope='module')
def bag_bytes(tmp_path_factory):
  pytest.importorskip('rosbags')
  from rosbags.typesys import Stores  # noqa: PLC0415

  from tests.physsim.bags_test import write_bag  # noqa: PLC0415

  path, _, _ = write_bag(
    tmp_path_factory.mktemp('bag') / 'rec.bag', Stores.ROS1_NOETIC, frames=3, tf=False
  )
  return pathlib.Path(path).read_bytes()


@_settings('bag')
@given(data=st.data())
def test_damaged_bags_are_read_or_refused_by_name(scratch, bag_bytes, data):
  raw = bytearray(bag_bytes)
  how = data.draw(st.sampled_from(['truncate', 'flip', 'both']))
  if how in ('truncate', 'both'):
    raw = raw[: data.draw(st.integers(0, len(raw)))]
  if how in ('flip', 'both') and raw:
    for _ in range(data.draw(st.integers(1, 8))):
      i = data.draw(st.integers(0, len(raw) - 1))
      raw[i] = data.draw(st.integers(0, 255))
  path = _write(os.path.join(scratch, 'damaged.bag'), bytes(raw))
  try:
    rec = bags.read_bag(path)
  except ValueError as e:
    assert_names(e, path)
    return
  assert np.isfinite(rec.depth).all() and rec.depth.ndim == 3
