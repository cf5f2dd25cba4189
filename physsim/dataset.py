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
"""

from __future__ import annotations

import csv
import errno
import io
import json
import math
import os
import re
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterable
from collections.abc import Sequence as Seq
from typing import Any, NamedTuple

import cv2
import numpy as np

from physsim import params as params_lib
from physsim.materials import FABRICS

GENERATOR_VERSION = 'physsim-dataset/1'
MM_PER_M = 1000.0
MAX_MM = 65535
TMP_PREFIX = '.tmp-'
INDEX_COLUMNS = (
  'seq_id',
  'material',
  'label',
  'bending_scale',
  'wind_speed',
  'area_weight',
  'u_bending_scale',
  'u_wind_speed',
  'u_area_weight',
  'valid',
  'n_cameras',
  'n_frames',
)
_SAFE_NAME = re.compile(r'[A-Za-z0-9_.-]+')
_COLUMN_TYPES = {
  'seq_id': str,
  'material': str,
  'label': int,
  'valid': lambda s: {'true': True, 'false': False}[s.lower()],
  'n_cameras': int,
  'n_frames': int,
}


# ------------------------------------------------------------------ conversion


def depth_to_mm(depth) -> np.ndarray:
  """Metres to 16-bit millimetres for PNG storage.

  Args:
    depth: float array of any shape, metres; 0, negative, NaN or inf = invalid.

  Returns:
    uint16 array of the same shape: ``round(1000 d)`` clipped to [0, 65535],
    with 0 wherever the input is invalid.
  """
  d = np.asarray(depth, np.float64)
  ok = np.isfinite(d) & (d > 0)
  mm = np.rint(np.where(ok, d, 0.0) * MM_PER_M)
  return np.clip(mm, 0, MAX_MM).astype(np.uint16)


def mm_to_depth(mm) -> np.ndarray:
  """16-bit millimetres to float32 metres (0 stays 0 = invalid)."""
  return (np.asarray(mm, np.float64) / MM_PER_M).astype(np.float32)


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


def read_json(path: str) -> dict:
  """A JSON object from ``path``; missing or corrupt is a ValueError naming it."""
  try:
    with open(path) as f:
      out = json.load(f)
  except FileNotFoundError:
    raise ValueError(f'{path}: file not found') from None
  except (json.JSONDecodeError, UnicodeDecodeError) as e:
    raise ValueError(f'{path}: not valid JSON ({e})') from None
  if not isinstance(out, dict):
    raise ValueError(f'{path}: expected a JSON object, got {type(out).__name__}')
  return out


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


def read_png(path: str, dtype=None) -> np.ndarray:
  """Reads a PNG unchanged; ValueError naming the file if missing or corrupt."""
  if not os.path.isfile(path):
    raise ValueError(f'{path}: file not found')
  image = cv2.imread(path, cv2.IMREAD_UNCHANGED)
  if image is None:
    raise ValueError(f'{path}: not a readable image (corrupt or not a PNG)')
  if dtype is not None and image.dtype != dtype:
    raise ValueError(
      f'{path}: expected {np.dtype(dtype).name} pixels, got {image.dtype}'
    )
  return image


# ------------------------------------------------------------------ index rows


def make_row(
  seq_id: str,
  material: str,
  label: int,
  params: params_lib.Params | None,
  space: params_lib.SearchSpace | None,
  *,
  valid: bool,
  n_cameras: int,
  n_frames: int,
) -> dict:
  """One index row; ``params=None`` (a real capture) stores NaN parameters.

  Args:
    seq_id: folder name of the sequence, unique within its material.
    material: fabric name (a folder name).
    label: integer class, unique per parameter set in the dataset.
    params: one parameter set (scalar fields) or None if unknown.
    space: the material's search space, for the [-1, 1] values.
    valid: False where the simulation blew up.
    n_cameras: cameras C.
    n_frames: frames T.

  Returns:
    dict with exactly ``INDEX_COLUMNS``.
  """
  for name, value in (('seq_id', seq_id), ('material', material)):
    if not value or os.sep in value or value.startswith('.') or ',' in value:
      raise ValueError(f'{name}={value!r} is not a usable folder name')
  if params is None:
    phys, unit = [math.nan] * 3, [math.nan] * 3
  else:
    p = params_lib.make(*params)
    phys = [float(getattr(p, f)) for f in params_lib.FIELDS]
    unit = [float(x) for x in np.ravel(params_lib.to_unit(p, space))]
  return {
    'seq_id': str(seq_id),
    'material': str(material),
    'label': int(label),
    **dict(zip(params_lib.FIELDS, phys, strict=True)),
    **{f'u_{f}': u for f, u in zip(params_lib.FIELDS, unit, strict=True)},
    'valid': bool(valid),
    'n_cameras': int(n_cameras),
    'n_frames': int(n_frames),
  }


def sequence_dir(root: str, material: str, seq_id: str) -> str:
  return os.path.join(root, material, seq_id)


def is_complete(root: str, material: str, seq_id: str) -> bool:
  """True if the sequence folder exists and holds its ``meta.json``."""
  return os.path.isfile(os.path.join(sequence_dir(root, material, seq_id), 'meta.json'))


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
  parent = os.path.dirname(final)
  os.makedirs(parent, exist_ok=True)
  tmp = os.path.join(parent, f'{TMP_PREFIX}{seq_id}-{uuid.uuid4().hex[:8]}')
  os.makedirs(tmp)
  try:
    if depth is not None:
      mm = depth_to_mm(depth)
      for c in range(n_cam):
        cam = os.path.join(tmp, f'cam{c}')
        os.makedirs(cam)
        for t in range(n_frames):
          imwrite(os.path.join(cam, f'{t:04d}.png'), mm[c, t])
          if rgb is not None:
            bgr = cv2.cvtColor(rgb[c, t], cv2.COLOR_RGB2BGR)
            imwrite(os.path.join(cam, f'rgb_{t:04d}.png'), bgr)
    # meta.json last: its presence marks the folder complete.
    with open(os.path.join(tmp, 'meta.json'), 'w') as f:
      json.dump(meta, f, indent=1, sort_keys=True, allow_nan=True)
    if os.path.exists(final):
      old = os.path.join(parent, f'{TMP_PREFIX}old-{seq_id}-{uuid.uuid4().hex[:8]}')
      os.replace(final, old)
      os.replace(tmp, final)
      shutil.rmtree(old, ignore_errors=True)
    else:
      os.replace(tmp, final)
  except BaseException:
    shutil.rmtree(tmp, ignore_errors=True)
    raise
  return final


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


def finished_sequences(root: str) -> list[str]:
  """Folders ``<root>/<material>/<seq_id>`` that hold a ``meta.json``, sorted."""
  out = []
  if not os.path.isdir(root):
    return out
  for m in sorted(os.listdir(root)):
    mdir = os.path.join(root, m)
    if m.startswith('.') or not os.path.isdir(mdir):
      continue
    for s in sorted(os.listdir(mdir)):
      if not s.startswith('.') and os.path.isfile(os.path.join(mdir, s, 'meta.json')):
        out.append(os.path.join(mdir, s))
  return out


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


# --------------------------------------------------------------------- reading


class DatasetIndex(NamedTuple):
  """A dataset's ``dataset.json`` and ``index.csv``.

  Attributes:
    root: dataset folder.
    info: parsed ``dataset.json`` (empty dict if absent, e.g. a capture folder).
    rows: one dict per sequence with the ``INDEX_COLUMNS``, typed.
  """

  root: str
  info: dict
  rows: tuple[dict, ...]

  @property
  def materials(self) -> tuple[str, ...]:
    return tuple(sorted({r['material'] for r in self.rows}))

  def filter(self, material: str | None = None, valid: bool | None = None):
    """Rows of one material and/or validity, as a new ``DatasetIndex``."""
    rows = tuple(
      r
      for r in self.rows
      if (material is None or r['material'] == material)
      and (valid is None or r['valid'] == valid)
    )
    return self._replace(rows=rows)

  def path(self, row: dict) -> str:
    return sequence_dir(self.root, row['material'], row['seq_id'])


def open_dataset(root: str) -> DatasetIndex:
  """Reads ``<root>/index.csv`` (and ``dataset.json`` if present).

  Raises:
    ValueError: naming the file, if the folder or index is missing or malformed.
  """
  if not os.path.isdir(root):
    raise ValueError(f'{root}: dataset folder not found')
  path = os.path.join(root, 'index.csv')
  if not os.path.isfile(path):
    raise ValueError(f'{path}: file not found (run rebuild_index on the folder?)')
  info_path = os.path.join(root, 'dataset.json')
  info = read_json(info_path) if os.path.isfile(info_path) else {}
  rows = []
  with open(path, newline='') as f:
    reader = csv.DictReader(f)
    if tuple(reader.fieldnames or ()) != INDEX_COLUMNS:
      raise ValueError(f'{path}: header {reader.fieldnames} != {list(INDEX_COLUMNS)}')
    for line, raw in enumerate(reader, start=2):
      try:
        rows.append({k: _COLUMN_TYPES.get(k, float)(v) for k, v in raw.items()})
      except (KeyError, ValueError, TypeError, AttributeError) as e:
        raise ValueError(f'{path}:{line}: malformed row {raw} ({e})') from None
      # Both name folders under the root: a path in them would escape it.
      for key in ('material', 'seq_id'):
        if not _SAFE_NAME.fullmatch(rows[-1][key]) or rows[-1][key] in ('.', '..'):
          raise ValueError(
            f'{path}:{line}: {key} {rows[-1][key]!r} is not a plain name'
          )
      if rows[-1]['material'] not in FABRICS:
        raise ValueError(
          f'{path}:{line}: material {rows[-1]["material"]!r} is not one of '
          f'{sorted(FABRICS)}'
        )
  return DatasetIndex(root, info, tuple(rows))


class Sequence(NamedTuple):
  """One sequence read back.

  Attributes:
    depth: (C, T, H, W) float32 metres, 0 = invalid.
    meta: the parsed ``meta.json``.
    rgb: (C, T, H, W, 3) uint8 or None.
  """

  depth: np.ndarray
  meta: dict
  rgb: np.ndarray | None


def _read_frames(path, meta, cameras, frames, rgb: bool):
  h, w = int(meta['height']), int(meta['width'])
  out = np.empty(
    (len(cameras), len(frames), h, w, 3) if rgb else (len(cameras), len(frames), h, w),
    np.uint8 if rgb else np.uint16,
  )
  for i, c in enumerate(cameras):
    for j, t in enumerate(frames):
      name = f'rgb_{t:04d}.png' if rgb else f'{t:04d}.png'
      file = os.path.join(path, f'cam{c}', name)
      image = read_png(file, np.uint8 if rgb else np.uint16)
      if image.shape[:2] != (h, w) or image.ndim != (3 if rgb else 2):
        raise ValueError(
          f'{file}: shape {image.shape}, expected ({h}, {w}) from meta.json'
        )
      out[i, j] = cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if rgb else image
  return out


def read_sequence(
  path: str,
  *,
  cameras: Seq[int] | None = None,
  frames: Seq[int] | None = None,
  rgb: bool = True,
) -> Sequence:
  """Reads a finished sequence folder.

  Args:
    path: ``<root>/<material>/<seq_id>``.
    cameras: camera indices to read (default all).
    frames: frame indices to read (default all).
    rgb: also read colour frames if the sequence has them.

  Returns:
    ``Sequence`` with depth (C', T', H, W) float32 metres.

  Raises:
    ValueError: naming the file: no ``meta.json``, a sequence without frames
      (an invalid simulation), indices out of range, a missing or corrupt PNG.
  """
  meta = read_json(os.path.join(path, 'meta.json'))
  if not meta.get('has_depth', True):
    raise ValueError(
      f'{path}/meta.json: sequence has no frames (valid={meta.get("valid")})'
    )
  n_cam, n_frames = int(meta['n_cameras']), int(meta['n_frames'])
  cameras = range(n_cam) if cameras is None else list(cameras)
  frames = range(n_frames) if frames is None else list(frames)
  for name, idx, n in (('camera', cameras, n_cam), ('frame', frames, n_frames)):
    bad = [i for i in idx if not 0 <= i < n]
    if bad:
      raise ValueError(f'{path}: {name} indices {bad} outside [0, {n})')
  depth = mm_to_depth(_read_frames(path, meta, cameras, frames, rgb=False))
  colour = None
  if rgb and meta.get('has_rgb'):
    colour = _read_frames(path, meta, cameras, frames, rgb=True)
  return Sequence(depth, meta, colour)


class TrainingArrays(NamedTuple):
  """Flattened images of one material with what identifies each.

  Attributes:
    images: (N, H, W) float32 metres, 0 = invalid.
    labels: (N,) int label of the parameter set (one per simulation).
    seq_ids: (N,) str sequence id, for splitting by simulation.
    cameras: (N,) int camera index.
    frames: (N,) int frame index.
    params: (N, 3) float64 physical (bending, wind, area weight).
    unit_params: (N, 3) float64 the same in [-1, 1].
  """

  images: np.ndarray
  labels: np.ndarray
  seq_ids: np.ndarray
  cameras: np.ndarray
  frames: np.ndarray
  params: np.ndarray
  unit_params: np.ndarray


def resize_depth(depth: np.ndarray, size: tuple[int, int]) -> np.ndarray:
  """Nearest-neighbour resize of (..., H, W) to ``size`` = (height, width).

  Nearest keeps each output pixel a real measurement: interpolating would blend
  cloth edges with the invalid zeros around them into phantom depths.
  """
  h, w = size
  if depth.shape[-2:] == (h, w):
    return depth
  flat = depth.reshape(-1, *depth.shape[-2:])
  out = np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_NEAREST) for f in flat])
  return out.reshape(*depth.shape[:-2], h, w)


def load_training_arrays(
  dataset: str | DatasetIndex,
  material: str,
  *,
  size: tuple[int, int] | None = None,
  cameras: Seq[int] | None = None,
  frames: Seq[int] | None = None,
) -> TrainingArrays:
  """Loads every valid sequence of one material as flat training images.

  Args:
    dataset: root folder or an opened ``DatasetIndex``.
    material: which material's rows.
    size: optional (height, width) to resize to (nearest neighbour).
    cameras: camera indices per sequence (default all).
    frames: frame indices per sequence (default all).

  Returns:
    ``TrainingArrays`` ordered by sequence, then camera, then frame.

  Raises:
    ValueError: no valid sequences of that material, or a bad file (named).
  """
  index = dataset if isinstance(dataset, DatasetIndex) else open_dataset(dataset)
  rows = index.filter(material=material, valid=True).rows
  if not rows:
    raise ValueError(
      f'{index.root}: no valid sequences of material {material!r} '
      f'(materials: {list(index.materials)})'
    )
  parts = {k: [] for k in TrainingArrays._fields}
  for r in rows:
    seq = read_sequence(index.path(r), cameras=cameras, frames=frames, rgb=False)
    d = seq.depth if size is None else resize_depth(seq.depth, size)
    c, t = d.shape[:2]
    n = c * t
    parts['images'].append(d.reshape(n, *d.shape[2:]))
    parts['labels'].append(np.full(n, r['label'], np.int64))
    parts['seq_ids'].append(np.full(n, r['seq_id'], dtype=object))
    cam_idx = (
      np.arange(seq.meta['n_cameras']) if cameras is None else np.asarray(cameras)
    )
    frame_idx = (
      np.arange(seq.meta['n_frames']) if frames is None else np.asarray(frames)
    )
    parts['cameras'].append(np.repeat(cam_idx, t))
    parts['frames'].append(np.tile(frame_idx, c))
    phys = [r[f] for f in params_lib.FIELDS]
    unit = [r[f'u_{f}'] for f in params_lib.FIELDS]
    parts['params'].append(np.tile(np.asarray(phys, np.float64), (n, 1)))
    parts['unit_params'].append(np.tile(np.asarray(unit, np.float64), (n, 1)))
  shapes = {p.shape[1:] for p in parts['images']}
  if len(shapes) > 1:
    raise ValueError(
      f'{index.root}: sequences of {material!r} differ in frame size {shapes}; '
      'pass size=(H, W)'
    )
  out = {k: np.concatenate(v) for k, v in parts.items()}
  out['seq_ids'] = out['seq_ids'].astype(str)
  return TrainingArrays(**out)
