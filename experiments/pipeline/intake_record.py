"""The intake's settings and what it yields: ``IntakeConfig`` (how a
recording is read, cleaned and aligned, from the flags), ``Intake`` (the
recording taken in, in its own resolution and frame rate) and ``summary``,
the few lines a user checks before a search (``guess_note`` when up was a
guess). The steps themselves are ``experiments.pipeline.intake``'s.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

import physsim
from experiments.pipeline import cli
from physsim import camera_files

# How each source of up is named in the summary.
UP_WORDS = {
  'user': '--up', 'world_up': '--world_up', 'gravity': 'the camera file\'s "gravity"',
  'floor': 'the floor', 'cloth plane': 'the cloth plane', 'camera file': 'the camera file',
}  # fmt: skip


@dataclasses.dataclass(frozen=True)
class IntakeConfig:
  """How a recording is read, cleaned and aligned (``intake`` module docstring).

  Attributes:
    fps: the recording's frame rate, Hz; 0: from the camera file, meta.json
      or fps.txt beside the frames.
    start: source frames skipped at the beginning of the recording.
    depth_scale: metres per unit of 16-bit PNG frames (0.001: millimetres;
      0.0002: TUM's 5000 per metre).
    frame_glob: which files of a frame folder are frames (a glob; names must
      also hold a number).
    depth_range: (min, max) metres kept; empty: everything.
    mask: an image (non-zero where the cloth may be) or a folder of one per
      frame; empty: none.
    remove_planes: find and remove floor and wall planes.
    plane_tol: metres from a floor or wall plane that count as on it.
    pins: the two pinned top corners in the camera frame (OpenCV axes, x
      right, y down, z forward), x1,y1,z1,x2,y2,z2 metres; empty: fitted.
    up: the upward direction in the camera frame (OpenCV axes), x,y,z;
      empty: --world_up, else the camera file's "gravity", else a floor in
      view, else the cloth's plane (a guess: tilted as far as the wind
      swings the cloth in the first frames).
    world_up: which axis of the camera file's world points up (x, y, z, -x,
      -y, -z), for a file with "cam_to_world" (your rig's calibration); empty:
      not known.
    wind_toward_camera: the wind blows toward the camera (default: away).
    min_overlap: least IoU of the recording's cloth with the simulated
      cloth seen from the fitted pose, at rest or swung about its top edge
      (the best of 0-90 degrees, and of the first second's frames: a sheet
      the wind billows matches a rigid swing only now and then); below it
      the search is refused.
    depth_topic: a ROS bag's (or RealSense .bag's) depth image topic; empty:
      found by name (physsim.bags), the candidates listed when ambiguous.
    info_topic: the bag's CameraInfo topic of that depth stream; empty: found
      by name.
    imu_topic: the bag's IMU (accelerometer) topic, for gravity; empty: found
      by name.
    allow_no_camera: take in a recording without a camera file (no
      --camera_json): nothing can then be removed as background but by
      depth_range or mask, nor the camera placed, so training-like cameras
      are simulated; refused unless this is set.
  """

  fps: float = 0.0
  start: int = 0
  depth_scale: float = 0.001
  frame_glob: str = '*.png'
  depth_range: tuple[float, ...] = ()
  mask: str = ''
  remove_planes: bool = True
  plane_tol: float = 0.03
  pins: tuple[float, ...] = ()
  up: tuple[float, ...] = ()
  world_up: str = ''
  wind_toward_camera: bool = False
  min_overlap: float = 0.5
  depth_topic: str = ''
  info_topic: str = ''
  imu_topic: str = ''
  allow_no_camera: bool = False

  def check(self) -> None:
    """Raises ValueError naming the first bad field (every number finite
    first: ``cli.check_numbers``)."""
    cli.check_numbers(self)
    if not 1e-6 <= self.depth_scale <= 1.0:
      raise ValueError(
        f'--depth_scale={self.depth_scale}: must be metres per unit in [1e-6, 1]'
      )
    if self.fps and not 1 <= self.fps <= 1000:
      raise ValueError(
        f'fps must be 0 (from the files) or in [1, 1000] Hz, got {self.fps}'
      )
    if self.start < 0:
      raise ValueError(f'start must be >= 0, got {self.start}')
    if self.depth_range and (
      len(self.depth_range) != 2 or not 0 <= self.depth_range[0] < self.depth_range[1]
    ):
      raise ValueError(f'depth_range must be min,max metres, got {self.depth_range}')
    if self.pins and (len(self.pins) != 6 or not all(map(math.isfinite, self.pins))):
      raise ValueError(f'pins must be 6 numbers x1,y1,z1,x2,y2,z2, got {self.pins}')
    if self.up and (len(self.up) != 3 or not np.linalg.norm(self.up) > 0):
      raise ValueError(f'up must be 3 numbers x,y,z not all 0, got {self.up}')
    if self.world_up and self.world_up not in camera_files.WORLD_AXES:
      raise ValueError(
        f'--world_up={self.world_up}: must be one of '
        f'{", ".join(camera_files.WORLD_AXES)}'
      )
    if not 0 < self.plane_tol < 0.5 or not 0 <= self.min_overlap <= 1:
      raise ValueError(
        f'need 0 < plane_tol < 0.5 m and 0 <= min_overlap <= 1, got '
        f'{self.plane_tol}, {self.min_overlap}'
      )


class Intake(NamedTuple):
  """A recording taken in, in its own resolution and frame rate.

  Attributes:
    depth: (T, H, W) metres, background removed (0).
    fps: its frame rate.
    source_frames: (T,) index of each frame in the recording (after ``start``
      skipped none).
    intrinsics: its camera, or None (unknown: training-like cameras).
    pose: its camera's pose in the simulator's world, or None.
    pins_camera: (2, 3) the pins in the camera frame, left first, or None.
    up_from: where up came from ('user', 'world_up', 'gravity', 'floor',
      'cloth plane', 'camera file'; ``UP_WORDS``).
    valid_fraction: (T,) share of valid pixels before the background went.
    cloth_fraction: (T,) share of pixels kept as cloth.
    overlap: IoU of the recording's cloth with the simulated cloth at its
      best swing angle, in the best frame of the first second.
    planes: background planes removed, (normal, offset) in the camera frame.
    source: the recording's path.
    truth: ground truth when the recording carries it.
    camera_form: the camera file's form, or ''.
    passthrough: a dataset sequence, taken as it is.
    swing_deg: the swing angle of that best overlap.
    overlap_frame: the frame of that best overlap (the overlay shows it).
    silhouette: (H, W) bool, the simulated cloth at that angle, or None.
    camera_file: the camera file's path, or ''.
    warnings: what the user should check (sources of up that disagree).
    alignment_sd: (metres, degrees) the alignment's own error, 1 sd
      (``intake_alignment.alignment_error``); (0, 0) for a camera already in
      the simulator's world or none placed.
  """

  depth: np.ndarray
  fps: float
  source_frames: np.ndarray
  intrinsics: physsim.Intrinsics | None
  pose: physsim.Pose | None
  pins_camera: np.ndarray | None
  up_from: str
  valid_fraction: np.ndarray
  cloth_fraction: np.ndarray
  overlap: float | None
  planes: list
  source: str
  truth: dict | None
  camera_form: str
  passthrough: bool = False
  swing_deg: float | None = None
  silhouette: np.ndarray | None = None
  camera_file: str = ''
  warnings: tuple[str, ...] = ()
  alignment_sd: tuple[float, float] = (0.0, 0.0)
  overlap_frame: int = 0

  @property
  def up_is_guess(self) -> bool:
    """Up came from the cloth's own plane (no rig axis, IMU or floor)."""
    return self.up_from == 'cloth plane'


def summary(intake: Intake) -> str:
  """What was taken in, in a few lines, for the user to check before a search."""
  d = intake.depth[intake.depth > 0]
  t, h, w = intake.depth.shape
  lines = [
    f'recording {intake.source}: {t} frames at {intake.fps:g} fps, {w} x {h} px, '
    f'cloth depth {d.min():.2f}-{d.max():.2f} m',
    f'  valid pixels {100 * intake.valid_fraction.mean():.0f}%, kept as cloth '
    f'{100 * intake.cloth_fraction.min():.1f}-{100 * intake.cloth_fraction.max():.1f}% '
    f'per frame, {len(intake.planes)} background plane(s) removed',
  ]
  if intake.camera_form:
    lines.append(f'  camera: {intake.camera_form}')
  if intake.pins_camera is not None:
    p = intake.pins_camera
    spacing = np.linalg.norm(p[1] - p[0])
    lines.append(
      '  pins (camera frame, m): '
      + ', '.join('(' + ', '.join(f'{v:.3f}' for v in q) + ')' for q in p)
      + f'; {spacing:.3f} m apart; up from {UP_WORDS[intake.up_from]}'
    )
  if intake.pose is not None:
    c = np.asarray(intake.pose.position)
    lines.append(
      f"  camera in the simulator's world: ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) m"
      + (
        f', overlap with the simulated cloth IoU {intake.overlap:.2f}'
        if intake.overlap is not None
        else ''
      )
    )
  elif intake.intrinsics is None:
    lines.append('  camera unknown: training-like cameras will be simulated')
  if any(intake.alignment_sd):
    m, deg = intake.alignment_sd
    lines.append(
      f'  alignment error (estimated, 1 sd): {100 * m:.1f} cm, {deg:g} degrees'
    )
  if intake.up_is_guess:
    lines.append(f'  warning: {guess_note(intake)}')
  lines += [f'  warning: {w}' for w in intake.warnings]
  return '\n'.join(lines)


def guess_note(intake: Intake) -> str:
  """What a recording whose up is a guess says (summary, table, estimate.json)."""
  return (
    f"{intake.source}: up is a guess from the cloth's own plane (no floor in view, "
    'no --world_up, no "gravity" in the camera file); a cloth the wind swings in '
    'the first frames tilts it, and the answer with it. The posterior carries a '
    f'tilt of {intake.alignment_sd[1]:g} degrees (1 sd); give --world_up (your '
    'camera file\'s up axis) or "gravity" to remove the guess'
  )
