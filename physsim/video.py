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

Which files are frames and what their headers say is ``physsim.video_files``;
decoding each format, ``physsim.video_formats``. Here the decoded frames are
masked, resampled in time and resized as the simulations' cameras see them.
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import cv2
import numpy as np

from physsim import input_files, video_formats
from physsim.video_files import MAX_BYTES, fps_beside, positive_fps


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
  """Raises naming the first of ``frames`` without a valid pixel: nothing to
  compare a simulation with."""
  empty = np.flatnonzero(~(frames > 0).any(axis=(1, 2)))
  if empty.size:
    raise ValueError(
      f'{path}: {names[empty[0]]} has no valid pixel{why} ({empty.size} such frame(s))'
    )


def _check_arguments(
  interpolation: str,
  resize: str,
  fps: float | None,
  size: tuple[int, int] | None,
  frames: int | None,
  depth_range: tuple[float, float] | None,
  depth_scale: float,
  start: int,
) -> float | None:
  """``load_depth_video``'s arguments checked before any file is opened;
  returns ``fps`` as a float (or None).

  Raises:
    ValueError: naming the argument and the values it takes.
  """
  if interpolation not in ('nearest', 'linear'):
    raise ValueError(
      f"interpolation must be 'nearest' or 'linear', got {interpolation!r}"
    )
  if resize not in ('nearest', 'valid_area'):
    raise ValueError(f"resize must be 'nearest' or 'valid_area', got {resize!r}")
  if fps is not None:
    fps = positive_fps('fps argument', fps)
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
  return fps


def _read_source(
  path: str, pattern: str, depth_scale: float, start: int
) -> tuple[video_formats.Raw, float | None]:
  """The recording's frames from the ``start``-th on, decoded by the reader
  of the format ``path`` holds, and the frame rate written beside them
  (``fps_beside``: None if none is).

  Raises:
    ValueError: naming the path: missing, not a regular file or folder, of
      an unknown format, or with no more than ``start`` frames.
  """
  if os.path.isdir(path):
    raw = video_formats.read_png_folder(path, pattern, depth_scale, start)
    start = 0  # applied while reading
    beside = fps_beside(path)
  elif os.path.isfile(path):
    ext = os.path.splitext(path)[1].lower()
    if ext in ('.npy', '.npz'):
      raw = video_formats.read_array(path)
    elif ext in video_formats.VIDEO_EXTENSIONS:
      raw = video_formats.read_video(path)
    else:
      raise ValueError(
        f'{path}: unknown format {ext!r}; expected a PNG folder, .npy, .npz or '
        f'one of {video_formats.VIDEO_EXTENSIONS}'
      )
    beside = fps_beside(os.path.dirname(os.path.abspath(path)))
  elif os.path.lexists(path):
    input_files.check_regular(path, 'recording')  # a FIFO, socket or device
    raise ValueError(f'{path}: cannot be read')
  else:
    raise ValueError(f'{path}: no such file or folder')

  if start >= len(raw.frames):
    raise ValueError(f'{path}: start {start} but only {len(raw.frames)} frames')
  return raw._replace(frames=raw.frames[start:], names=raw.names[start:]), beside


def _masked(
  path: str, raw: video_formats.Raw, depth_range: tuple[float, float] | None
) -> np.ndarray:
  """The frames with depth outside ``depth_range`` (metres) made invalid
  (0); every frame must keep a valid pixel, before the mask and after it.

  Raises:
    ValueError: naming the path and the first frame left without one, or a
      range asked of normalised frames.
  """
  depth = raw.frames
  _check_some_valid(path, depth, raw.names, '')
  if depth_range is None:
    return depth
  if raw.normalised:
    raise ValueError(
      f'{path}: depth_range needs absolute depth, but {raw.kind} frames are '
      'normalised per frame'
    )
  lo, hi = map(float, depth_range)
  depth = np.where((depth >= lo) & (depth <= hi), depth, 0.0).astype(np.float32)
  _check_some_valid(path, depth, raw.names, f' inside depth_range {depth_range}')
  return depth


def _resampled(
  path: str,
  depth: np.ndarray,
  source_fps: float | None,
  fps: float | None,
  interpolation: str,
) -> tuple[np.ndarray, float | None]:
  """The frames recorded at ``source_fps`` resampled to ``fps`` (None: kept
  as recorded), and their frame rate.

  Raises:
    ValueError: naming the path: the source frame rate unknown, or one that
      would expand the frames past ``MAX_BYTES``.
  """
  if fps is None:
    return depth, source_fps
  if source_fps is None:
    raise ValueError(
      f'{path}: source frame rate unknown; pass source_fps or put fps.txt / '
      'meta.json {"fps": ...} beside the frames'
    )
  pos = resample_indices(len(depth), source_fps, fps)
  if len(pos) * depth[0].nbytes > MAX_BYTES:
    raise ValueError(
      f'{path}: {len(depth)} frames at {source_fps:g} fps resampled to {fps:g} fps '
      f'would be {len(pos)} frames ({len(pos) * depth[0].nbytes / 2**30:.1f} GiB); '
      'is the source fps right?'
    )
  return resample_frames(depth, pos, interpolation), fps


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
  fps = _check_arguments(
    interpolation, resize, fps, size, frames, depth_range, depth_scale, start
  )
  raw, beside = _read_source(path, pattern, depth_scale, start)
  depth = _masked(path, raw, depth_range)
  src = source_fps if source_fps is not None else beside or raw.fps
  if src is not None:
    src = positive_fps(f'{path}: source fps', src)
  depth, out_fps = _resampled(path, depth, src, fps, interpolation)
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
