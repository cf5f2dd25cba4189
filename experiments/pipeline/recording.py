"""A recording to estimate from: depth (and colour) frames, its camera, its truth.

``load_recording`` reads any format ``physsim.video`` reads (16-bit PNG folders
in mm, ``.npy``/``.npz`` in metres, video files) and dataset sequence folders
(``meta.json`` beside ``cam0/``), which bring their own fps, camera and ground
truth.
"""

from __future__ import annotations

import concurrent.futures
import json
import os
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

import physsim
from experiments.pipeline import embedding
from physsim import camera_files, dataset, input_files, video


class Recording(NamedTuple):
  """A depth (and optionally colour) video to estimate from.

  Attributes:
    depth: (T, H, W) float32 metres, 0 invalid.
    fps: its frame rate after resampling.
    intrinsics: its camera's ``physsim.Intrinsics`` or None.
    pose: its camera's ``physsim.Pose`` (one camera) or None.
    source: where it came from.
    truth: ground-truth parameters when known (evaluation sets), else None.
    rgb: (T, H, W, 3) uint8 colour frames of the same times, or None.
  """

  depth: np.ndarray
  fps: float
  intrinsics: physsim.Intrinsics | None
  pose: physsim.Pose | None
  source: str
  truth: dict | None = None
  rgb: np.ndarray | None = None


def read_json(path: str) -> dict:
  """A JSON file's content; a missing or corrupt file, or one that is no
  regular file (a FIFO would block), is a ValueError naming it."""
  input_files.check_regular(path, 'JSON file')
  try:
    with open(path) as f:
      return json.load(f)
  except (OSError, ValueError) as e:
    raise ValueError(f'{path}: cannot read JSON ({e})') from e


def truth_of(meta: dict) -> dict | None:
  """The ground-truth parameters a ``meta.json`` holds, or None."""
  if 'wind_speed' not in meta:
    return None
  return {k: float(meta[k]) for k in ('bending_scale', 'wind_speed', 'area_weight')}


def _camera(cam: dict, where: str, size, *, required: bool):
  """(intrinsics resized to ``size``, camera-0 pose) of a camera dict in this
  project's form (``physsim.camera_files``), or Nones.

  A camera file must hold intrinsics; a ``meta.json`` without them means an
  unknown camera. Broken fields are a ValueError naming ``where``. Cameras in
  other forms (a user's world frame) go through the intake.
  """
  if not isinstance(cam, dict) or 'intrinsics' not in cam:
    if required:
      raise ValueError(
        f'{where}: no "intrinsics" (want {{"intrinsics", "extrinsics"}}; a '
        "camera in a tool's own form goes through experiments.pipeline.intake)"
      )
    return None, None
  found = camera_files.parse_camera(cam, where)
  return found.intrinsics.resized(size[1], size[0]), found.pose


def _load_rgb(path: str, meta: dict | None, fps: float, size, n: int) -> np.ndarray:
  """Camera 0's colour frames of a dataset sequence, resampled and resized like
  its depth: (n, H, W, 3) uint8."""
  if meta is None or not os.path.isdir(os.path.join(path, 'cam0')):
    raise ValueError(
      f'{path}: no RGB frames: colour frames are read from a dataset sequence '
      'folder (meta.json, cam0/rgb_*.png)'
    )
  if not meta.get('has_rgb'):
    raise ValueError(
      f'{path}: no RGB frames (meta.json has_rgb is not true, no cam0/rgb_*.png); '
      'an RGB network needs them (generate_dataset --rgb, make_eval_set)'
    )
  colour = dataset.read_sequence(path, cameras=[0], rgb=True).rgb[0]  # (T0, h, w, 3)
  pos = video.resample_indices(len(colour), float(meta['fps']), fps)
  # The nearest source frame, ties to the later one: load_depth_video's rule.
  nearest = np.minimum(np.floor(pos + 0.5 + 1e-9).astype(int), len(colour) - 1)
  return embedding.resize_rgb(colour[nearest[:n]], size)


def load_recording(
  path: str,
  *,
  fps: float,
  size: tuple[int, int],
  frames: int | None = None,
  camera_json: str | None = None,
  rgb: bool = False,
) -> Recording:
  """Loads a recording in any format ``physsim.video`` reads.

  A dataset sequence folder (``meta.json`` beside ``cam0/``) brings its own
  fps, camera (intrinsics and extrinsics of camera 0) and ground truth.
  ``camera_json`` (``{"intrinsics": ..., "extrinsics": ...}``, as in
  ``meta.json``) gives or overrides the camera of any other recording.

  Args:
    path: the recording.
    fps: frame rate to resample to.
    size: (H, W) to resize to (nearest neighbour).
    frames: keep at most this many frames.
    camera_json: optional camera file.
    rgb: also load camera 0's colour frames (a dataset sequence with
      ``cam0/rgb_*.png``), resampled and resized as training resizes them,
      for RGB networks.

  Raises:
    ValueError: a bad recording or camera file (or a camera file without
      intrinsics), or ``rgb`` asked of a recording without colour frames, named.
  """
  meta_path = os.path.join(path, 'meta.json')
  meta = read_json(meta_path) if os.path.isfile(meta_path) else None
  frames_path, source_fps = path, None
  if meta is not None and os.path.isdir(os.path.join(path, 'cam0')):
    frames_path, source_fps = os.path.join(path, 'cam0'), meta.get('fps')
  vid = video.load_depth_video(frames_path, source_fps=source_fps, fps=fps, size=size)
  if frames is not None:
    vid = vid._replace(depth=vid.depth[:frames])
  if vid.normalised:
    raise ValueError(
      f'{path}: normalised (8-bit) depth has no absolute scale; the estimate '
      'needs metric depth (16-bit mm PNG, .npy/.npz in metres)'
    )
  if camera_json:
    intr, pose = _camera(read_json(camera_json), camera_json, size, required=True)
  elif meta is not None:
    intr, pose = _camera(meta, meta_path, size, required=False)
  else:
    intr = pose = None
  truth = truth_of(meta) if meta is not None else None
  colour = _load_rgb(path, meta, fps, size, len(vid.depth)) if rgb else None
  if colour is not None and len(colour) != len(vid.depth):
    raise ValueError(
      f'{path}: {len(colour)} colour frames but {len(vid.depth)} depth frames'
    )
  return Recording(vid.depth, fps, intr, pose, path, truth, colour)


# Threads that read a study's recordings at once (``load_recordings``).
READERS = 8


def load_recordings(
  paths: Sequence[str], *, workers: int | None = None, **kw
) -> list[Recording]:
  """``load_recording(path, **kw)`` of every path, in order, read by
  ``workers`` threads (default ``READERS``, at most the cores): decoding a
  PNG frame releases Python's lock, and a study reads hundreds of recordings
  of dozens of frames each before its first simulation. The first path that
  fails raises, as one by one."""
  workers = max(1, min(workers or READERS, os.cpu_count() or 1, len(paths) or 1))
  if workers == 1:
    return [load_recording(p, **kw) for p in paths]
  with concurrent.futures.ThreadPoolExecutor(workers) as pool:
    return list(pool.map(lambda p: load_recording(p, **kw), paths))
