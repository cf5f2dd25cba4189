"""Loads depth videos (real captures or simulated frames) into one checked form.

Formats, chosen by the path:
  * a folder of 16-bit PNGs, 0 = invalid, in millimetres unless ``depth_scale``
    says otherwise (this project's format, e.g. ``<seq>/cam0``). Frames are the
    files matching ``pattern`` whose names hold a number, in natural order
    (``2.png`` before ``10.png``); ``rgb_*``, ``color*``, ``mask*`` and
    ``preview*`` files are never frames;
  * a folder of 8-bit PNGs, each frame min-max normalised (the original paper's
    real captures): absolute depth is lost, so values are returned in [0, 1]
    with ``normalised=True``; 0 (the masked background) counts as invalid;
  * ``.npy`` / ``.npz`` float arrays (T, H, W) in metres (``.npz``: key
    ``depth`` or its only array, optional scalar ``fps``);
  * a video file OpenCV reads (``.mp4``, ``.avi``, ...): grey intensity / 255,
    treated as normalised like the 8-bit PNGs.

The source frame rate comes from ``source_fps``, else a ``meta.json`` (key
``fps``) or ``fps.txt`` in the frames' folder or its parent (beside a file for
arrays and videos), else the ``.npz`` ``fps`` or the video's CAP_PROP_FPS.
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

import cv2
import numpy as np

from physsim import input_files

# Depth beyond this in a file said to be in metres is almost surely millimetres.
MAX_METRES = 20.0
# The nearest surfaces of a cloth recording (5th percentile of valid depth)
# outside this range mean a wrong unit: TUM's 5000 per metre read as mm puts a
# cloth at 2-4 m at 5-10 m.
PLAUSIBLE_METRES = (0.1, 5.0)
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
VIDEO_EXTENSIONS = ('.mp4', '.avi', '.mov', '.mkv', '.m4v', '.webm', '.mpg', '.mpeg')


class DepthVideo(NamedTuple):
  """A loaded depth video.

  Attributes:
    depth: (T, H, W) float32; metres, or [0, 1] if ``normalised``; 0 = invalid.
    fps: frame rate of ``depth`` (None if unknown and not resampled).
    normalised: True if absolute depth was lost (per-frame min-max intensity).
    source: ``'<format>:<path>'``, format one of png16, png8, npy, npz, video.
  """

  depth: np.ndarray
  fps: float | None
  normalised: bool
  source: str


class _Raw(NamedTuple):
  frames: np.ndarray  # (T, H, W) float32
  names: list[str]  # per-frame name for error messages
  normalised: bool
  fps: float | None
  kind: str


def _to_grey(image: np.ndarray) -> np.ndarray:
  if image.ndim == 3 and image.shape[2] == 4:
    return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
  if image.ndim == 3 and image.shape[2] == 3:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
  return image


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


def _read_png_folder(path: str, pattern: str, depth_scale: float, start: int) -> _Raw:
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
    return _Raw(depth, files, False, None, 'png16')
  grey = np.stack([_to_grey(f) for f in frames]).astype(np.float32) / np.float32(255)
  return _Raw(grey, files, True, None, 'png8')


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
  a = np.asarray(value)
  if a.size != 1 or a.dtype.kind not in 'iuf':
    raise ValueError(
      f'{path}: "fps" must be one number, got a {a.dtype} array of shape {a.shape}'
    )
  return float(a.reshape(()))


def _read_array(path: str) -> _Raw:
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
  return _Raw(depth, names, False, fps, kind)


def _read_video(path: str) -> _Raw:
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
  return _Raw(grey, names, True, fps if fps and fps > 0 else None, 'video')


def _fps_beside(folder: str) -> float | None:
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
        return _positive_fps(meta, value)
    if os.path.isfile(txt):
      try:
        with open(txt, encoding='utf-8') as f:
          text = f.read(64).strip()
      except ValueError:
        text = '(not text)'
      return _positive_fps(txt, text)
  return None


def _positive_fps(where: str, value) -> float:
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


def resample_indices(n: int, source_fps: float, fps: float) -> np.ndarray:
  """Fractional source positions of the output frames at ``fps``.

  Output frame k is at time k / fps, i.e. source position k * source_fps / fps;
  frames run while that position stays within the n source frames.

  Returns:
    (T_out,) float64 positions in [0, n - 1].
  """
  ratio = source_fps / fps
  n_out = int(math.floor((n - 1) / ratio + 1e-9)) + 1
  return np.minimum(np.arange(n_out) * ratio, n - 1)


def resample_frames(
  frames: np.ndarray, pos: np.ndarray, interpolation: str
) -> np.ndarray:
  """Frames at fractional source positions ``pos`` (``resample_indices``):
  ``'nearest'`` or ``'linear'`` (where both neighbours are valid)."""
  nearest = np.minimum(np.floor(pos + 0.5 + 1e-9).astype(int), len(frames) - 1)
  if interpolation == 'nearest':
    return frames[nearest]
  i0 = np.floor(pos + 1e-9).astype(int)
  i1 = np.minimum(i0 + 1, len(frames) - 1)
  a = (pos - i0).astype(np.float32)[:, None, None]
  f0, f1 = frames[i0], frames[i1]
  both = (f0 > 0) & (f1 > 0)
  # Blending a depth with an invalid 0 would invent a surface: fall back to nearest.
  return np.where(both, (1 - a) * f0 + a * f1, frames[nearest]).astype(np.float32)


def resize_frames(frames: np.ndarray, size: tuple[int, int], method: str) -> np.ndarray:
  """(T, H, W) frames resized to ``size`` (H, W): ``'nearest'`` or
  ``'valid_area'`` (area average of the valid pixels)."""
  h, w = size
  if frames.shape[1:] == (h, w):
    return frames
  if method == 'nearest':
    return np.stack(
      [cv2.resize(f, (w, h), interpolation=cv2.INTER_NEAREST) for f in frames]
    )
  out = []
  for f in frames:
    valid = (f > 0).astype(np.float32)
    wsum = cv2.resize(valid, (w, h), interpolation=cv2.INTER_AREA)
    dsum = cv2.resize(f * valid, (w, h), interpolation=cv2.INTER_AREA)
    # Average only the valid pixels; mostly-invalid cells stay invalid.
    out.append(np.where(wsum >= 0.5, dsum / np.maximum(wsum, 1e-6), 0.0))
  return np.stack(out).astype(np.float32)


def _check_some_valid(path: str, frames: np.ndarray, names: list[str], why: str):
  empty = np.flatnonzero(~(frames > 0).any(axis=(1, 2)))
  if empty.size:
    raise ValueError(
      f'{path}: {names[empty[0]]} has no valid pixel{why} ({empty.size} such frame(s))'
    )


def load_depth_video(
  path: str,
  *,
  source_fps: float | None = None,
  fps: float | None = 20.0,
  size: tuple[int, int] | None = (256, 256),
  frames: int | None = None,
  depth_range: tuple[float, float] | None = None,
  interpolation: str = 'nearest',
  resize: str = 'nearest',
  depth_scale: float = 0.001,
  start: int = 0,
  pattern: str = '*.png',
) -> DepthVideo:
  """Loads, checks, masks, resamples in time and resizes a depth video.

  Args:
    path: a PNG folder, ``.npy``/``.npz`` file or video file (module docstring).
    source_fps: the recording's frame rate; overrides what the files say.
    fps: output frame rate (the simulations': 20 Hz); None keeps every frame.
    size: output (height, width) or None to keep. A 640x480 Xtion frame maps
      onto the simulated 256x256 camera (same 58x45 degree field of view) by a
      plain resize, without cropping.
    frames: keep the first this many output frames; fewer is an error.
    depth_range: (min, max) metres; depth outside becomes invalid (0). Needs
      absolute depth (not for normalised inputs).
    interpolation: time resampling, ``'nearest'`` (the source frame closest in
      time, ties to the later one) or ``'linear'`` (blend the two neighbours
      where both are valid, else nearest).
    resize: ``'nearest'`` (every output pixel is a real measurement) or
      ``'valid_area'`` (area average of valid pixels; invalid where under half
      the cell is valid).
    depth_scale: metres per unit of 16-bit PNGs (0.001: mm; TUM: 0.0002).
    start: source frames skipped at the beginning (before resampling).
    pattern: which files of a PNG folder are frames (a glob).

  Returns:
    ``DepthVideo``; ``depth`` is (T, H, W) float32.

  Raises:
    ValueError: naming the file: missing path, no frames, unreadable or corrupt
      PNG, frames differing in shape or dtype, NaN/inf/negative depth, depth
      that looks like millimetres, wrong array rank, an all-invalid frame,
      unknown source fps, too few frames, bad arguments.
  """
  if interpolation not in ('nearest', 'linear'):
    raise ValueError(
      f"interpolation must be 'nearest' or 'linear', got {interpolation!r}"
    )
  if resize not in ('nearest', 'valid_area'):
    raise ValueError(f"resize must be 'nearest' or 'valid_area', got {resize!r}")
  if fps is not None:
    fps = _positive_fps('fps argument', fps)
  if size is not None and (
    len(size) != 2 or not all(isinstance(s, int | np.integer) and s > 0 for s in size)
  ):
    raise ValueError(f'size must be two positive ints (height, width), got {size}')
  if frames is not None and frames < 1:
    raise ValueError(f'frames must be >= 1, got {frames}')
  if depth_range is not None:
    lo, hi = map(float, depth_range)
    if not (0 <= lo < hi):
      raise ValueError(f'depth_range must be 0 <= min < max metres, got {depth_range}')

  if not (math.isfinite(depth_scale) and 1e-6 <= depth_scale <= 1.0):
    raise ValueError(
      f'depth_scale must be metres per unit in [1e-6, 1], got {depth_scale}'
    )
  if start < 0:
    raise ValueError(f'start must be >= 0, got {start}')
  if os.path.isdir(path):
    raw = _read_png_folder(path, pattern, depth_scale, start)
    start = 0  # applied while reading
    beside = _fps_beside(path)
  elif os.path.isfile(path):
    ext = os.path.splitext(path)[1].lower()
    if ext in ('.npy', '.npz'):
      raw = _read_array(path)
    elif ext in VIDEO_EXTENSIONS:
      raw = _read_video(path)
    else:
      raise ValueError(
        f'{path}: unknown format {ext!r}; expected a PNG folder, .npy, .npz or '
        f'one of {VIDEO_EXTENSIONS}'
      )
    beside = _fps_beside(os.path.dirname(os.path.abspath(path)))
  elif os.path.lexists(path):
    input_files.check_regular(path, 'recording')  # a FIFO, socket or device
    raise ValueError(f'{path}: cannot be read')
  else:
    raise ValueError(f'{path}: no such file or folder')

  if start >= len(raw.frames):
    raise ValueError(f'{path}: start {start} but only {len(raw.frames)} frames')
  depth = raw.frames[start:]
  raw = raw._replace(names=raw.names[start:])
  _check_some_valid(path, depth, raw.names, '')
  if depth_range is not None:
    if raw.normalised:
      raise ValueError(
        f'{path}: depth_range needs absolute depth, but {raw.kind} frames are '
        'normalised per frame'
      )
    depth = np.where((depth >= lo) & (depth <= hi), depth, 0.0).astype(np.float32)
    _check_some_valid(path, depth, raw.names, f' inside depth_range {depth_range}')

  src = source_fps if source_fps is not None else beside or raw.fps
  if src is not None:
    src = _positive_fps(f'{path}: source fps', src)
  out_fps = src
  if fps is not None:
    if src is None:
      raise ValueError(
        f'{path}: source frame rate unknown; pass source_fps or put fps.txt / '
        'meta.json {"fps": ...} beside the frames'
      )
    pos = resample_indices(len(depth), src, fps)
    if len(pos) * depth[0].nbytes > MAX_BYTES:
      raise ValueError(
        f'{path}: {len(depth)} frames at {src:g} fps resampled to {fps:g} fps would '
        f'be {len(pos)} frames ({len(pos) * depth[0].nbytes / 2**30:.1f} GiB); is '
        'the source fps right?'
      )
    depth = resample_frames(depth, pos, interpolation)
    out_fps = fps
  if frames is not None:
    if len(depth) < frames:
      raise ValueError(
        f'{path}: only {len(depth)} frames at {out_fps} fps, {frames} requested'
      )
    depth = depth[:frames]
  if size is not None:
    depth = resize_frames(depth, tuple(int(s) for s in size), resize)
  return DepthVideo(
    np.ascontiguousarray(depth, np.float32),
    out_fps,
    raw.normalised,
    f'{raw.kind}:{os.path.abspath(path)}',
  )
