"""On-disk depth-video datasets: one format for simulated sweeps and real captures.

Layout::

  <root>/dataset.json                 generator version, seed, config, created
  <root>/index.csv                    one row per sequence (``INDEX_COLUMNS``)
  <root>/<material>/<seq_id>/meta.json  the row + intrinsics, extrinsics, fps, ...
  <root>/<material>/<seq_id>/cam{c}/{t:04d}.png      16-bit depth, mm, 0 = invalid
  <root>/<material>/<seq_id>/cam{c}/rgb_{t:04d}.png  optional 8-bit colour

A sequence is written into a hidden temporary sibling folder (``.tmp-*``) and
renamed into place once its ``meta.json`` is written last, so a folder holding a
``meta.json`` is always complete; temporary folders left by a crash are ignored
by the reader and removed by ``clean_tmp``. ``index.csv`` is derived from the
finished folders' ``meta.json`` (``rebuild_index``), written atomically.

The format's shared parts (constants, index rows, depth in millimetres, JSON
and PNG reads) are in ``dataset_format``, reading back in ``dataset_reading``;
this module writes, atomically. Their names are importable from here.
"""

from __future__ import annotations

import csv
import errno
import io
import json
import os
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterable
from typing import Any

import cv2
import numpy as np

from physsim.dataset_format import (
  GENERATOR_VERSION,
  INDEX_COLUMNS,
  MAX_MM,
  MM_PER_M,
  TMP_PREFIX,
  depth_to_mm,
  finished_sequences,
  is_complete,
  make_row,
  mm_to_depth,
  read_json,
  read_png,
  sequence_dir,
)
from physsim.dataset_reading import (
  DatasetIndex,
  Sequence,
  TrainingArrays,
  load_training_arrays,
  open_dataset,
  read_sequence,
  resize_depth,
)

# The format's and the reader's names, importable from here as before.
__all__ = [
  'GENERATOR_VERSION', 'INDEX_COLUMNS', 'MAX_MM', 'MM_PER_M', 'TMP_PREFIX',
  'DatasetIndex', 'Sequence', 'TrainingArrays', 'clean_tmp', 'depth_to_mm',
  'disk_full', 'finished_sequences', 'imwrite', 'is_complete', 'is_disk_full',
  'load_training_arrays', 'make_row', 'mm_to_depth', 'open_dataset', 'read_json',
  'read_png', 'read_sequence', 'rebuild_index', 'resize_depth', 'sequence_dir',
  'user_mode', 'write_atomic', 'write_dataset_info', 'write_index',
  'write_json_atomic', 'write_sequence', 'write_text_atomic',
]  # fmt: skip


# ----------------------------------------------------------------- atomic I/O


def user_mode(mode: int) -> int:
  """``mode`` as the user's umask would have it for a newly created file."""
  umask = os.umask(0)
  os.umask(umask)
  return mode & ~umask


def write_atomic(path: str, write) -> None:
  """Calls ``write(tmp)`` on a temporary sibling of ``path``, then renames it.

  The temporary name keeps ``path``'s extension (``np.savez`` and
  ``savefig`` look at it) and starts with ``TMP_PREFIX`` (ignored by readers,
  removed by ``clean_tmp``); on any error it is deleted.
  """
  folder = os.path.dirname(os.path.abspath(path))
  os.makedirs(folder, exist_ok=True)
  fd, tmp = tempfile.mkstemp(
    dir=folder, prefix=TMP_PREFIX, suffix=os.path.splitext(path)[1]
  )
  os.close(fd)
  try:
    write(tmp)
    os.chmod(tmp, user_mode(0o666))  # mkstemp makes it private (0600)
    os.replace(tmp, path)
  except BaseException as e:
    if os.path.exists(tmp):
      os.remove(tmp)
    if is_disk_full(e):
      raise disk_full(path, e) from None
    raise


# What a write that ran out of room raises (ENOSPC: no space, EDQUOT: quota).
_FULL = (errno.ENOSPC, errno.EDQUOT)


def is_disk_full(e: BaseException) -> bool:
  """True for the OSError of a write that ran out of disk space or quota."""
  return isinstance(e, OSError) and e.errno in _FULL


def disk_full(path: str, e: OSError) -> ValueError:
  """The one line that says a write failed for want of room, naming it."""
  return ValueError(f'disk full: {path} ({e.strerror or "no space left"})')


def write_text_atomic(path: str, text: str) -> None:
  """Writes ``text`` to ``path`` through a temporary file and ``os.replace``."""

  def write(tmp):
    with open(tmp, 'w', newline='') as f:
      f.write(text)

  write_atomic(path, write)


def write_json_atomic(path: str, obj: Any) -> None:
  write_text_atomic(path, json.dumps(obj, indent=1, sort_keys=True) + '\n')


def imwrite(path: str, image: np.ndarray) -> None:
  """An image encoded by OpenCV (by ``path``'s extension) and written by
  Python, so that a full disk says so (``cv2.imwrite`` only returns False).

  Raises:
    ValueError: naming the file: an image OpenCV cannot encode, or "disk
      full" (the file then removed).
    OSError: any other failed write.
  """
  ext = os.path.splitext(path)[1] or '.png'
  try:
    ok, buf = cv2.imencode(ext, image)
  except cv2.error as e:
    raise ValueError(f'{path}: OpenCV cannot encode the image ({e.err})') from None
  if not ok:
    raise ValueError(f'{path}: OpenCV cannot encode the image as {ext}')
  try:
    with open(path, 'wb') as f:
      f.write(buf.tobytes())
  except OSError as e:
    if not is_disk_full(e):
      raise
    if os.path.exists(path):
      os.remove(path)
    raise disk_full(path, e) from None


# --------------------------------------------------------------------- writing


def write_sequence(
  root: str,
  meta: dict,
  depth=None,
  rgb=None,
  *,
  overwrite: bool = False,
) -> str:
  """Writes one sequence atomically.

  Args:
    root: dataset root.
    meta: at least the ``INDEX_COLUMNS`` (see ``make_row``) plus anything else
      (intrinsics, extrinsics, fps, seed, mesh, ...); must be JSON-serialisable.
    depth: (C, T, H, W) metres, or None for a sequence without frames (e.g. an
      invalid simulation).
    rgb: optional (C, T, H, W, 3) uint8 colour frames.
    overwrite: replace a finished sequence instead of raising.

  Returns:
    The sequence folder.

  Raises:
    ValueError: missing columns, shapes that disagree with ``meta``, or an
      existing finished sequence without ``overwrite``.
  """
  final, meta, depth, rgb = _checked_sequence(root, meta, depth, rgb, overwrite)
  parent = os.path.dirname(final)
  os.makedirs(parent, exist_ok=True)
  tmp = os.path.join(parent, f'{TMP_PREFIX}{meta["seq_id"]}-{uuid.uuid4().hex[:8]}')
  os.makedirs(tmp)
  try:
    if depth is not None:
      _write_frames(tmp, depth, rgb)
    # meta.json last: its presence marks the folder complete.
    with open(os.path.join(tmp, 'meta.json'), 'w') as f:
      json.dump(meta, f, indent=1, sort_keys=True, allow_nan=True)
    if os.path.exists(final):
      old = os.path.join(
        parent, f'{TMP_PREFIX}old-{meta["seq_id"]}-{uuid.uuid4().hex[:8]}'
      )
      os.replace(final, old)
      os.replace(tmp, final)
      shutil.rmtree(old, ignore_errors=True)
    else:
      os.replace(tmp, final)
  except BaseException:
    shutil.rmtree(tmp, ignore_errors=True)
    raise
  return final


def _checked_sequence(root: str, meta: dict, depth, rgb, overwrite: bool):
  """``write_sequence``'s arguments checked: (its folder, the meta.json to
  write (a copy, with frame size and contents), depth, rgb as arrays).

  Raises:
    ValueError: as ``write_sequence``.
  """
  missing = [c for c in INDEX_COLUMNS if c not in meta]
  if missing:
    raise ValueError(f'sequence meta lacks the fields {missing}')
  material, seq_id = meta['material'], meta['seq_id']
  final = sequence_dir(root, material, seq_id)
  if is_complete(root, material, seq_id) and not overwrite:
    raise ValueError(f'{final}: sequence already written (pass overwrite=True)')
  meta = dict(meta)
  n_cam, n_frames = int(meta['n_cameras']), int(meta['n_frames'])
  if depth is not None:
    depth = np.asarray(depth)
    if depth.ndim != 4 or depth.shape[:2] != (n_cam, n_frames):
      raise ValueError(
        f'{final}: depth must be (C={n_cam}, T={n_frames}, H, W), got {depth.shape}'
      )
    meta.update(height=int(depth.shape[2]), width=int(depth.shape[3]))
  if rgb is not None:
    rgb = np.asarray(rgb)
    if depth is None or rgb.shape != (*depth.shape, 3) or rgb.dtype != np.uint8:
      raise ValueError(
        f'{final}: rgb must be uint8 (C, T, H, W, 3) matching depth, got '
        f'{rgb.dtype} {rgb.shape}'
      )
  meta.update(
    has_depth=depth is not None,
    has_rgb=rgb is not None,
    depth_units='mm',
    generator_version=meta.get('generator_version', GENERATOR_VERSION),
  )
  return final, meta, depth, rgb


def _write_frames(folder: str, depth: np.ndarray, rgb) -> None:
  """Writes ``cam{c}/{t:04d}.png`` (depth (C, T, H, W) metres, as mm) and,
  with ``rgb`` (C, T, H, W, 3) uint8, ``cam{c}/rgb_{t:04d}.png`` in ``folder``."""
  mm = depth_to_mm(depth)
  n_cam, n_frames = depth.shape[:2]
  for c in range(n_cam):
    cam = os.path.join(folder, f'cam{c}')
    os.makedirs(cam)
    for t in range(n_frames):
      imwrite(os.path.join(cam, f'{t:04d}.png'), mm[c, t])
      if rgb is not None:
        bgr = cv2.cvtColor(rgb[c, t], cv2.COLOR_RGB2BGR)
        imwrite(os.path.join(cam, f'rgb_{t:04d}.png'), bgr)


def clean_tmp(root: str) -> list[str]:
  """Removes temporary folders/files a crashed writer left; returns their paths."""
  removed = []
  if not os.path.isdir(root):
    return removed
  for folder in [root] + [
    os.path.join(root, d) for d in sorted(os.listdir(root)) if not d.startswith('.')
  ]:
    if not os.path.isdir(folder):
      continue
    for name in sorted(os.listdir(folder)):
      if name.startswith(TMP_PREFIX):
        p = os.path.join(folder, name)
        if os.path.isdir(p):
          shutil.rmtree(p, ignore_errors=True)
        else:
          os.remove(p)
        removed.append(p)
  return removed


def _format(value) -> str:
  if isinstance(value, bool):
    return 'true' if value else 'false'
  if isinstance(value, float):
    return repr(value)  # shortest repr round-trips exactly
  return str(value)


def write_index(root: str, rows: Iterable[dict]) -> str:
  """Writes ``<root>/index.csv`` atomically, rows sorted by (material, seq_id)."""
  rows = sorted(rows, key=lambda r: (r['material'], r['seq_id']))
  buf = io.StringIO()
  w = csv.writer(buf, lineterminator='\n')
  w.writerow(INDEX_COLUMNS)
  for r in rows:
    w.writerow([_format(r[c]) for c in INDEX_COLUMNS])
  path = os.path.join(root, 'index.csv')
  write_text_atomic(path, buf.getvalue())
  return path


def rebuild_index(root: str) -> list[dict]:
  """Rewrites ``index.csv`` from every finished sequence's ``meta.json``."""
  rows = []
  for path in finished_sequences(root):
    meta = read_json(os.path.join(path, 'meta.json'))
    missing = [c for c in INDEX_COLUMNS if c not in meta]
    if missing:
      raise ValueError(f'{path}/meta.json lacks the fields {missing}')
    rows.append({c: meta[c] for c in INDEX_COLUMNS})
  write_index(root, rows)
  return rows


def write_dataset_info(root: str, *, seed: int, config: dict, **extra) -> dict:
  """Writes ``<root>/dataset.json`` (generator version, seed, config, created)."""
  info = {
    'generator_version': GENERATOR_VERSION,
    'seed': int(seed),
    'config': config,
    'created': time.strftime('%Y-%m-%dT%H:%M:%S%z'),
    **extra,
  }
  write_json_atomic(os.path.join(root, 'dataset.json'), info)
  return info
