"""Property-based fuzzing of the newer surfaces (issue 78): protocol files,
``experiments.plan``'s settings and the estimate files it reads, and ROS 2
bag folders.

Each reader either reads its input or raises a ``ValueError`` whose one line
(at most 300 characters) names the file or flag, within a second, never
another exception and never a hang.

Derandomized, no example database: every run tries the same inputs. The
fast tier tries ``N_EXAMPLES`` of each surface (a few seconds each);
``PHYSNET_FUZZ_EXAMPLES=500`` (or more) tries that many of each::

  PHYSNET_FUZZ_EXAMPLES=500 python -m pytest -q tests/experiments/fuzz_files_test.py
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import tempfile
import time

import numpy as np
import pytest
from absl import flags as absl_flags
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from experiments import plan as plan_script
from experiments.pipeline import cli, layout, takes
from experiments.studies import protocol_config, protocol_plan

N_EXAMPLES = {
  'protocol': 40,
  'protocol_text': 40,
  'plan_flags': 60,
  'estimate_files': 40,
  'bag_folder': 25,
}
_BIG = int(os.environ.get('PHYSNET_FUZZ_EXAMPLES', '0') or 0)
# An error line's longest; a reader's answer's slowest (s: a hang guard on a
# loaded machine; the alias bomb's own bound is takes_test's).
MAX_LINE = cli.MAX_LINE
MAX_SECONDS = 10.0


def _settings(name, *, shrink: bool = True):
  """``shrink=False`` for a surface with a known failure (xfail): the first
  failing input ends it, without minutes spent minimising it."""
  phases = [Phase.explicit, Phase.reuse, Phase.generate] + [Phase.shrink] * shrink
  return settings(
    max_examples=max(N_EXAMPLES[name], _BIG), deadline=None, derandomize=True,
    database=None, suppress_health_check=list(HealthCheck), phases=phases,
  )  # fmt: skip


def refused_by_name(e: BaseException, *names: str) -> None:
  """One line naming one of ``names``: this project's refusals at most
  ``MAX_LINE`` as raised; absl's (which echo a flag's whole value) as
  ``cli.one_line`` prints them, cut to ``MAX_LINE``."""
  ours = not isinstance(e, absl_flags.Error)
  line = ' '.join(str(e).split()) if ours else cli.one_line(e)
  assert len(line) <= MAX_LINE, (len(line), line[:400])
  assert any(n in line for n in names), (line, names)


def _timed(fn):
  """fn()'s value or ValueError, and the seconds it took."""
  t0 = time.perf_counter()
  try:
    out = fn()
  except ValueError as e:
    return e, time.perf_counter() - t0
  return out, time.perf_counter() - t0


@pytest.fixture(scope='module')
def scratch():
  with tempfile.TemporaryDirectory(prefix='fuzz-files-') as d:
    for name in ('sheet', 'swatch', 'strip'):
      os.makedirs(os.path.join(d, name))
      with open(os.path.join(d, name, 'camera.json'), 'w') as f:
        f.write('{}')
    yield d


# --- values ------------------------------------------------------------------

_NUMBERS = st.one_of(
  st.integers(-(10**20), 10**20),
  st.floats(allow_nan=True, allow_infinity=True),
  st.sampled_from([0, -1, 1e-300, 1e300, 10**400, 0.05, 0.2, 2.0]),
)
_SCALARS = st.one_of(
  _NUMBERS,
  st.text(max_size=8),
  st.sampled_from(['sheet', 'swatch', 'sheet/camera.json', 'z', '-y', 'low', '']),
  st.text(min_size=300, max_size=600),
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

# --- protocol files -------------------------------------------------------------

_GOOD_PROTOCOL = {
  'recordings': [
    {'recording': 'sheet', 'camera_json': 'sheet/camera.json', 'wind_speed': 2.1,
     'wind_speed_sd': 0.05, 'fan': 'low'},
    {'recording': 'swatch', 'camera_json': 'swatch/camera.json', 'cloth_size': 0.25,
     'world_up': 'z', 'hem_mass': 0.1},
  ],
  'fabric': {'area_weight': 0.2, 'area_weight_sd': 0.004,
             'overhang': {'recording': 'strip', 'camera_json': 'strip/camera.json',
                          'length': 0.05}},
}  # fmt: skip
_ENTRY_KEYS = [*takes.KEYS, 'fabrik', 'size', 'recordings']
_FABRIC_KEYS = [*takes.FABRIC_KEYS, 'area_weight_sd', 'bending_length_sd',
                'bending_length_dof', 'overhang', 'weight']  # fmt: skip


@st.composite
def protocol_dicts(draw):
  """The good protocol with one to four of its keys set to anything, added
  or removed: at the top, in an entry, in the fabric, in its overhang."""
  d = json.loads(json.dumps(_GOOD_PROTOCOL))
  for _ in range(draw(st.integers(1, 4))):
    where = draw(st.sampled_from(['top', 'entry', 'fabric', 'overhang', 'twice']))
    if where == 'twice':
      entries = d.get('recordings')
      if isinstance(entries, list) and entries and isinstance(entries[0], dict):
        entries.append(dict(entries[0], fan='other'))
      continue
    if where == 'top':
      target, keys = d, ['recordings', 'fabric', 'fabrik', 'notes']
    elif where == 'entry':
      entries = d.get('recordings')
      if not isinstance(entries, list) or not entries:
        continue
      target = draw(st.sampled_from(entries))
      keys = _ENTRY_KEYS
    else:
      target = d.get('fabric')
      if where == 'overhang' and isinstance(target, dict):
        target = target.get('overhang')
      keys = _FABRIC_KEYS if where == 'fabric' else list(takes.OVERHANG_KEYS)
    if not isinstance(target, dict):
      continue
    key = draw(st.sampled_from(keys))
    if draw(st.booleans()) and key in target:
      del target[key]
    else:
      target[key] = draw(_VALUES)
  return d


def _read_protocol(path: str) -> None:
  """Every reader of a protocol file, as the estimate calls them; what they
  give checked against the file's own values."""
  for take in takes.read(path):
    assert os.path.exists(take.path)
    assert not take.camera_json or os.path.isfile(take.camera_json)
    for v in (take.cloth_size, take.hem_mass, *(take.wind or ())):
      assert np.isfinite(v), take
  for v in takes.fabric_readings(path).values():
    assert np.isfinite(v)
  over = takes.fabric_overhang(path)
  if over is not None:
    assert 0 < over.length <= 0.5 and os.path.exists(over.path)


def _write_protocol(scratch: str, d, yaml: bool) -> str:
  path = os.path.join(scratch, 'protocol.yaml' if yaml else 'protocol.json')
  with open(path, 'w') as f:
    f.write(json.dumps(d, allow_nan=True))  # JSON is YAML too
  return path


@_settings('protocol')
@given(d=protocol_dicts(), yaml=st.booleans())
def test_protocol_files_are_read_or_refused_by_name(scratch, d, yaml):
  path = _write_protocol(scratch, d, yaml)
  out, seconds = _timed(lambda: _read_protocol(path))
  assert seconds < MAX_SECONDS, seconds
  if isinstance(out, ValueError):
    refused_by_name(out, path)


def _alias_bomb(depth: int, width: int) -> str:
  lines = ['a0: &a0 [' + ', '.join(['"lol"'] * width) + ']']
  for i in range(1, depth):
    lines.append(f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * width) + ']')
  lines.append(f'recordings: [{{recording: sheet, fan: *a{depth - 1}}}]')
  return '\n'.join(lines) + '\n'


@_settings('protocol_text')
@given(
  raw=st.one_of(
    st.binary(max_size=300),
    st.text(max_size=300),
    st.tuples(st.integers(2, 12), st.integers(2, 12)).map(lambda t: _alias_bomb(*t)),
    st.integers(1, 20_000).map(lambda n: 'recordings:\n' + '- ' * n + '1'),
    st.integers(1, 20_000).map(lambda n: '{"recordings":' + '[' * n + ']' * n + '}'),
  ),
  yaml=st.booleans(),
)
def test_protocol_file_bytes_are_read_or_refused_by_name(scratch, raw, yaml):
  path = os.path.join(scratch, 'raw.yaml' if yaml else 'raw.json')
  with open(path, 'wb' if isinstance(raw, bytes) else 'w') as f:
    f.write(raw)
  out, seconds = _timed(lambda: _read_protocol(path))
  assert seconds < MAX_SECONDS, seconds
  if isinstance(out, ValueError):
    refused_by_name(out, path)


# --- plan: its settings, and the estimate files it reads -----------------------

_PLAN_FLAGS = ['nodes', 'draws', 'clip', 'reading', 'seed', 'candidates']
_FLAG_VALUES = st.one_of(
  st.integers(-(10**12), 10**12).map(str),
  st.sampled_from(['0', '1', '2', '3', '16', '17', '64', '65', '1e9', 'nan', 'inf',
                   '-inf', '', ' ', '0x10', '1_000', '3.5', '1e-300', '10' * 200]),
  st.floats(allow_nan=True, allow_infinity=True).map(repr),
  st.lists(
    st.one_of(st.sampled_from(protocol_plan.PLAN_CANDIDATES), st.text(max_size=30)),
    min_size=0, max_size=40,
  ).map(','.join),
)  # fmt: skip


@_settings('plan_flags')
@given(
  chosen=st.lists(
    st.tuples(st.sampled_from(_PLAN_FLAGS), _FLAG_VALUES), min_size=1, max_size=3
  )
)
def test_plan_settings_are_taken_or_refused_by_name(chosen):
  """What plan checks before it reads or simulates anything: within a
  second, so a bad count never allocates or simulates."""
  argv = ['plan', '--workdir=w'] + [f'--{n}={v}' for n, v in chosen]
  names = [n for n, _ in chosen]
  t0 = time.perf_counter()
  try:
    args = cli.parse(plan_script.Args, plan_script.PRESETS, argv)
    config = protocol_config.Config(draws=args.draws, clip=args.clip, seed=args.seed)
    protocol_plan.check_plan(list(args.candidates), args.nodes, args.reading, config)
  except absl_flags.Error as e:  # cli.run prints it as one line (exit 2)
    refused_by_name(e, *names)
    return
  except ValueError as e:
    refused_by_name(e, *names)
    return
  finally:
    assert time.perf_counter() - t0 < MAX_SECONDS
  lo, hi = protocol_plan.PLAN_LIMITS['nodes']
  assert lo <= args.nodes <= hi and 3 <= args.draws <= 64
  assert 1 <= len(args.candidates) <= 32 and np.isfinite(args.clip)


@pytest.fixture(scope='module')
def estimate_files(tmp_path_factory):
  """A good estimate's posterior.npz and estimate.json (their bytes)."""
  import physsim  # noqa: PLC0415

  d = tmp_path_factory.mktemp('estimate')
  rng = np.random.default_rng(0)
  bounds = physsim.search_space('gray_interlock').bounds()
  np.savez(d / 'posterior.npz', samples=rng.uniform(-1, 1, (50, 3)), bounds=bounds)
  (d / 'estimate.json').write_text(json.dumps({'material': 'gray_interlock'}))
  return (d / 'posterior.npz').read_bytes(), (d / 'estimate.json').read_bytes()


def _damage(data, raw: bytes) -> bytes:
  raw = bytearray(raw)
  how = data.draw(st.sampled_from(['truncate', 'flip', 'both', 'replace', 'none']))
  if how == 'replace':
    return data.draw(st.binary(max_size=200))
  if how in ('truncate', 'both'):
    raw = raw[: data.draw(st.integers(0, len(raw)))]
  if how in ('flip', 'both') and raw:
    for _ in range(data.draw(st.integers(1, 8))):
      raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
  return bytes(raw)


@_settings('estimate_files')
@given(data=st.data())
def test_damaged_estimate_files_are_read_or_refused_by_name(
  scratch, estimate_files, data
):
  """plan (and export) read an estimate's draws: a corrupt, truncated or
  odd posterior.npz or estimate.json is refused naming it."""
  npz, est = estimate_files
  workdir = os.path.join(scratch, 'estimate')
  shutil.rmtree(workdir, ignore_errors=True)
  os.makedirs(workdir)
  which = data.draw(st.sampled_from(['npz', 'json', 'both', 'json_values']))
  if which == 'json_values':
    est = json.dumps({'material': data.draw(_VALUES)}).encode()
  elif which in ('json', 'both'):
    est = _damage(data, est)
  if which in ('npz', 'both'):
    npz = _damage(data, npz)
  pathlib.Path(workdir, layout.POSTERIOR_FILE).write_bytes(npz)
  pathlib.Path(workdir, layout.ESTIMATE_FILE).write_bytes(est)
  out, seconds = _timed(lambda: layout.read_draws(workdir))
  assert seconds < MAX_SECONDS, seconds
  if isinstance(out, ValueError):
    refused_by_name(out, layout.POSTERIOR_FILE, layout.ESTIMATE_FILE)
    return
  material, draws, weights = out
  assert isinstance(material, str) and draws.ndim == 2 and draws.shape[1] == 2
  assert np.isfinite(draws).all() and len(weights) == len(draws)


# --- ROS 2 bag folders ----------------------------------------------------------


@pytest.fixture(scope='module')
def bag_folder(tmp_path_factory):
  pytest.importorskip('rosbags')
  from rosbags.typesys import Stores  # noqa: PLC0415

  from tests.physsim.bags_test import write_bag  # noqa: PLC0415

  path, _, _ = write_bag(
    tmp_path_factory.mktemp('bag2') / 'rec', Stores.ROS2_HUMBLE, frames=2, imu=False
  )
  return {f: pathlib.Path(path, f).read_bytes() for f in os.listdir(path)}


@_settings('bag_folder')
@given(data=st.data())
def test_damaged_ros2_bag_folders_are_read_or_refused_by_name(
  scratch, bag_folder, data
):
  """metadata.yaml edited (values, aliases) or cut, the storage file
  damaged, either missing: read or refused naming the folder."""
  from physsim import bags  # noqa: PLC0415

  path = os.path.join(scratch, 'bag')
  shutil.rmtree(path, ignore_errors=True)
  os.makedirs(path)
  for name, raw in bag_folder.items():
    what = data.draw(st.sampled_from(['keep', 'keep', 'damage', 'drop', 'alias']))
    if what == 'drop':
      continue
    if what == 'alias' and name == 'metadata.yaml':
      raw = raw.replace(b'rosbag2_bagfile_information:', b'x: &x [1, 2]\n'
                        b'rosbag2_bagfile_information:', 1) + b'  y: *x\n'  # fmt: skip
    elif what == 'damage':
      raw = _damage(data, raw)
    pathlib.Path(path, name).write_bytes(raw)
  t0 = time.perf_counter()
  try:
    bags.check_bag_folder(path)
    if not bags.is_bag(path):
      return  # read as a frame folder: fuzz_test's surface
    rec = bags.read_bag(path)
  except ValueError as e:
    refused_by_name(e, path)
    return
  finally:
    assert time.perf_counter() - t0 < 10 * MAX_SECONDS
  assert np.isfinite(rec.depth).all() and rec.depth.ndim == 3


def test_the_fast_tier_tries_some_of_each_surface():
  assert all(n >= 25 for n in N_EXAMPLES.values())
