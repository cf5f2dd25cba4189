"""The recording's camera placed in the simulator's world, and checked.

The intake's alignment (``experiments.pipeline.intake``, steps 4 and 5): the
two pinned corners, given by the user or fitted (``physsim.alignment``), and
up (``given_ups``: --up, --world_up, the camera file's "gravity"; else a
floor in view, else the cloth's own plane) give the camera's pose
(``fit_placement``); a camera file in this project's own form already holds it.
From the pose the simulated cloth must be in view and its silhouette, at rest
or swung about its top edge, overlap the recording's cloth; else the intake
refuses, after writing the overlay that shows why (``align``). The placement's
own error (``alignment_error``) is what the posterior carries.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

import physsim
from experiments.pipeline import cloth_view, intake_files, simulation
from experiments.pipeline.intake_record import UP_WORDS, Intake, IntakeConfig
from physsim import alignment, camera_files

# Pin spacing may differ from the simulated cloth's by this share.
PIN_SPACING_TOL = 0.2
# Two sources of up (--up, --world_up, gravity, a floor) that differ by more
# than this many degrees are reported.
UP_CROSS_CHECK_DEG = 3.0
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


class Placement(NamedTuple):
  """The camera placed in the simulator's world (``fit_placement``).

  Attributes:
    pose: the camera's pose.
    pins: (2, 3) the pins in the camera frame, left first.
    up_from: where up came from (``intake_record.UP_WORDS``).
    warnings: what the user should check (sources of up that disagree).
    sd: (metres, degrees) the placement's own error, 1 sd (``alignment_error``).
  """

  pose: physsim.Pose
  pins: np.ndarray
  up_from: str
  warnings: tuple[str, ...]
  sd: tuple[float, float]


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
  fit, pins, want_spacing: float, intr, warnings, scatter_se: float = 0.0
) -> tuple:
  """(metres, degrees): the alignment's own error, 1 sd per axis, for the
  estimate's ``camera_sd_m``/``camera_sd_deg``.

  The pins are fitted at the cloth's top corners, which sit inside the pinned
  corners and behind them (the cloth by a pin curls and sweeps downwind, and
  the sensor loses it edge-on), by about half the pins' spacing shortfall
  against the simulated cloth's. With ``scatter_se`` (``alignment.track_pins``'
  scatter over the square root of its kept stretches: the noise left in the
  chosen fit) in quadrature, that is the length ``L`` of a shift in no known
  direction: ``L / sqrt(3)`` per axis, at least ``MIN_SD_M`` or two pixels at
  the pins' depth. Its turn of the pins' line across their spacing adds in
  quadrature to the tilt by where up came from (``UP_SD_DEG``), which is at
  least any disagreement between up's sources. The pins' scatter itself is not
  the error: it grows with the cloth's flutter, the placement's error does not
  (benchmarks.alignment_error)."""
  depth = float(np.mean(pins[:, 2]))
  spacing = float(np.linalg.norm(pins[1] - pins[0]))
  per_axis = float(np.hypot(0.5 * abs(spacing - want_spacing), scatter_se)) / np.sqrt(3)
  m = max(MIN_SD_M, 2 * depth / intr.fx, per_axis)
  deg = UP_SD_DEG[fit.up_from]
  if fit.floor_up is not None and fit.up_from not in ('floor', 'cloth plane'):
    deg = max(deg, alignment.angle_deg(fit.up, fit.floor_up))
  if warnings:  # sources of up more than UP_CROSS_CHECK_DEG apart
    deg = max(deg, 2 * UP_CROSS_CHECK_DEG)
  deg = float(np.hypot(deg, np.degrees(np.arctan2(per_axis, want_spacing))))
  return (round(min(m, 0.2), 4), round(min(deg, 20.0), 2))


def align(
  taken: Intake,
  cam: camera_files.CameraFile,
  config: IntakeConfig,
  sim: simulation.Simulation,
  planes: list,
  workdir: str | None,
) -> Intake:
  """``taken`` with its camera placed in the simulator's world and checked:
  the pose fitted from the pins and up (``fit_placement``) unless the camera
  file already holds it, the simulated cloth in view from it (``in_view``), and
  its silhouette overlapping the recording's cloth in the first second
  (``best_overlap``), else refused after the overlay is written to
  ``workdir``. ``planes``: the background planes removed (a floor gives up).

  Raises:
    ValueError: naming the recording or camera file and what to check.
  """
  pins_world, mesh = cloth_view.simulated_pins(sim)
  if config.pins or cam.world == 'user' or cam.pose is None:
    placed = fit_placement(taken, cam, config, sim, planes, pins_world)
  else:
    pins = alignment.pins_in_camera(cam.pose, pins_world)
    placed = Placement(cam.pose, pins, 'camera file', (), (0.0, 0.0))
  sims = in_view(cam.path, mesh, pins_world, taken.intrinsics, placed.pose)
  frame, best, overlap = best_overlap(taken, sims)
  out = taken._replace(
    pose=placed.pose, pins_camera=placed.pins, up_from=placed.up_from,
    overlap=overlap, swing_deg=float(cloth_view.SWINGS_DEG[best]),
    silhouette=sims[best], overlap_frame=frame,
    warnings=taken.warnings + tuple(placed.warnings),
    alignment_sd=placed.sd,
  )  # fmt: skip
  if overlap < config.min_overlap:
    refuse_poor_overlap(out, config, sim, workdir)
  return out


def fit_placement(
  taken: Intake,
  cam: camera_files.CameraFile,
  config: IntakeConfig,
  sim: simulation.Simulation,
  planes: list,
  pins_world: np.ndarray,
) -> Placement:
  """The camera's pose from the pins (``--pins``, else fitted to the cloth and
  followed over the whole recording for its most upwind place) and up (the
  first of ``given_ups``, else a floor, else the cloth's plane); refused when
  the pins are not as far apart as the simulated cloth's ``pins_world``."""
  if sim.garment and not config.pins:
    raise ValueError(
      'a garment cannot be found by the square-cloth fit; give --pins (the two '
      'pinned corners in the camera frame)'
    )
  intr = taken.intrinsics
  want = float(np.linalg.norm(pins_world[1] - pins_world[0]))
  user = np.asarray(config.pins, np.float64).reshape(2, 3) if config.pins else None
  given = given_ups(cam, config)
  fit = alignment.fit_pins(
    taken.depth, intr, pins=user, background=planes, plane_tol=config.plane_tol,
    up=given[0][1] if given else None, up_from=given[0][0] if given else 'user',
    spacing=want,
  )  # fmt: skip
  warnings = cross_check(given, fit)
  found, scatter_se = fit.pins, 0.0
  if not config.pins:  # the whole recording's most upwind fit, and its noise
    track = alignment.track_pins(
      taken.depth, intr, fit.pins, fit.up, wind_toward_camera=config.wind_toward_camera,
      spacing=want,
    )  # fmt: skip
    found = track.pins
    scatter_se = track.scatter / np.sqrt(max(int(track.kept.sum()), 1))
  pose, pins = alignment.camera_pose(
    found, fit.up, pins_world, wind_toward_camera=config.wind_toward_camera
  )
  check_spacing(taken.source, pins, want, sim)
  sd = alignment_error(fit, pins, want, intr, warnings, scatter_se)
  return Placement(pose, pins, fit.up_from, warnings, sd)


def check_spacing(
  source: str, pins: np.ndarray, want: float, sim: simulation.Simulation
) -> None:
  """Refuses pins (camera frame) whose spacing differs from the simulated
  cloth's ``want`` by more than ``PIN_SPACING_TOL``: wrong intrinsics, depth
  scale or cloth size, which no search would recover from."""
  spacing = float(np.linalg.norm(pins[1] - pins[0]))
  if abs(spacing / want - 1) > PIN_SPACING_TOL:
    raise ValueError(
      f'{source}: the pins are {spacing:.3f} m apart but the simulated '
      f"cloth's are {want:.3f} m; check the camera file's intrinsics, the "
      'depth_scale and --pins'
      + ('' if sim.garment else f', or give the cloth\'s side as --cloth_size '
         f'(now {sim.cloth_size:g} m)')
    )  # fmt: skip


def in_view(
  camera_path: str,
  mesh: physsim.Mesh,
  pins_world: np.ndarray,
  intr: physsim.Intrinsics,
  pose: physsim.Pose,
) -> np.ndarray:
  """The simulated cloth's silhouettes from ``pose`` (``cloth_view.silhouettes``,
  at rest first, then swung); refused when too little of it is in view
  (``MIN_VISIBLE``, ``MIN_PIXELS``): a misplaced camera."""
  seen = alignment.visible_share(mesh.vertices, pose, intr)
  sims = cloth_view.silhouettes(mesh, pins_world, intr, pose)
  area = int(sims[0].sum())
  if seen < MIN_VISIBLE or area < MIN_PIXELS:
    raise ValueError(
      f'{camera_path}: from this camera {100 * seen:.0f}% of the simulated cloth is '
      f'in view, covering {area} pixels; check the camera pose (cam_to_world) or '
      '--pins'
    )
  return sims


def best_overlap(taken: Intake, sims: np.ndarray) -> tuple[int, int, float]:
  """(frame, swing, IoU) of the best overlap of the recording's cloth in its
  first second with the silhouettes ``sims``: a sheet the wind billows matches
  a rigid swing only now and then."""
  first_second = taken.depth[: max(1, int(round(taken.fps)))] > 0
  ious = np.array([[alignment.iou(f, sim) for sim in sims] for f in first_second])
  frame, best = np.unravel_index(int(np.argmax(ious)), ious.shape)
  return int(frame), int(best), float(ious[frame, best])


def refuse_poor_overlap(
  out: Intake, config: IntakeConfig, sim: simulation.Simulation, workdir: str | None
) -> None:
  """Refuses an intake whose overlap is below ``min_overlap``, after writing
  its overlay (and ``intake.json``) to ``workdir`` for the user to see why.

  Raises:
    ValueError: always, naming the overlap, the overlay, and where up was a
      guess what would replace it.
  """
  where = ''
  if workdir:
    intake_files.write(out, workdir, sim, frames=False)
    where = f'; see {os.path.join(workdir, intake_files.OVERLAY_FILE)}'
  guess = ''
  if out.up_is_guess:
    guess = (
      "; up was a guess from the cloth's own plane: --world_up=AXIS (the camera "
      'file\'s world axis that points up), "gravity" in the camera file or --up '
      'places the camera without it'
    )
  raise ValueError(
    f'{out.source}: the simulated cloth at the fitted pose overlaps the '
    f"recording's by IoU {out.overlap:.2f} < min_overlap {config.min_overlap}{where}"
    f'{guess}'
  )
