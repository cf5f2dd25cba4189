"""A user's recording in: its camera, its clip, its background, its cloth.

``take_in`` turns a depth recording as a camera wrote it into what the search
compares against simulations, in the recording's own terms (resolution, frame
rate), and checks it before any simulation runs:

1. **camera**: any form ``physsim.camera_files`` reads (OpenCV JSON, ROS
   CameraInfo YAML, RealSense/Open3D intrinsics, this project's); lens
   distortion is undone with OpenCV; the file's ``fps`` is the recording's
   frame rate unless ``--fps`` says otherwise;
2. **clip**: frames from ``start`` covering the compared duration (``frames``
   at the comparison rate), their unit from ``depth_scale``;
3. **background** (``physsim.scene``): ``depth_range``, a mask image or
   folder, floor and wall planes, and all but the largest region removed;
   the kept cloth share of each frame reported;
4. **alignment** (``physsim.alignment``): the pins given by the user or
   fitted, up from a floor (else the cloth plane), and from them the camera's
   pose in the simulator's world. A camera file in this project's own form
   (a simulated recording) already has that pose and is not refitted;
5. **checks**: the pins as far apart as the simulated cloth's (within 20%),
   the cloth in view from the pose, and the simulated cloth's silhouette
   overlapping the recording's (IoU >= ``min_overlap``); else it refuses,
   after writing the overlay that shows why.

A dataset sequence folder (``meta.json`` beside ``cam0/``) is this project's
own simulation: it has no background and its camera is in the simulator's
world, so it passes through unchanged.

``write`` saves ``intake.json``, ``overlay.png`` and the cleaned frames
(``intake/NNNN.png``, 16-bit mm, own resolution); ``to_recording`` resamples
the cleaned frames to the comparison's rate and the network's image size.
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import tempfile
from typing import NamedTuple

import cv2
import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline import cli, files, simulation
from experiments.pipeline import recording as recording_lib
from physsim import alignment, bags, camera_files, dataset, input_files, scene, video

# Pin spacing may differ from the simulated cloth's by this share.
PIN_SPACING_TOL = 0.2
# Two sources of up (--up, --world_up, gravity, a floor) that differ by more
# than this many degrees are reported.
UP_CROSS_CHECK_DEG = 3.0
# How each source of up is named in the summary.
UP_WORDS = {
  'user': '--up', 'world_up': '--world_up', 'gravity': 'the camera file\'s "gravity"',
  'floor': 'the floor', 'cloth plane': 'the cloth plane', 'camera file': 'the camera file',
}  # fmt: skip
# The alignment's own error (1 sd of a tilt, degrees) by where up came from:
# a given up (the rig's world, an IMU) is good to about a degree, a floor's
# normal to two; the cloth's plane is a guess that a cloth swung by the wind
# in the first frames tilts by the swing (the most EstimateConfig allows).
UP_SD_DEG = {
  'user': 1.0, 'world_up': 1.0, 'gravity': 1.0, 'floor': 2.0, 'cloth plane': 20.0,
  'camera file': 0.0,
}  # fmt: skip
# Its shift (1 sd, metres): at least this, or two pixels at the pins' depth.
MIN_SD_M = 0.01
# Least share of the simulated cloth's vertices in view from the pose.
MIN_VISIBLE = 0.5
# ... and the fewest pixels it may cover (a camera 100 m away sees a speck).
MIN_PIXELS = 100
# The smallest frames taken in, pixels (width, height): below it no camera
# resolves a cloth (and a few pixels a frame are a broken export).
MIN_SIZE = (32, 24)
INTAKE_FILE = 'intake.json'
OVERLAY_FILE = 'overlay.png'
FRAMES_DIR = 'intake'


@dataclasses.dataclass(frozen=True)
class IntakeConfig:
  """How a recording is read, cleaned and aligned (module docstring).

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
      (``alignment_error``); (0, 0) for a camera already in the simulator's
      world or none placed.
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


def is_sequence(path: str) -> bool:
  """A dataset sequence folder (``meta.json`` beside ``cam0/``)."""
  return os.path.isfile(os.path.join(path, 'meta.json')) and os.path.isdir(
    os.path.join(path, 'cam0')
  )


def _mask(path: str, index: np.ndarray, shape) -> np.ndarray:
  """(T, H, W) bool of a mask image or folder (one per recording frame)."""
  if os.path.isdir(path):
    names = video.frame_files(path)
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


def simulated_pins(sim: simulation.Simulation) -> tuple[np.ndarray, physsim.Mesh]:
  """((2, 3) the simulated cloth's outer pins, left first; its rest mesh) for
  an estimate's ``Simulation``."""
  mesh = simulation.mesh(sim)
  return outer_pins(mesh), mesh


def outer_pins(mesh) -> np.ndarray:
  """(2, 3) the outermost pinned vertices of ``mesh``, left (-x) first."""
  pinned = mesh.vertices[mesh.pinned]
  return pinned[np.argsort(pinned[:, 0])[[0, -1]]].astype(np.float64)


SWINGS_DEG = tuple(range(0, 91, 10))
# The least share of the compared clip a recording must cover (``check_clip``).
MIN_CLIP_SHARE = 0.5


def swung(vertices: np.ndarray, pins_world: np.ndarray, deg: float) -> np.ndarray:
  """Rest vertices turned by ``deg`` about the pins' line, downwind (+y)."""
  a = np.deg2rad(deg)
  rel = vertices - pins_world.mean(axis=0)
  y = rel[:, 1] * np.cos(a) - rel[:, 2] * np.sin(a)
  z = rel[:, 1] * np.sin(a) + rel[:, 2] * np.cos(a)
  return np.stack([rel[:, 0], y, z], axis=1) + pins_world.mean(axis=0)


def silhouettes(mesh, pins_world, intr, pose, degs=SWINGS_DEG) -> np.ndarray:
  """(len(degs), H, W) bool: the simulated cloth swung by each angle, seen
  by the camera."""
  render = physsim.make_depth_renderer(mesh.faces, intr)
  positions = np.stack([swung(mesh.vertices, pins_world, d) for d in degs])
  poses = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32)[None, None], pose)
  out = render(jnp.asarray(positions, jnp.float32)[None], poses)  # (1, 1, S, H, W)
  return np.asarray(out)[0, 0] > 0


def _passthrough(path: str, sim: simulation.Simulation) -> Intake:
  first = video.frame_files(os.path.join(path, 'cam0'))
  shape = cv2.imread(os.path.join(path, 'cam0', first[0]), cv2.IMREAD_UNCHANGED).shape
  rec = recording_lib.load_recording(
    path, fps=sim.fps, size=tuple(shape[:2]), frames=sim.frames
  )
  pins_world, _ = simulated_pins(sim)
  pins = (
    alignment.pins_in_camera(rec.pose, pins_world) if rec.pose is not None else None
  )
  valid = (rec.depth > 0).reshape(len(rec.depth), -1).mean(axis=1)
  return Intake(
    rec.depth, rec.fps, np.arange(len(rec.depth)), rec.intrinsics, rec.pose, pins,
    'camera file', valid, valid, None, [], path, rec.truth, 'project', True,
  )  # fmt: skip


def take_in(
  path: str,
  config: IntakeConfig,
  camera_json: str,
  sim: simulation.Simulation,
  *,
  workdir: str | None = None,
) -> Intake:
  """Reads, cleans, aligns and checks a recording (module docstring).

  Args:
    path: the recording (a frame folder, .npy/.npz, or a dataset sequence).
    config: the intake settings.
    camera_json: its camera file ('' for none).
    sim: the estimate's ``Simulation`` (comparison rate and length, cloth).
    workdir: where a refused alignment writes its overlay, or None.

  Raises:
    ValueError: naming the file or setting, for anything that would make the
      estimate meaningless.
  """
  config.check()
  if is_sequence(path) and not camera_json:
    return _passthrough(path, sim)
  bag = None
  bags.check_bag_folder(path)
  if bags.is_bag(path):
    bag = bags.read_bag(
      path, depth_topic=config.depth_topic, info_topic=config.info_topic,
      imu_topic=config.imu_topic, start=config.start,
    )  # fmt: skip
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
  frames_path = os.path.join(path, 'cam0') if is_sequence(path) else path
  header = (
    None if bag else video.read_header(frames_path, config.frame_glob, config.start)
  )
  if header is not None:
    _check_size(path, header.width, header.height, cam)
  src_fps = config.fps or (cam.fps if cam else None) or (bag.fps if bag else None)
  frames_path, truth = path, None
  if is_sequence(path):  # a dataset sequence with another camera file: camera 0
    frames_path = os.path.join(path, 'cam0')
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
  # The recording's frames that cover the compared clip.
  pos = video.resample_indices(len(vid.depth), vid.fps, sim.fps)[: sim.frames]
  check_clip(path, len(pos), sim)
  index = np.arange(int(math.floor(pos[-1] + 0.5 + 1e-9)) + 1)
  depth = vid.depth[index]
  h, w = depth.shape[1:]
  _check_size(path, w, h, cam)
  intr = None
  if cam is not None:
    cam = camera_files.scaled_to(cam, w, h)
    intr = cam.intrinsics
    if cam.distorted:
      depth = camera_files.undistort(depth, cam)
  valid = (depth > 0).reshape(len(depth), -1).mean(axis=1)
  mask = _mask(config.mask, index + config.start, (h, w)) if config.mask else None
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
  planes = [(p.normal.tolist(), p.offset) for p in bg.planes]
  intake = Intake(
    bg.depth, vid.fps, index + config.start, intr, None, None, '', valid,
    bg.fraction, None, planes, path, truth, cam.form if cam else '',
    camera_file=camera_json, warnings=bag.notes if bag is not None else (),
  )  # fmt: skip
  if cam is None:
    return intake
  return _align(intake, cam, config, sim, bg.planes, workdir)


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


def given_ups(cam: camera_files.CameraFile, config: IntakeConfig) -> list:
  """[(source, (3,) up in the camera frame)] of the ups the user gave, most
  trusted first: --up, --world_up (through the file's cam_to_world), the
  file's "gravity"."""
  out = []
  if config.up:
    out.append(('user', np.asarray(config.up, np.float64)))
  if config.world_up:
    out.append(('world_up', cam.world_up(config.world_up)))
  if cam.gravity is not None:
    out.append(('gravity', -np.asarray(cam.gravity, np.float64)))
  return out


def cross_check(given: list, fit: alignment.ClothFit) -> tuple[str, ...]:
  """A warning for each pair of sources of up (those given, and a floor in
  view) more than ``UP_CROSS_CHECK_DEG`` apart."""
  sources = list(given)
  if fit.floor_up is not None:
    sources.append(('floor', fit.floor_up))
  out = []
  for i, (a, va) in enumerate(sources):
    for b, vb in sources[i + 1 :]:
      angle = alignment.angle_deg(va, vb)
      if angle > UP_CROSS_CHECK_DEG:
        out.append(
          f'up from {UP_WORDS[a]} and from {UP_WORDS[b]} differ by {angle:.1f} '
          f'degrees (more than {UP_CROSS_CHECK_DEG:g}); {UP_WORDS[fit.up_from]} was '
          'used: check them'
        )
  return tuple(out)


def alignment_error(
  fit, pins, want_spacing: float, intr, warnings, scatter: float = 0.0
) -> tuple:
  """(metres, degrees): the alignment's own error, 1 sd, for the estimate's
  ``camera_sd_m``/``camera_sd_deg``: a tilt by where up came from
  (``UP_SD_DEG``), at least as large as any disagreement between its sources;
  a shift of two pixels at the pins' depth, at least ``MIN_SD_M``, or half the
  pins' spacing error if larger. ``scatter`` (``alignment.track_pins``: how
  far the fitted pins move over the recording) is a shift of its own and turns
  the pins' line by its angle across their spacing."""
  deg = UP_SD_DEG[fit.up_from]
  deg = max(deg, float(np.degrees(np.arctan2(scatter, want_spacing))))
  if fit.floor_up is not None and fit.up_from not in ('floor', 'cloth plane'):
    deg = max(deg, alignment.angle_deg(fit.up, fit.floor_up))
  if warnings:  # sources of up more than UP_CROSS_CHECK_DEG apart
    deg = max(deg, 2 * UP_CROSS_CHECK_DEG)
  depth = float(np.mean(pins[:, 2]))
  spacing = float(np.linalg.norm(pins[1] - pins[0]))
  m = max(MIN_SD_M, 2 * depth / intr.fx, 0.5 * abs(spacing - want_spacing), scatter)
  return (round(min(m, 0.2), 4), round(min(deg, 20.0), 2))


def _check_size(path: str, w: int, h: int, cam) -> None:
  """Frames big enough to hold a cloth, and of the camera file's shape."""
  if w < MIN_SIZE[0] or h < MIN_SIZE[1]:
    raise ValueError(
      f'{path}: frames of {w} x {h} px; the intake needs at least '
      f'{MIN_SIZE[0]} x {MIN_SIZE[1]} (a broken export?)'
    )
  if cam is not None:
    camera_files.scaled_to(cam, w, h)


def _align(
  intake: Intake, cam, config: IntakeConfig, sim: simulation.Simulation, planes, workdir
) -> Intake:
  pins_world, mesh = simulated_pins(sim)
  intr = intake.intrinsics
  if config.pins or cam.world == 'user' or cam.pose is None:
    if sim.garment and not config.pins:
      raise ValueError(
        'a garment cannot be found by the square-cloth fit; give --pins (the two '
        'pinned corners in the camera frame)'
      )
    user = np.asarray(config.pins, np.float64).reshape(2, 3) if config.pins else None
    given = given_ups(cam, config)
    fit = alignment.fit_pins(
      intake.depth, intr, pins=user, background=planes, plane_tol=config.plane_tol,
      up=given[0][1] if given else None, up_from=given[0][0] if given else 'user',
      spacing=float(np.linalg.norm(pins_world[1] - pins_world[0])),
    )  # fmt: skip
    warnings = cross_check(given, fit)
    found, scatter = fit.pins, 0.0
    if not config.pins:  # the whole recording's most upwind fit, and its spread
      track = alignment.track_pins(
        intake.depth, intr, fit.pins, fit.up, wind_toward_camera=config.wind_toward_camera,
        spacing=float(np.linalg.norm(pins_world[1] - pins_world[0])),
      )  # fmt: skip
      found, scatter = track.pins, track.scatter
    pose, pins = alignment.camera_pose(
      found, fit.up, pins_world, wind_toward_camera=config.wind_toward_camera
    )
    spacing = float(np.linalg.norm(pins[1] - pins[0]))
    want = float(np.linalg.norm(pins_world[1] - pins_world[0]))
    if abs(spacing / want - 1) > PIN_SPACING_TOL:
      raise ValueError(
        f'{intake.source}: the pins are {spacing:.3f} m apart but the simulated '
        f"cloth's are {want:.3f} m; check the camera file's intrinsics, the "
        'depth_scale and --pins'
        + ('' if sim.garment else f', or give the cloth\'s side as --cloth_size '
           f'(now {sim.cloth_size:g} m)')
      )  # fmt: skip
    up_from = fit.up_from
    sd = alignment_error(fit, pins, want, intr, warnings, scatter)
  else:
    pose, up_from, warnings, sd = cam.pose, 'camera file', (), (0.0, 0.0)
    pins = alignment.pins_in_camera(pose, pins_world)
  seen = alignment.visible_share(mesh.vertices, pose, intr)
  sims = silhouettes(mesh, pins_world, intr, pose)  # at rest first, then swung
  area = int(sims[0].sum())
  if seen < MIN_VISIBLE or area < MIN_PIXELS:
    raise ValueError(
      f'{cam.path}: from this camera {100 * seen:.0f}% of the simulated cloth is in '
      f'view, covering {area} pixels; check the camera pose (cam_to_world) or --pins'
    )
  first_second = intake.depth[: max(1, int(round(intake.fps)))] > 0
  ious = np.array([[alignment.iou(f, sim) for sim in sims] for f in first_second])
  frame, best = np.unravel_index(int(np.argmax(ious)), ious.shape)
  overlap = float(ious[frame, best])
  out = intake._replace(
    pose=pose, pins_camera=pins, up_from=up_from, overlap=overlap,
    swing_deg=float(SWINGS_DEG[best]), silhouette=sims[best],
    overlap_frame=int(frame),
    warnings=intake.warnings + tuple(warnings),
    alignment_sd=sd,
  )  # fmt: skip
  if overlap < config.min_overlap:
    where = ''
    if workdir:
      write(out, workdir, sim, frames=False)
      where = f'; see {os.path.join(workdir, OVERLAY_FILE)}'
    guess = ''
    if out.up_is_guess:
      guess = (
        "; up was a guess from the cloth's own plane: --world_up=AXIS (the camera "
        'file\'s world axis that points up), "gravity" in the camera file or --up '
        'places the camera without it'
      )
    raise ValueError(
      f'{intake.source}: the simulated cloth at the fitted pose overlaps the '
      f"recording's by IoU {overlap:.2f} < min_overlap {config.min_overlap}{where}"
      f'{guess}'
    )
  return out


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


def to_json(intake: Intake) -> dict:
  """``intake.json``'s content."""
  pose = physsim.pose_to_dict(intake.pose) if intake.pose is not None else None
  pins = intake.pins_camera.tolist() if intake.pins_camera is not None else None
  return {
    'source': os.path.abspath(intake.source),
    'fps': intake.fps,
    'frames': int(len(intake.depth)),
    'source_frames': intake.source_frames.tolist(),
    'resolution': [int(intake.depth.shape[2]), int(intake.depth.shape[1])],
    'pins_camera': pins,
    'up_from': intake.up_from,
    'camera_form': intake.camera_form,
    'camera_file': os.path.abspath(intake.camera_file) if intake.camera_file else '',
    'intrinsics': intake.intrinsics.to_dict() if intake.intrinsics else None,
    'pose_in_simulator': pose,
    'valid_fraction': intake.valid_fraction.tolist(),
    'cloth_fraction': intake.cloth_fraction.tolist(),
    'overlap_iou': intake.overlap,
    'swing_deg': intake.swing_deg,
    'overlap_frame': intake.overlap_frame,
    'background_planes': [{'normal': n, 'offset': o} for n, o in intake.planes],
    'warnings': list(intake.warnings),
    'alignment_sd': {'m': intake.alignment_sd[0], 'deg': intake.alignment_sd[1]},
    'up_is_guess': intake.up_is_guess,
  }


def overlay(intake: Intake, mesh) -> np.ndarray:
  """BGR picture: the depth of the frame that best matched the simulated
  cloth (``overlap_frame``; grey, removed background dark blue) with the
  simulated cloth's outline (red) and the pins (green), over a legend that
  says so (``with_legend``)."""
  first = intake.depth[min(intake.overlap_frame, len(intake.depth) - 1)]
  valid = first > 0
  img = np.zeros(first.shape + (3,), np.uint8)
  if valid.any():
    lo, hi = np.quantile(first[valid], [0.02, 0.98])
    grey = np.clip(255 * (1 - (first - lo) / max(hi - lo, 1e-6)), 40, 255).astype(
      np.uint8
    )
    img[valid] = grey[valid, None]
  img[~valid] = (60, 20, 0)
  scale = max(1, 480 // max(first.shape))
  img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
  sim = intake.silhouette
  if sim is None and intake.pose is not None and intake.intrinsics is not None:
    sim = silhouettes(mesh, outer_pins(mesh), intake.intrinsics, intake.pose, (0.0,))[0]
  if sim is not None:
    sim = sim.astype(np.uint8)
    sim = cv2.resize(sim, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    contours, _ = cv2.findContours(sim, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, (0, 0, 255), 1)
  if intake.pins_camera is not None and intake.intrinsics is not None:
    k = intake.intrinsics.matrix()
    for p in intake.pins_camera:
      u, v, z = k @ p
      if z > 0:
        centre = (int(round((u / z + 0.5) * scale)), int(round((v / z + 0.5) * scale)))
        cv2.circle(img, centre, max(3, scale), (0, 255, 0), 2)
  return with_legend(img)


# What the overlay's colours mean (BGR), drawn under the picture.
LEGEND = (
  ((0, 0, 255), 'simulated cloth outline'),
  ((0, 255, 0), 'pins found'),
  ((200, 200, 200), 'depth (near: light)'),
  ((60, 20, 0), 'background removed'),
)


def with_legend(img: np.ndarray) -> np.ndarray:
  """``img`` (BGR) over a band that names each colour of ``LEGEND``."""
  row = 18
  band = np.full((row * len(LEGEND) + 6, img.shape[1], 3), 255, np.uint8)
  for k, (colour, text) in enumerate(LEGEND):
    y = 4 + k * row
    band[y + 2 : y + row - 4, 4:18] = colour
    cv2.putText(band, text, (24, y + row - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                (0, 0, 0), 1, cv2.LINE_AA)  # fmt: skip
  return np.concatenate([img, band], axis=0)


def check_workdir(workdir: str, path: str, camera_json: str, run_file: str) -> None:
  """Refuses, before anything is written, an intake of ``path`` into a
  workdir that holds another recording's intake (``intake.json`` of another
  source), or a search (``run_file``) of another recording or camera file.

  Raises:
    ValueError: naming the workdir's file and what differs.
  """
  old_path = os.path.join(workdir, INTAKE_FILE)
  run = os.path.join(workdir, run_file)
  if not os.path.exists(old_path):
    if os.path.exists(run):
      raise ValueError(
        f'{run}: the workdir holds an estimate of a recording that was not taken '
        f'in here, not of {path}; use another --workdir'
      )
    return
  old = recording_lib.read_json(old_path)
  source = old.get('source') if isinstance(old, dict) else None
  if source != os.path.abspath(path):
    raise ValueError(
      f'{old_path}: the workdir holds the intake of {source}, not of {path}; use '
      'another --workdir'
    )
  camera = os.path.abspath(camera_json) if camera_json else ''
  if os.path.exists(run) and old.get('camera_file', camera) != camera:
    raise ValueError(
      f'{old_path}: the workdir holds an estimate with a different camera file '
      f'({old.get("camera_file") or "none"}, not {camera or "none"}); use another '
      '--workdir'
    )


def write(
  intake: Intake, workdir: str, sim: simulation.Simulation, *, frames: bool = True
) -> None:
  """Saves ``intake.json``, ``overlay.png`` and (``frames``) the cleaned
  frames as 16-bit mm PNGs in ``intake/`` (``sim``: the estimate's
  ``Simulation``, for the simulated cloth): all of them, or none. Each is
  written under a temporary folder first and renamed into place only when
  every one is complete, ``intake.json`` last: a full disk leaves no
  ``overlay.png`` without its ``intake.json``.

  Raises:
    ValueError: "disk full" naming the file that did not fit.
  """
  os.makedirs(workdir, exist_ok=True)
  img = overlay(intake, simulation.mesh(sim))
  tmp = tempfile.mkdtemp(prefix='.intake-', dir=workdir)
  try:
    dataset.imwrite(os.path.join(tmp, OVERLAY_FILE), img)
    if frames:
      staged = os.path.join(tmp, FRAMES_DIR)
      os.makedirs(staged)
      mm = dataset.depth_to_mm(intake.depth)
      for t, f in enumerate(mm):
        dataset.imwrite(os.path.join(staged, f'{t:04d}.png'), f)
      with open(os.path.join(staged, 'fps.txt'), 'w') as f:
        f.write(f'{intake.fps:g}\n')
      os.chmod(staged, dataset.user_mode(0o777))
    files.write_json(os.path.join(tmp, INTAKE_FILE), to_json(intake))
    for name in (OVERLAY_FILE, INTAKE_FILE):
      os.chmod(os.path.join(tmp, name), dataset.user_mode(0o666))
    # Into place: the frames, the overlay, then intake.json (the run's mark).
    if frames:
      final = os.path.join(workdir, FRAMES_DIR)
      if os.path.isdir(final):
        shutil.rmtree(final)
      os.replace(staged, final)
    os.replace(os.path.join(tmp, OVERLAY_FILE), os.path.join(workdir, OVERLAY_FILE))
    os.replace(os.path.join(tmp, INTAKE_FILE), os.path.join(workdir, INTAKE_FILE))
  except OSError as e:
    if dataset.is_disk_full(e):
      raise dataset.disk_full(getattr(e, 'filename', None) or workdir, e) from None
    raise
  finally:
    shutil.rmtree(tmp, ignore_errors=True)


def to_recording(intake: Intake, fps: float, size: tuple[int, int], frames: int):
  """The ``recording.Recording`` the search compares: the cleaned frames at
  ``fps`` (nearest in time) and ``size`` (nearest), the camera resized."""
  pos = video.resample_indices(len(intake.depth), intake.fps, fps)[:frames]
  depth = video.resample_frames(intake.depth, pos, 'nearest')
  depth = video.resize_frames(depth, tuple(size), 'nearest')
  intr = intake.intrinsics.resized(size[1], size[0]) if intake.intrinsics else None
  return recording_lib.Recording(
    np.ascontiguousarray(depth, np.float32), fps, intr, intake.pose, intake.source,
    intake.truth,
  )  # fmt: skip
