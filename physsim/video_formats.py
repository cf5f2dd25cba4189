"""Decodes a depth recording's frames, one reader per format (the formats are
listed in ``physsim.video``'s docstring), and checks their values: a 16-bit
PNG folder's unit, an array's metres. Each reader returns the frames as they
were recorded (``Raw``); ``physsim.video`` masks, resamples and resizes them.
"""

from __future__ import annotations

import os
import zipfile
from typing import NamedTuple

import cv2
import numpy as np

from physsim.video_files import frame_files, read_header

# Depth beyond this in a file said to be in metres is almost surely millimetres.
MAX_METRES = 20.0
# The nearest surfaces of a cloth recording (5th percentile of valid depth)
# outside this range mean a wrong unit: TUM's 5000 per metre read as mm puts a
# cloth at 2-4 m at 5-10 m.
PLAUSIBLE_METRES = (0.1, 5.0)
VIDEO_EXTENSIONS = ('.mp4', '.avi', '.mov', '.mkv', '.m4v', '.webm', '.mpg', '.mpeg')


class Raw(NamedTuple):
  """A recording's frames as decoded, before masking and resampling.

  Attributes:
    frames: (T, H, W) float32: metres, or [0, 1] if ``normalised``.
    names: each frame's name, for error messages.
    normalised: True if absolute depth was lost (per-frame min-max intensity).
    fps: the frame rate the file itself says (an .npz's, a video's), or None.
    kind: the format: png16, png8, npy, npz or video.
  """

  frames: np.ndarray
  names: list[str]
  normalised: bool
  fps: float | None
  kind: str


def _to_grey(image: np.ndarray) -> np.ndarray:
  """A colour frame (BGR or BGRA, as OpenCV reads it) as one grey channel."""
  if image.ndim == 3 and image.shape[2] == 4:
    return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
  if image.ndim == 3 and image.shape[2] == 3:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
  return image


def read_png_folder(path: str, pattern: str, depth_scale: float, start: int) -> Raw:
  """The frames of a PNG folder from the ``start``-th on: 16-bit ones in
  metres (``depth_scale`` per unit), 8-bit ones normalised to [0, 1]; sizes
  and memory checked from the headers before any is decoded."""
  files = frame_files(path, pattern)
  if not files:
    raise ValueError(
      f'{path}: no frames (files matching {pattern!r} with a number in the name)'
    )
  if start >= len(files):
    raise ValueError(f'{path}: start {start} but only {len(files)} frames')
  read_header(path, pattern, start)  # sizes and memory, before decoding
  files = files[start:]
  frames, first = [], None
  for name in files:
    file = os.path.join(path, name)
    image = cv2.imread(file, cv2.IMREAD_UNCHANGED)
    if image is None:
      raise ValueError(f'{file}: not a readable image (corrupt or not a PNG)')
    if first is None:
      if image.dtype == np.uint16 and image.ndim != 2:
        raise ValueError(
          f'{file}: 16-bit depth must have one channel, got {image.shape}'
        )
      if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f'{file}: expected 8- or 16-bit PNG, got {image.dtype}')
      first = (image.shape, image.dtype)
    elif (image.shape, image.dtype) != first:
      raise ValueError(
        f'{file}: shape/dtype {image.shape} {image.dtype} differs from the first '
        f'frame {files[0]} ({first[0]} {first[1]})'
      )
    frames.append(image)
  if first[1] == np.uint16:
    depth = np.stack(frames).astype(np.float32) / np.float32(1.0 / depth_scale)
    _check_scale(path, depth, depth_scale)
    return Raw(depth, files, False, None, 'png16')
  grey = np.stack([_to_grey(f) for f in frames]).astype(np.float32) / np.float32(255)
  return Raw(grey, files, True, None, 'png8')


def _check_scale(path: str, depth: np.ndarray, depth_scale: float) -> None:
  """A wrong unit (TUM's 5000 per metre read as mm) shows as implausibly far
  (or near) nearest surfaces."""
  valid = depth[depth > 0]
  if valid.size == 0:
    return
  near = float(np.quantile(valid, 0.05))
  lo, hi = PLAUSIBLE_METRES
  if not lo <= near <= hi:
    raise ValueError(
      f'{path}: the nearest surfaces lie at {near:.3g} m with depth_scale '
      f'{depth_scale:g} m per unit, outside [{lo:g}, {hi:g}] m; give the file '
      'unit with depth_scale (0.001: mm, 0.0002: TUM 5000 per metre)'
    )


def _check_metres(path: str, depth: np.ndarray) -> np.ndarray:
  """An array's depth as float32 metres: (T, H, W), numeric, finite, not
  negative and not millimetres."""
  if depth.ndim != 3:
    raise ValueError(f'{path}: depth array must be (T, H, W), got shape {depth.shape}')
  if depth.shape[0] == 0 or depth.size == 0:
    raise ValueError(f'{path}: no frames (shape {depth.shape})')
  if not (
    np.issubdtype(depth.dtype, np.floating) or np.issubdtype(depth.dtype, np.integer)
  ):
    raise ValueError(f'{path}: depth must be numeric, got {depth.dtype}')
  depth = depth.astype(np.float64)
  bad = ~np.isfinite(depth)
  if bad.any():
    t = int(np.argwhere(bad)[0, 0])
    raise ValueError(f'{path}: NaN/inf depth (first in frame {t}); use 0 for invalid')
  if (depth < 0).any():
    t = int(np.argwhere(depth < 0)[0, 0])
    raise ValueError(f'{path}: negative depth {depth.min():g} (frame {t})')
  if depth.max() > MAX_METRES:
    raise ValueError(
      f'{path}: depth up to {depth.max():g} "metres" looks like millimetres; '
      'divide by 1000'
    )
  return depth.astype(np.float32)


def _scalar_fps(path: str, value) -> float:
  """An .npz's ``fps`` member as one number."""
  a = np.asarray(value)
  if a.size != 1 or a.dtype.kind not in 'iuf':
    raise ValueError(
      f'{path}: "fps" must be one number, got a {a.dtype} array of shape {a.shape}'
    )
  return float(a.reshape(()))


def read_array(path: str) -> Raw:
  """The depth of an ``.npy``, or an ``.npz``'s ``depth`` array (or its only
  one) and ``fps``, in metres."""
  read_header(path)  # shape and memory, before decoding
  try:
    data = np.load(path, allow_pickle=False)
  except (OSError, ValueError, EOFError) as e:
    raise ValueError(f'{path}: not a readable NumPy file ({e})') from None
  fps = None
  if isinstance(data, np.lib.npyio.NpzFile):
    # Members load lazily: their errors (pickled objects, truncation) here.
    try:
      with data:
        keys = list(data.keys())
        if 'depth' in keys:
          depth = data['depth']
        elif len([k for k in keys if k != 'fps']) == 1:
          depth = data[next(k for k in keys if k != 'fps')]
        else:
          raise ValueError(f'{path}: .npz needs a "depth" array, has {keys}')
        if 'fps' in keys:
          fps = _scalar_fps(path, data['fps'])
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
      if str(e).startswith(path):
        raise
      raise ValueError(f'{path}: not a readable NumPy file ({e})') from None
    kind = 'npz'
  else:
    depth, kind = data, 'npy'
  depth = _check_metres(path, np.asarray(depth))
  names = [f'frame {t}' for t in range(depth.shape[0])]
  return Raw(depth, names, False, fps, kind)


def read_video(path: str) -> Raw:
  """A video file's frames as grey intensity / 255 (normalised) and the
  frame rate its container says."""
  cap = cv2.VideoCapture(path)
  try:
    if not cap.isOpened():
      raise ValueError(f'{path}: OpenCV cannot open the video')
    fps = cap.get(cv2.CAP_PROP_FPS)
    frames = []
    while True:
      ok, image = cap.read()
      if not ok:
        break
      frames.append(_to_grey(image))
  finally:
    cap.release()
  if not frames:
    raise ValueError(f'{path}: no frames could be decoded')
  if len({f.shape for f in frames}) > 1:
    raise ValueError(f'{path}: frames differ in size')
  grey = np.stack(frames).astype(np.float32) / np.float32(255)
  names = [f'frame {t}' for t in range(len(frames))]
  return Raw(grey, names, True, fps if fps and fps > 0 else None, 'video')
