"""Issue 40's bad inputs, each a named test: refused with one line naming the
file or flag, before anything is decoded or written (settings that are NaN
or infinite, an .npz whose fps is an array, a camera file nested 100,000
deep, frames of a few pixels, a frame header far larger than its camera, a
blank wall without a camera file, a second process in a workdir, an intake
into a workdir holding another recording's run, Ctrl-C)."""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import struct
import subprocess
import sys
import textwrap
import zlib

import numpy as np
import pytest

from experiments import estimate
from experiments.pipeline import cli, files, intake, objective
from physsim import camera_files, video, video_files

_ROOT = pathlib.Path(__file__).resolve().parents[2]
_SMOKE = objective.PRESETS['smoke']


def tree_digest(root) -> str:
  """A digest of every file's path and content under ``root`` ('' if none)."""
  root = str(root)
  if not os.path.exists(root):
    return ''
  h = hashlib.sha1()
  for folder, dirs, names in sorted(os.walk(root)):
    dirs.sort()
    for name in sorted(names):
      path = os.path.join(folder, name)
      h.update(os.path.relpath(path, root).encode())
      with open(path, 'rb') as f:
        h.update(f.read())
  return h.hexdigest()


def camera(path, w=160, h=120, **extra) -> str:
  cam = {'width': w, 'height': h, 'fx': 0.9 * w, 'fy': 0.9 * w, 'cx': w / 2,
         'cy': h / 2, 'fps': 20, **extra}  # fmt: skip
  pathlib.Path(path).write_text(json.dumps(cam))
  return str(path)


def png_header_only(path, w, h) -> str:
  """A file with a valid PNG signature and IHDR chunk of ``w`` x ``h`` 16-bit
  grey, and no pixels: only a reader of headers gets anything from it."""
  ihdr = struct.pack('>IIBBBBB', w, h, 16, 0, 0, 0, 0)
  chunk = struct.pack('>I', 13) + b'IHDR' + ihdr
  chunk += struct.pack('>I', zlib.crc32(b'IHDR' + ihdr))
  pathlib.Path(path).write_bytes(b'\x89PNG\r\n\x1a\n' + chunk)
  return str(path)


def float_flags():
  """Every float (or tuple of floats) flag of the estimate's command line."""
  out = []
  for leaf in cli.leaves(estimate.Args):
    kind, elem = cli._parser(leaf.type, leaf.flag)
    if kind == 'float' or (kind == 'list' and elem is float):
      out.append(leaf.flag)
  return out


def test_every_float_flag_refuses_nan_and_inf():
  names = float_flags()
  assert {'sharpness', 'camera_sd_m', 'depth_scale', 'pins', 'wind_speed'} <= set(names)
  for name in names:
    for bad in ('nan', 'inf', '-inf'):
      with pytest.raises(ValueError, match=rf'^--{name}={bad}.*finite'):
        cli.parse(estimate.Args, estimate.PRESETS, ['p', f'--{name}={bad}'])


def test_configs_refuse_nan_from_python_too():
  with pytest.raises(ValueError, match='--sharpness=nan'):
    _SMOKE.replace(sharpness=float('nan')).check()
  with pytest.raises(ValueError, match='--sharpness=inf'):
    _SMOKE.replace(sharpness=float('inf')).check()
  with pytest.raises(ValueError, match='--sim_fps=nan'):  # a renamed flag
    _SMOKE.replace(fps=float('nan')).check()
  with pytest.raises(ValueError, match='--up=1.0,nan,0.0'):
    intake.IntakeConfig(up=(1.0, float('nan'), 0.0)).check()
  with pytest.raises(ValueError, match='--sharpness=1e\\+300'):
    _SMOKE.replace(sharpness=1e300).check()
  with pytest.raises(ValueError, match='--seed=-1'):
    _SMOKE.replace(seed=-1).check()
  _SMOKE.check()
  intake.IntakeConfig().check()


def test_an_npz_whose_fps_is_an_array_names_the_file(tmp_path):
  path = tmp_path / 'rec.npz'
  np.savez(path, depth=np.full((3, 48, 64), 2.0, np.float32), fps=np.array([20, 30]))
  with pytest.raises(ValueError, match=r'rec.npz: "fps" must be one number'):
    video.load_depth_video(str(path), size=None)
  np.savez(path, depth=np.full((3, 48, 64), 2.0, np.float32), fps=np.array([20.0]))
  assert video.load_depth_video(str(path), size=None).fps == 20.0


def test_a_camera_file_nested_100000_deep_names_the_file(tmp_path):
  deep = tmp_path / 'deep.json'
  deep.write_text('[' * 100_000 + ']' * 100_000)
  with pytest.raises(
    ValueError, match='deep.json: not readable JSON .nested too deeply'
  ):
    camera_files.read_camera(str(deep))
  inner = tmp_path / 'inner.json'
  inner.write_text(
    '{"width": 160, "height": 120, "fx": 100, "fy": 100, "cx": 80, "cy": 60, '
    '"distortion": ' + '[' * 100_000 + ']' * 100_000 + '}'
  )
  with pytest.raises(ValueError, match='inner.json: '):
    camera_files.read_camera(str(inner))
  binary = tmp_path / 'binary.json'
  binary.write_bytes(b'\xff\xfe\x00garbage')
  with pytest.raises(ValueError, match='binary.json: not a text file'):
    camera_files.read_camera(str(binary))
  huge = tmp_path / 'huge.json'
  huge.write_text(json.dumps({'width': 1e400, 'height': 120, 'fx': 1}))
  with pytest.raises(ValueError, match='huge.json: needs integer'):
    camera_files.read_camera(str(huge))


def test_frames_of_a_few_pixels_are_refused(tmp_path):
  path = tmp_path / 'tiny.npz'
  np.savez(path, depth=np.full((10_000, 3, 4), 2.0, np.float32), fps=20.0)
  cam = camera(tmp_path / 'cam.json', 4, 3)
  with pytest.raises(ValueError, match=r'tiny.npz: frames of 4 x 3 px; .* at least'):
    intake.take_in(str(path), intake.IntakeConfig(), cam, _SMOKE.simulation)


def test_frame_sizes_are_checked_from_headers_before_decoding(tmp_path):
  # 12000 x 9000 frames (no pixels: decoding would fail) with a 640x360 camera.
  folder = tmp_path / 'big'
  folder.mkdir()
  for t in range(3):
    png_header_only(folder / f'{t}.png', 12000, 9000)
  with pytest.raises(ValueError, match='12000 x 9000 px; no depth camera'):
    video_files.read_header(str(folder))
  cam = camera(tmp_path / 'cam.json', 640, 360)
  with pytest.raises(ValueError, match='big: frames of 12000 x 9000'):
    intake.take_in(str(folder), intake.IntakeConfig(), cam, _SMOKE.simulation)
  # Within the side limit, the camera's other aspect ratio refuses it.
  for t in range(3):
    png_header_only(folder / f'{t}.png', 1200, 900)
  with pytest.raises(ValueError, match='cam.json: the camera is 640 x 360 but the f'):
    intake.take_in(str(folder), intake.IntakeConfig(), cam, _SMOKE.simulation)
  assert video_files.read_header(str(folder)) == video_files.Header(3, 900, 1200)
  # A .npy header claiming 400 GB of frames, with no data behind it.
  npy = tmp_path / 'huge.npy'
  with open(npy, 'wb') as f:
    header = {'descr': '<f4', 'fortran_order': False, 'shape': (100_000, 1000, 1000)}
    np.lib.format.write_array_header_1_0(f, header)
  with pytest.raises(ValueError, match=r'huge.npy: 100000 frames .* GiB decoded'):
    video.load_depth_video(str(npy), source_fps=20)


def test_a_blank_wall_without_a_camera_file_is_refused(tmp_path):
  path = tmp_path / 'wall.npz'
  np.savez(path, depth=np.full((30, 120, 160), 2.0, np.float32), fps=20.0)
  with pytest.raises(ValueError, match='wall.npz: no camera file.*--allow_no_camera'):
    intake.take_in(str(path), intake.IntakeConfig(), '', _SMOKE.simulation)
  args = estimate.Args(
    recording=(str(path),), workdir=str(tmp_path / 'w'), intake_only=True,
    search=_SMOKE,
  )  # fmt: skip
  with pytest.raises(ValueError, match='--allow_no_camera'):
    estimate.main(args)
  assert not os.path.exists(tmp_path / 'w')
  # Asked for, it is taken in (all of it as cloth: the user's risk).
  taken = intake.take_in(
    str(path), intake.IntakeConfig(allow_no_camera=True), '', _SMOKE.simulation
  )
  assert taken.cloth_fraction.min() == 1.0


def test_one_process_per_workdir(tmp_path):
  workdir = tmp_path / 'w'
  holder = subprocess.Popen(
    [sys.executable, '-c', textwrap.dedent(f"""
      import sys, time
      from experiments.pipeline import files
      with files.locked({str(workdir)!r}):
        print('held', flush=True)
        sys.stdin.read()
      """)],
    cwd=_ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    env=dict(os.environ, PYTHONPATH=str(_ROOT)),
  )  # fmt: skip
  try:
    assert holder.stdout.readline().strip() == 'held'
    args = estimate.Args(
      recording=('nowhere',), workdir=str(workdir), intake_only=True, search=_SMOKE,
      intake=intake.IntakeConfig(allow_no_camera=True),
    )  # fmt: skip
    with pytest.raises(ValueError, match=rf'w: in use by process {holder.pid} '):
      estimate.main(args)
  finally:
    holder.communicate('')
  assert holder.returncode == 0
  assert not os.path.exists(workdir)  # made by the holder, left empty
  # The same process twice (a second call while the first holds it).
  with files.locked(str(workdir)):
    with pytest.raises(ValueError, match=f'in use by process {os.getpid()}'):
      with files.locked(str(workdir)):
        pass


def test_a_dead_process_lock_is_taken_over(tmp_path):
  workdir = tmp_path / 'w'
  workdir.mkdir()
  dead = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'],
                        capture_output=True, text=True, check=True)  # fmt: skip
  (workdir / files.LOCK_FILE).write_text(dead.stdout)
  with files.locked(str(workdir)):
    assert (workdir / files.LOCK_FILE).read_text().strip() == str(os.getpid())
  assert not (workdir / files.LOCK_FILE).exists() and workdir.is_dir()


def test_an_intake_into_another_recordings_workdir_writes_nothing(tmp_path):
  workdir = tmp_path / 'a'
  workdir.mkdir()
  (workdir / 'intake.json').write_text(json.dumps({'source': '/recordings/A'}))
  (workdir / 'overlay.png').write_bytes(b'A overlay')
  (workdir / 'intake').mkdir()
  (workdir / 'intake' / '0000.png').write_bytes(b'A frame')
  before = tree_digest(workdir)
  cam = camera(tmp_path / 'cam.json')
  for only in (True, False):
    args = estimate.Args(
      recording=(str(tmp_path / 'B'),), camera_json=cam, workdir=str(workdir),
      intake_only=only, search=_SMOKE, model=str(tmp_path / 'no_model'),
    )  # fmt: skip
    with pytest.raises(ValueError, match='intake.json: the workdir holds the intake '
                       'of /recordings/A, not of .*B; use another --workdir'):  # fmt: skip
      estimate.main(args)
    assert tree_digest(workdir) == before
  # A search there of a recording that was not taken in: refused too.
  (workdir / 'intake.json').unlink()
  (workdir / 'run.json').write_text('{}')
  with pytest.raises(ValueError, match='run.json: the workdir holds an estimate'):
    estimate.main(args)


def _run_script(tmp_path, body: str, *flags_):
  (tmp_path / 'ctrl_script.py').write_text(textwrap.dedent(body))
  env = dict(os.environ, PYTHONPATH=f'{_ROOT}:{tmp_path}')
  return subprocess.run(
    [sys.executable, '-m', 'ctrl_script', *flags_], cwd=tmp_path, env=env,
    capture_output=True, text=True, timeout=120,
  )  # fmt: skip


_SCRIPT = """
import dataclasses, signal, threading, time
from experiments.pipeline import cli

@dataclasses.dataclass(frozen=True)
class Args:
  \"\"\"A script.

  Attributes:
    rate: a number.
    name: a name.
  \"\"\"
  rate: float = 1.0
  name: str = ''

def main(args):
  # as from a terminal: a shell's background job starts with SIGINT ignored,
  # and then Python installs no KeyboardInterrupt for it
  signal.signal(signal.SIGINT, signal.default_int_handler)
  if args.name == 'interrupt':
    # Ctrl-C, to this thread: a process-wide kill may land on one of JAX's
    # threads, and the main thread raise before Python sees it
    signal.pthread_kill(threading.get_ident(), signal.SIGINT)
    time.sleep(10)
  raise ValueError(f'--name={args.name}: refused\\nsecond line')

if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
"""


def test_ctrl_c_is_one_line_with_the_resume_command(tmp_path):
  out = _run_script(tmp_path, _SCRIPT, '--name=interrupt', '--rate=2')
  assert out.returncode == 130, out.stderr
  assert out.stderr.splitlines() == [
    'interrupted; resume with: python -m ctrl_script --name=interrupt --rate=2'
  ]


def test_flag_errors_and_user_errors_are_one_line_with_status_2(tmp_path):
  for flags_, match in (
    (['--rate=abc'], '--rate'), (['--rate=nan'], '--rate=nan'),
    (['--name=x'], '--name=x: refused; second line'), (['extra'], 'unexpected'),
  ):  # fmt: skip
    out = _run_script(tmp_path, _SCRIPT, *flags_)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith('error: '), lines
    assert match in lines[0]
