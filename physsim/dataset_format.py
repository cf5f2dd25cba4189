"""The dataset format's parts shared by its writer and reader: the layout's
constants and index columns, depth in 16-bit millimetres, a JSON or PNG read
back (a bad file named), an index row and where a sequence's folder is
(``physsim.dataset`` has the layout)."""

from __future__ import annotations

import json
import math
import os

import cv2
import numpy as np

from physsim import params as params_lib

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
