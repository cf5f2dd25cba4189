"""Atomic writes for experiment outputs (``physsim.dataset``'s writers, plus figures).

An interrupted script never leaves a half-written JSON, text or PNG under its
final name.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os

from model import config_io
from physsim.dataset import write_atomic
from physsim.dataset import write_json_atomic as write_json
from physsim.dataset import write_text_atomic as write_text

__all__ = [
  'LOCK_FILE', 'locked', 'pyplot', 'resume', 'savefig', 'write_atomic',
  'write_json', 'write_text',
]  # fmt: skip

LOCK_FILE = '.lock'


def pyplot():
  """``matplotlib.pyplot`` on the file-only Agg backend, imported on first use.

  An estimate prints its table before it draws; matplotlib's import (about
  half a second) need not come before the table.
  """
  import matplotlib

  matplotlib.use('Agg')
  import matplotlib.pyplot as plt

  return plt


def savefig(fig, path: str, dpi: int = 100) -> None:
  """Saves a matplotlib figure as PNG, atomically."""
  write_atomic(path, lambda p: fig.savefig(p, dpi=dpi, format='png'))


def resume(path: str, config) -> dict:
  """What an earlier run of the same config saved in the JSON at ``path``
  (``{'config': ..., ...}``), or {} when there is none or its config differs
  (JSON turns tuples into lists, so the configs are compared as dataclasses)."""
  if not os.path.exists(path):
    return {}
  data = config_io.read_json(path)
  try:
    same = config_io.from_dict(type(config), data.get('config')) == config
  except (ValueError, TypeError):
    same = False
  return data if same else {}


def _holder(path: str) -> str:
  try:
    with open(path) as f:
      pid = f.read(32).strip()
  except OSError:
    pid = ''
  return f'process {pid}' if pid.isdigit() else 'another process'


@contextlib.contextmanager
def locked(workdir: str):
  """Holds ``workdir`` for this process: a second process (or a second call
  here) is refused while the first runs, naming its pid. The lock is the
  kernel's (``flock`` on ``<workdir>/.lock``), so a process that died, even
  by SIGKILL, leaves none behind that blocks the next. The lock file goes on
  exit, and the workdir too when this call made it and left it empty.

  Raises:
    ValueError: the workdir is held, naming the holder's pid.
    OSError: the workdir cannot be made.
  """
  made = not os.path.isdir(workdir)
  os.makedirs(workdir, exist_ok=True)
  path = os.path.join(workdir, LOCK_FILE)
  while True:
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
      fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
      os.close(fd)
      if e.errno not in (errno.EAGAIN, errno.EACCES):
        raise
      raise ValueError(
        f'{workdir}: in use by {_holder(path)} (lock {path}); wait for it to end '
        'or use another --workdir'
      ) from None
    # The file may have been removed by its last holder between our open and
    # our lock: then the lock is on a dead inode, so take the new file.
    try:
      same = os.stat(path).st_ino == os.fstat(fd).st_ino
    except FileNotFoundError:
      same = False
    if same:
      break
    os.close(fd)
  try:
    os.ftruncate(fd, 0)
    os.write(fd, f'{os.getpid()}\n'.encode())
    yield
  finally:
    with contextlib.suppress(OSError):
      os.remove(path)
    os.close(fd)
    if made:
      with contextlib.suppress(OSError):
        os.rmdir(workdir)  # only if empty
