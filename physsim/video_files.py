"""A depth recording's files before any pixel is decoded: which files of a
folder are its frames, what their headers say (how many frames, how large,
and so whether they fit in memory), and the frame rate written beside them.

``physsim.video`` checks these first, so that a recording too large, of
frames of different sizes, or with a malformed ``meta.json`` is refused by
name before it is read; ``physsim.bags`` and ``experiments.pipeline.intake``
check theirs by the same limits.
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
import re
import struct
import zipfile
from typing import NamedTuple

import numpy as np

from physsim import input_files

# Source frame rates outside this range are a typo, not a camera.
FPS_RANGE = (1.0, 1000.0)
# The most decoded frames (float32 bytes) one video may expand to.
MAX_BYTES = 8 << 30
# The largest frame side, pixels: no depth camera writes more (checked from
# the file's header, before its pixels are decoded).
MAX_SIDE = 8192
_NOT_FRAMES = ('rgb_', 'color', 'colour', 'mask', 'preview')
# The largest meta.json read for its fps.
MAX_TEXT_BYTES = 16 << 20


def natural_key(name: str) -> list:
  """Sort key that orders the numbers in names by value: 2 before 10."""
  return [int(t) if t.isdigit() else t.lower() for t in re.split(r'(\d+)', name)]


def frame_files(path: str, pattern: str = '*.png') -> list[str]:
  """The frame files of a folder in natural order: names matching ``pattern``
  that hold a number and are not colour, mask or preview images.

  Raises:
    ValueError: naming it: a frame's name on a FIFO, socket, device or folder
      (``open()`` on a FIFO would wait forever).
  """
  files = [
    f
    for f in os.listdir(path)
    if fnmatch.fnmatch(f.lower(), pattern.lower())
    and any(c.isdigit() for c in f)
    and not f.lower().startswith(_NOT_FRAMES)
  ]
  for f in files:
    input_files.check_regular(os.path.join(path, f), 'frame')
  return sorted(files, key=natural_key)


class Header(NamedTuple):
  """What a recording's headers say before any pixel is decoded.

  Attributes:
    frames: how many frames (after ``start``).
    height, width: a frame's size, pixels.
  """

  frames: int
  height: int
  width: int

  @property
  def decoded_bytes(self) -> int:
    """Bytes of the frames decoded as float32."""
    return 4 * self.frames * self.height * self.width


_PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def png_size(file: str) -> tuple[int, int] | None:
  """(width, height) from a PNG's IHDR chunk (its first 24 bytes), or None
  for a file that is not a PNG (another format OpenCV may still read).

  Raises:
    ValueError: naming the file: a PNG signature with a broken header.
  """
  with open(file, 'rb') as f:
    head = f.read(24)
  if not head.startswith(_PNG_SIGNATURE):
    return None
  if len(head) < 24 or head[12:16] != b'IHDR':
    raise ValueError(f'{file}: not a readable image (a PNG without its IHDR header)')
  w, h = struct.unpack('>II', head[16:24])
  return w, h


def _npy_shape(f) -> tuple[tuple[int, ...], np.dtype] | None:
  """(shape, dtype) from an open .npy stream's header, or None for a header
  version this reader does not parse (the full load then checks it)."""
  version = np.lib.format.read_magic(f)
  if version == (1, 0):
    shape, _, dtype = np.lib.format.read_array_header_1_0(f)
  elif version == (2, 0):
    shape, _, dtype = np.lib.format.read_array_header_2_0(f)
  else:
    return None
  return tuple(int(n) for n in shape), dtype


def _array_header(path: str) -> Header | None:
  """The depth array's header of a .npy or .npz, or None when unknown."""
  try:
    if path.lower().endswith('.npz'):
      with zipfile.ZipFile(path) as z:
        names = [n for n in z.namelist() if n.endswith('.npy')]
        arrays = [n for n in names if n != 'fps.npy']
        name = 'depth.npy' if 'depth.npy' in names else None
        if name is None and len(arrays) == 1:
          name = arrays[0]
        if name is None:
          return None
        with z.open(name) as f:
          found = _npy_shape(f)
    else:
      with open(path, 'rb') as f:
        found = _npy_shape(f)
  except (OSError, ValueError, EOFError, zipfile.BadZipFile, struct.error) as e:
    raise ValueError(f'{path}: not a readable NumPy file ({e})') from None
  if found is None:
    return None
  shape, _ = found
  if len(shape) != 3:
    raise ValueError(f'{path}: depth array must be (T, H, W), got shape {shape}')
  return Header(*shape)


def read_header(path: str, pattern: str = '*.png', start: int = 0) -> Header | None:
  """A recording's frame count and size from its headers alone (PNG IHDR,
  .npy/.npz array headers), or None where only decoding tells (videos,
  non-PNG images).

  Raises:
    ValueError: naming the file: frames of different sizes, a side above
      ``MAX_SIDE``, or more than ``MAX_BYTES`` once decoded.
  """
  if os.path.isdir(path):
    files = frame_files(path, pattern)[start:]
    if not files:
      return None
    first = None
    for name in files:
      size = png_size(os.path.join(path, name))
      if size is None:
        return None
      if first is None:
        first = (name, size)
      elif size != first[1]:
        raise ValueError(
          f'{os.path.join(path, name)}: shape/dtype {size[0]} x {size[1]} px '
          f'differs from the first frame {first[0]} ({first[1][0]} x {first[1][1]})'
        )
    header = Header(len(files), first[1][1], first[1][0])
  elif os.path.isfile(path) and path.lower().endswith(('.npy', '.npz')):
    header = _array_header(path)
    if header is None:
      return None
    header = header._replace(frames=max(header.frames - start, 0))
  else:
    return None
  if max(header.height, header.width) > MAX_SIDE:
    raise ValueError(
      f'{path}: frames of {header.width} x {header.height} px; no depth camera '
      f'writes more than {MAX_SIDE} a side'
    )
  if header.decoded_bytes > MAX_BYTES:
    raise ValueError(
      f'{path}: {header.frames} frames of {header.width} x {header.height} px would '
      f'take {header.decoded_bytes / 2**30:.1f} GiB decoded (at most '
      f'{MAX_BYTES / 2**30:g}); cut the recording (start, fewer files)'
    )
  return header


def fps_beside(folder: str) -> float | None:
  """fps from ``meta.json`` or ``fps.txt`` in ``folder`` or its parent."""
  for d in (folder, os.path.dirname(os.path.abspath(folder))):
    meta = os.path.join(d, 'meta.json')
    txt = os.path.join(d, 'fps.txt')
    for file in (meta, txt):
      if input_files.is_special(file):
        input_files.check_regular(file, 'file')
    if os.path.isfile(meta):
      try:
        if os.path.getsize(meta) > MAX_TEXT_BYTES:
          raise ValueError(f'larger than {MAX_TEXT_BYTES >> 20} MiB')
        with open(meta, encoding='utf-8') as f:
          value = json.load(f).get('fps')
      except (ValueError, AttributeError, RecursionError) as e:
        why = 'nested too deeply' if isinstance(e, RecursionError) else e
        raise ValueError(f'{meta}: not a JSON object with "fps" ({why})') from None
      if value is not None:
        return positive_fps(meta, value)
    if os.path.isfile(txt):
      try:
        with open(txt, encoding='utf-8') as f:
          text = f.read(64).strip()
      except ValueError:
        text = '(not text)'
      return positive_fps(txt, text)
  return None


def positive_fps(where: str, value) -> float:
  """``value`` as a frame rate, checked to lie in ``FPS_RANGE``.

  Raises:
    ValueError: naming ``where``: not a number, or outside the range.
  """
  try:
    fps = float(value)
  except (TypeError, ValueError):
    fps = math.nan
  lo, hi = FPS_RANGE
  if not (math.isfinite(fps) and lo <= fps <= hi):
    raise ValueError(
      f'{where}: fps must be a number in [{lo:g}, {hi:g}], got {value!r}'
    )
  return fps
