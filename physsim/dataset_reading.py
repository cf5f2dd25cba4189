"""Reading a dataset back: its index (``index.csv`` and ``dataset.json``), a
sequence's frames, and one material's sequences as flat training images."""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Sequence as Seq
from typing import NamedTuple

import cv2
import numpy as np

from physsim import params as params_lib
from physsim.dataset_format import (
  INDEX_COLUMNS,
  mm_to_depth,
  read_json,
  read_png,
  sequence_dir,
)
from physsim.materials import FABRICS

_SAFE_NAME = re.compile(r'[A-Za-z0-9_.-]+')
_COLUMN_TYPES = {
  'seq_id': str,
  'material': str,
  'label': int,
  'valid': lambda s: {'true': True, 'false': False}[s.lower()],
  'n_cameras': int,
  'n_frames': int,
}


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
