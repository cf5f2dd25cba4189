"""Atomic writes for experiment outputs: a temporary sibling, then ``os.replace``.

An interrupted script never leaves a half-written JSON or PNG under its final
name. Temporary names start with ``physsim.dataset.TMP_PREFIX``, which the
dataset reader ignores and ``dataset.clean_tmp`` removes.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable

from physsim.dataset import TMP_PREFIX


def write_atomic(path: str, write: Callable[[str], object]) -> None:
  """Calls ``write(tmp)`` on a temporary sibling of ``path``, then renames it."""
  d = os.path.dirname(os.path.abspath(path))
  os.makedirs(d, exist_ok=True)
  fd, tmp = tempfile.mkstemp(dir=d, prefix=TMP_PREFIX, suffix=os.path.splitext(path)[1])
  os.close(fd)
  try:
    write(tmp)
    os.replace(tmp, path)
  except BaseException:
    if os.path.exists(tmp):
      os.remove(tmp)
    raise


def write_json(path: str, obj, indent: int = 1) -> None:
  """Writes ``obj`` as JSON, atomically."""

  def write(p):
    with open(p, 'w') as f:
      json.dump(obj, f, indent=indent)

  write_atomic(path, write)


def write_text(path: str, text: str) -> None:
  """Writes ``text``, atomically."""

  def write(p):
    with open(p, 'w') as f:
      f.write(text)

  write_atomic(path, write)


def savefig(fig, path: str, dpi: int = 100) -> None:
  """Saves a matplotlib figure as PNG, atomically."""
  write_atomic(path, lambda p: fig.savefig(p, dpi=dpi, format='png'))
