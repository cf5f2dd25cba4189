"""A user's recording read in: its frames (a frame folder, .npy/.npz, a bag),
its camera, the clip the search compares, and its background removed.

These are the intake's first steps (``experiments.pipeline.intake``), each a
function of its own that refuses, naming the file or setting, what would make
the estimate meaningless: no camera file (unless allowed), frames too small or
of another shape than the camera's, depth without a metric scale or a frame
rate, a recording much shorter than the compared clip, no cloth left once the
background is gone. A dataset sequence folder (``meta.json`` beside ``cam0/``)
without another camera file is this project's own simulation and passes
through as it is (``passthrough``).
"""

from __future__ import annotations

import math
import os

import cv2
import numpy as np

import physsim
from experiments.pipeline import cloth_view, simulation
from experiments.pipeline import recording as recording_lib
from experiments.pipeline.intake_record import Intake, IntakeConfig
from physsim import (
  alignment,
  bags,
  camera_files,
  input_files,
  scene,
  video,
  video_files,
)

# The smallest frames taken in, pixels (width, height): below it no camera
# resolves a cloth (and a few pixels a frame are a broken export).
MIN_SIZE = (32, 24)
# The least share of the compared clip a recording must cover (``check_clip``).
MIN_CLIP_SHARE = 0.5


def is_sequence(path: str) -> bool:
  """A dataset sequence folder (``meta.json`` beside ``cam0/``)."""
  return os.path.isfile(os.path.join(path, 'meta.json')) and os.path.isdir(
    os.path.join(path, 'cam0')
  )


def passthrough(path: str, sim: simulation.Simulation) -> Intake:
  """A dataset sequence taken as it is: camera 0's frames at the comparison's
  rate, size and length, its camera already in the simulator's world (no
  background to remove, nothing to align)."""
  first = video_files.frame_files(os.path.join(path, 'cam0'))
  shape = cv2.imread(os.path.join(path, 'cam0', first[0]), cv2.IMREAD_UNCHANGED).shape
  rec = recording_lib.load_recording(
    path, fps=sim.fps, size=tuple(shape[:2]), frames=sim.frames
  )
  pins_world, _ = cloth_view.simulated_pins(sim)
  pins = (
    alignment.pins_in_camera(rec.pose, pins_world) if rec.pose is not None else None
  )
  valid = (rec.depth > 0).reshape(len(rec.depth), -1).mean(axis=1)
  return Intake(
    rec.depth, rec.fps, np.arange(len(rec.depth)), rec.intrinsics, rec.pose, pins,
    'camera file', valid, valid, None, [], path, rec.truth, 'project', True,
  )  # fmt: skip


def read_bag(path: str, config: IntakeConfig) -> bags.BagRecording | None:
  """The depth stream (with its CameraInfo and IMU) of a ROS or RealSense bag
  at ``path``, or None for frame files; a ROS 2 bag folder without its
  metadata is refused (``bags.check_bag_folder``)."""
  bags.check_bag_folder(path)
  if not bags.is_bag(path):
    return None
  return bags.read_bag(
    path, depth_topic=config.depth_topic, info_topic=config.info_topic,
    imu_topic=config.imu_topic, start=config.start,
  )  # fmt: skip


def read_camera(
  path: str, camera_json: str, bag: bags.BagRecording | None, config: IntakeConfig
) -> camera_files.CameraFile | None:
  """The recording's camera: its camera file, else the bag's CameraInfo; the
  bag's IMU gives gravity to a camera without it. None only where
  ``allow_no_camera`` lets a recording in without one: without a camera no
  background plane can be removed nor the camera placed."""
  bag_camera = bag.camera if bag is not None else None
  if not camera_json and bag_camera is None and not config.allow_no_camera:
    raise ValueError(
      f'{path}: no camera file (--camera_json): without it no background can be '
      'removed but by depth_range or mask (a blank wall would pass as cloth) and '
      'the camera cannot be placed; give it, or pass --allow_no_camera to '
      'simulate training-like cameras anyway'
    )
  cam = camera_files.read_camera(camera_json) if camera_json else bag_camera
  if cam is not None and bag is not None and bag.gravity is not None:
    if cam.gravity is None:
      cam = cam._replace(gravity=bag.gravity)
  return cam


def read_video(
  path: str,
  config: IntakeConfig,
  cam: camera_files.CameraFile | None,
  bag: bags.BagRecording | None,
) -> tuple[video.DepthVideo, dict | None]:
  """(the recording's depth in metres at its own frame rate, the ground truth
  a dataset sequence carries, else None): a bag's stream, a sequence's camera
  0 or the frame files, their size checked from the headers before any frame
  is decoded; refused when the depth has no metric scale or no frame rate."""
  frames_path = os.path.join(path, 'cam0') if is_sequence(path) else path
  if bag is None:  # frame files: their size from the headers, before decoding
    header = video_files.read_header(frames_path, config.frame_glob, config.start)
    if header is not None:
      check_size(path, header.width, header.height, cam)
  src_fps = config.fps or (cam.fps if cam else None) or (bag.fps if bag else None)
  truth = None
  if is_sequence(path):  # a dataset sequence with another camera file: camera 0
    truth = recording_lib.truth_of(
      recording_lib.read_json(os.path.join(path, 'meta.json'))
    )
  if bag is not None:
    vid = video.DepthVideo(bag.depth, src_fps, False, f'bag:{os.path.abspath(path)}')
  else:
    vid = video.load_depth_video(
      frames_path, source_fps=src_fps, fps=None, size=None,
      depth_scale=config.depth_scale, start=config.start, pattern=config.frame_glob,
    )  # fmt: skip
  if vid.normalised:
    raise ValueError(
      f'{path}: normalised (8-bit) depth has no absolute scale; the estimate '
      'needs metric depth (16-bit PNG, .npy/.npz in metres)'
    )
  if vid.fps is None:
    raise ValueError(
      f'{path}: frame rate unknown; give --fps, "fps" in the camera file, or '
      'fps.txt beside the frames'
    )
  return vid, truth


def compared_clip(
  path: str,
  vid: video.DepthVideo,
  cam: camera_files.CameraFile | None,
  sim: simulation.Simulation,
) -> tuple[np.ndarray, np.ndarray, camera_files.CameraFile | None]:
  """(index of the recording's frames that cover the compared clip, those
  frames, the camera scaled to them): the frames' lens distortion undone, so
  that every later step sees a pinhole camera."""
  pos = video.resample_indices(len(vid.depth), vid.fps, sim.fps)[: sim.frames]
  check_clip(path, len(pos), sim)
  index = np.arange(int(math.floor(pos[-1] + 0.5 + 1e-9)) + 1)
  depth = vid.depth[index]
  h, w = depth.shape[1:]
  check_size(path, w, h, cam)
  if cam is not None:
    cam = camera_files.scaled_to(cam, w, h)
    if cam.distorted:
      depth = camera_files.undistort(depth, cam)
  return index, depth, cam


def without_background(
  path: str,
  depth: np.ndarray,
  intr: physsim.Intrinsics | None,
  index: np.ndarray,
  config: IntakeConfig,
) -> scene.Background:
  """``depth`` (the frames ``index`` after ``start``) with all but the cloth
  removed (``scene.remove_background``: the depth range, the mask, floor and
  wall planes where the camera is known, all but the largest region); refused
  when a frame has no cloth left."""
  h, w = depth.shape[1:]
  mask = read_mask(config.mask, index + config.start, (h, w)) if config.mask else None
  bg = scene.remove_background(
    depth,
    intr or physsim.Intrinsics(width=w, height=h),
    depth_range=tuple(config.depth_range) or None,
    mask=mask,
    planes=config.remove_planes and intr is not None,
    plane_tol=config.plane_tol,
  )
  empty = np.flatnonzero(bg.fraction == 0)
  if empty.size:
    raise ValueError(
      f'{path}: no cloth left in frame {int(index[empty[0]]) + config.start} after '
      'background removal; check depth_range, mask and plane_tol'
    )
  return bg


def check_clip(path: str, frames: int, sim: simulation.Simulation) -> None:
  """Refuses a recording much shorter than the clip the search compares:
  ``frames`` at the simulation's rate against ``sim.frames``. A shorter one
  sets how many frames are simulated (``Simulation.frames``), down to
  ``MIN_CLIP_SHARE`` of them; below, a few frames would pass for the clip.

  Raises:
    ValueError: naming the recording and both lengths.
  """
  if frames < MIN_CLIP_SHARE * sim.frames:
    raise ValueError(
      f'{path}: {frames} frames at {sim.fps:g} fps ({frames / sim.fps:.2f} s), but '
      f'the search compares a clip of {sim.frames} frames ({sim.frames / sim.fps:.2f}'
      f' s; at least {MIN_CLIP_SHARE:.0%} of it needed); record longer, or shorten '
      'the clip (--frames)'
    )


def check_size(path: str, w: int, h: int, cam) -> None:
  """Frames big enough to hold a cloth, and of the camera file's shape."""
  if w < MIN_SIZE[0] or h < MIN_SIZE[1]:
    raise ValueError(
      f'{path}: frames of {w} x {h} px; the intake needs at least '
      f'{MIN_SIZE[0]} x {MIN_SIZE[1]} (a broken export?)'
    )
  if cam is not None:
    camera_files.scaled_to(cam, w, h)


def read_mask(path: str, index: np.ndarray, shape) -> np.ndarray:
  """(T, H, W) bool of a mask image or folder (one per recording frame)."""
  if os.path.isdir(path):
    names = video_files.frame_files(path)
    if not names:
      raise ValueError(f'{path}: no mask images (PNG files with a number in the name)')
    if index.max() >= len(names):
      raise ValueError(
        f'{path}: {len(names)} masks but frame {index.max()} of the recording is used'
      )
    picked = [os.path.join(path, names[i]) for i in index]
  else:
    input_files.check_regular(path, 'mask image')
    picked = [path] * len(index)
  out = []
  for file in picked:
    m = cv2.imread(file, cv2.IMREAD_GRAYSCALE)
    if m is None:
      raise ValueError(f'{file}: not a readable mask image')
    if m.shape != tuple(shape):
      raise ValueError(
        f'{file}: mask is {m.shape[::-1]} (w x h), frames are {shape[::-1]}'
      )
    out.append(m > 0)
  return np.stack(out)
