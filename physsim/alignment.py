"""Where the cloth hangs in a recording, and so where its camera stands in the
simulator's world.

The simulator's cloth hangs from two pinned top corners (``Mesh.pinned``; for
the square, (-0.5, 0, 1.5) and (0.5, 0, 1.5) m), in the x-z plane, z up, the
wind blowing along +y. A recording's world frame is its user's, so instead of
trusting it the cloth is found in the camera frame:

* the **pins**, given by the user (camera frame, metres) or fitted
  (``fit_pins``): a RANSAC plane through the cloth in the first frames, the
  smallest rectangle around its in-plane outline, the side of it nearest the
  top of the image (or along ``up``) as the top edge, then a straight line
  through the real cloth points along that edge, whose ends are the pins
  (or, where the wind lifts the sheet's middle above its pinned corners, the
  upper half's lateral ends, whichever pair is nearer the simulated spacing);
* **up**: given (the user's ``up`` in the camera frame, the camera file's
  world axis named by ``--world_up``, or the gravity its IMU measured:
  ``up_from`` says which), else the normal of a floor: a background plane whose
  normal is square to the top edge (within 17 degrees) and to the line of
  sight (within 45 degrees; a wall behind the cloth faces the camera), on
  the pins' side; else the cloth's own plane, in which the direction from the
  cloth's middle to its top edge is up. A cloth already swung by the wind in
  the first frames tilts the last; a floor in view or a first second at rest
  avoids it;
* the **wind** blows away from the camera unless the user says otherwise.

``camera_pose`` turns the pins and up into the camera's pose in the
simulator's world: the midpoint of the pins lands on the simulator's, the
top edge along +x, up along +z.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from physsim.camera import Intrinsics, Pose
from physsim.scene import Plane, backproject, fit_plane, median_frame, plane_basis

# A floor's normal: |cos| to the top edge below this (square to it) ...
_FLOOR_EDGE_COS = 0.3
# ... and |cos| to the line of sight below this (a wall faces the camera).
_FLOOR_VIEW_COS = np.cos(np.deg2rad(45.0))


class ClothFit(NamedTuple):
  """The cloth as found in the camera frame (OpenCV axes, metres).

  Attributes:
    pins: (2, 3) the pinned top corners.
    plane: the cloth's fitted plane.
    up: (3,) unit up direction used.
    up_from: ``'floor'``, ``'cloth plane'`` or where a given up came from
      (``'user'``, ``'world_up'``, ``'gravity'``).
    floor_up: (3,) up from a floor in view, or None (for cross-checks).
    cloth_up: (3,) up from the cloth's plane (tilted as far as the cloth is
      swung in the first frames).
  """

  pins: np.ndarray
  plane: Plane
  up: np.ndarray
  up_from: str
  floor_up: np.ndarray | None = None
  cloth_up: np.ndarray | None = None


def angle_deg(a, b) -> float:
  """Angle between two directions, degrees."""
  c = float(_unit(a) @ _unit(b))
  return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _unit(v):
  v = np.asarray(v, np.float64)
  return v / np.linalg.norm(v)


def _cloth_points(depth: np.ndarray, intrinsics: Intrinsics, frames: int) -> np.ndarray:
  """(N, 3) points of the per-pixel median of the first ``frames`` frames."""
  median = median_frame(depth[:frames])
  points = backproject(median, intrinsics)[median > 0]
  if len(points) < 30:
    raise ValueError(
      f'only {len(points)} cloth pixels in the first {frames} frames; cannot find '
      'the cloth (check the background removal, depth_range or mask)'
    )
  return points


def _floor_up(planes: list[Plane], pins: np.ndarray) -> np.ndarray | None:
  """Up from a floor among ``planes`` (module docstring), or None."""
  edge = _unit(pins[1] - pins[0])
  mid = pins.mean(axis=0)
  view = _unit(mid)
  floors = [
    p
    for p in planes
    if abs(p.normal @ edge) < _FLOOR_EDGE_COS and abs(p.normal @ view) < _FLOOR_VIEW_COS
  ]
  if not floors:
    return None
  p = min(floors, key=lambda p: abs(p.normal @ view))
  return _unit(p.normal * np.sign(p.normal @ mid + p.offset))


def _top_corners(
  points: np.ndarray, up: np.ndarray, edge: np.ndarray, fx: float, band: float = 0.04
) -> np.ndarray:
  """(2, 3) the ends of the cloth's highest ``band`` of points: the pinned
  corners, which stay highest however far the wind swings the cloth about
  them. The band's main horizontal direction is the edge's (``edge`` only
  picks its sign)."""
  h = points @ up
  top = points[h >= np.quantile(h, 0.995) - band]
  flat = top - np.outer(top @ up, up)
  axis = np.linalg.svd(flat - flat.mean(axis=0), full_matrices=False)[2][0]
  axis = axis * np.sign(axis @ edge)
  t, h_top = top @ axis, top @ up
  ends = []
  for sign in (-1.0, 1.0):
    # A corner is extreme along the edge and, among such points (a swung
    # cloth's side edge runs away from the camera at nearly the same
    # height), the highest.
    score = sign * t + h_top
    corner = top[score >= score.max() - 0.01].mean(axis=0)
    # Pixel centres sit on average half a pixel inside the cloth's outline.
    half_pixel = 0.5 * corner[2] / fx
    ends.append(corner + half_pixel * (sign * axis + up))
  return np.stack(ends)


def _side_corners(
  points: np.ndarray, up: np.ndarray, edge: np.ndarray, fx: float
) -> np.ndarray:
  """(2, 3) the cloth's ends along the edge in its upper half, each the
  highest of the points within 2 cm of the extreme: the pins where a strong
  wind lifts the sheet's middle above them (only the corners are pinned), so
  that its highest band lies between them."""
  h = points @ up
  upper = points[h >= np.quantile(h, 0.5)]
  axis = _unit(edge - (edge @ up) * up)
  t = upper @ axis
  ends = []
  for sign in (-1.0, 1.0):
    near = upper[sign * t >= (sign * t).max() - 0.02]
    hn = near @ up
    corner = near[hn >= hn.max() - 0.01].mean(axis=0)
    half_pixel = 0.5 * corner[2] / fx
    ends.append(corner + half_pixel * (sign * axis + up))
  return np.stack(ends)


def fit_pins(
  depth: np.ndarray,
  intrinsics: Intrinsics,
  *,
  pins: np.ndarray | None = None,
  background: list[Plane] = (),
  up: np.ndarray | None = None,
  up_from: str = 'user',
  frames: int = 5,
  plane_tol: float = 0.03,
  seed: int = 0,
  spacing: float | None = None,
) -> ClothFit:
  """The cloth's pins, plane and up in a background-free depth video.

  Args:
    depth: (T, H, W) metres, 0 where not cloth (``scene.remove_background``).
    intrinsics: the camera at this resolution.
    pins: (2, 3) the user's pins (camera frame), or None to fit them.
    background: the background planes removed (a floor among them gives up).
    up: (3,) a given up direction in the camera frame, or None.
    up_from: where ``up`` came from (``'user'``, ``'world_up'``, ``'gravity'``).
    frames: first frames whose median shows the cloth at (or near) rest.
    plane_tol: RANSAC inlier distance, metres.
    seed: RANSAC's randomness.
    spacing: the simulated cloth's pin spacing, metres, or None. Given, the
      pins are the pair nearest to it of the highest band's ends and the
      upper half's lateral ends (``_side_corners``); else the former.
  """
  points = _cloth_points(depth, intrinsics, frames)
  plane, inliers = fit_plane(points, plane_tol, seed=seed)
  normal = plane.normal * np.sign(plane.normal @ points.mean(axis=0))  # away
  plane = Plane(normal, float(-normal @ points[inliers].mean(axis=0)))
  basis = plane_basis(normal)
  centre = points[inliers].mean(axis=0)
  user_pins = pins is not None
  if user_pins:
    pins = np.asarray(pins, np.float64).reshape(2, 3)
  else:  # a first guess: the top side of the smallest rectangle in the plane
    uv = ((points[inliers] - centre) @ basis.T).astype(np.float32)
    corners = cv2.boxPoints(cv2.minAreaRect(uv)).astype(np.float64) @ basis + centre
    sides = [(corners[i], corners[(i + 1) % 4]) for i in range(4)]
    # The image's up (-y) stands in for gravity here.
    hint = _unit(up) if up is not None else np.array([0.0, -1.0, 0.0])
    pins = np.stack(max(sides, key=lambda s: float((s[0] + s[1]) @ hint)))
  edge_axis = _unit(pins[1] - pins[0])
  cloth_up = np.cross(normal, edge_axis)
  cloth_up = _unit(cloth_up * np.sign(cloth_up @ (pins.mean(axis=0) - centre)))
  floor = _floor_up(list(background), pins)
  if up is not None:
    up_vec = _unit(up)
  else:
    up_vec, up_from = (
      (floor, 'floor') if floor is not None else (cloth_up, 'cloth plane')
    )
  if not user_pins:
    pins = _top_corners(points, up_vec, edge_axis, intrinsics.fx)
    if spacing is not None:
      side = _side_corners(points, up_vec, edge_axis, intrinsics.fx)
      off = lambda p: abs(float(np.linalg.norm(p[1] - p[0])) - spacing)
      pins = min((pins, side), key=off)
  return ClothFit(pins, plane, up_vec, up_from, floor, cloth_up)


class PinTrack(NamedTuple):
  """The pins fitted over the whole recording (``track_pins``).

  Attributes:
    pins: (2, 3) each pin's most upwind fit (camera frame).
    candidates: (K, 2, 3) every stretch's fit, the first fit first, each pair
      in the first fit's order.
    kept: (K,) bool, the candidates that are not misfits (``MISFIT_SHARE``).
    scatter: the larger of the two pins' RMS distance from their mean over
      the kept candidates, metres (0 for one candidate).
  """

  pins: np.ndarray
  candidates: np.ndarray
  kept: np.ndarray
  scatter: float


# A stretch whose pin lands farther than this share of the pins' spacing from
# that pin's median over the stretches has fitted another corner or a sliver
# of cloth (a sheet seen edge-on for a moment), not the pin: it is left out of
# the choice and of the scatter, which it would otherwise dominate (one such
# fit, 0.74 m off, made 20 cm of scatter where the pins were within 5 cm).
MISFIT_SHARE = 0.25


def track_pins(
  depth: np.ndarray,
  intrinsics: Intrinsics,
  first: np.ndarray,
  up: np.ndarray,
  *,
  windows: int = 8,
  frames: int = 5,
  spacing: float | None = None,
  wind_toward_camera: bool = False,
) -> PinTrack:
  """The pins from the whole recording, not only its first frames.

  The pins hold still while the wind moves the cloth downwind of them, so a
  corner the camera sees edge-on (or, past the sensor's grazing angle, not
  at all) is fitted at a cloth point behind it, and differently in each
  stretch of frames. ``fit_pins`` runs on ``windows`` stretches of ``frames``
  frames spread over ``depth`` (T, H, W) with ``up`` given; each pin is taken
  from the stretch that puts it most upwind (the cloth's least swept-back
  moment), and how far the fits move (``scatter``) is the noise in that
  choice (the intake claims its standard error, not the scatter itself, which
  grows with the cloth's flutter). A stretch that fitted something else
  (``MISFIT_SHARE``) is left out of both.

  Args:
    depth: (T, H, W) metres, 0 where not cloth.
    intrinsics: the camera at this resolution.
    first: (2, 3) the first frames' fit.
    up: (3,) up in the camera frame.
    windows: stretches fitted.
    frames: frames per stretch.
    spacing: the simulated cloth's pin spacing (``fit_pins``).
    wind_toward_camera: the wind blows toward the camera, not away.
  """
  first = np.asarray(first, np.float64)
  edge = first[1] - first[0]
  candidates = [first]
  t = len(depth)
  starts = sorted({round(s) for s in np.linspace(0, max(t - frames, 0), windows)})
  for s in starts if len(starts) > 1 else ():
    try:
      fit = fit_pins(
        depth[s : s + frames], intrinsics, up=up, frames=frames, spacing=spacing
      )
    except ValueError:  # too little cloth in this stretch
      continue
    p = fit.pins if (fit.pins[1] - fit.pins[0]) @ edge > 0 else fit.pins[::-1]
    candidates.append(p)
  c = np.asarray(candidates)
  off = np.linalg.norm(c - np.median(c, axis=0), axis=2).max(axis=1)
  kept = off <= MISFIT_SHARE * np.linalg.norm(edge)
  if kept.sum() < 2:  # no majority to hold to: every fit, and all their spread
    kept = np.ones(len(c), bool)
  good = c[kept]
  rms = np.sqrt(((good - good.mean(axis=0)) ** 2).sum(axis=2).mean(axis=0))
  # downwind: level, square to the pins' line, away from the camera (or toward)
  x = _unit(edge)
  level = _unit(_unit(up) - (_unit(up) @ x) * x)
  down = np.cross(level, x)
  if (float(down @ first.mean(axis=0)) > 0) == wind_toward_camera:
    down = -down
  pins = np.stack([good[np.argmin(good[:, k] @ down), k] for k in range(2)])
  return PinTrack(pins, c, kept, float(rms.max()) if len(good) > 1 else 0.0)


def camera_pose(
  pins_camera: np.ndarray,
  up_camera: np.ndarray,
  pins_world: np.ndarray,
  *,
  wind_toward_camera: bool = False,
) -> tuple[Pose, np.ndarray]:
  """The camera's pose in the simulator's world from the pins it sees.

  Args:
    pins_camera: (2, 3) the pins in the camera frame, either order.
    up_camera: (3,) up in the camera frame.
    pins_world: (2, 3) the simulator's pins, left (-x) first.
    wind_toward_camera: the wind (+y) blows toward the camera, not away.

  Returns:
    (pose, (2, 3) pins_camera ordered as ``pins_world``).
  """
  p = np.asarray(pins_camera, np.float64)
  for _ in range(2):
    x = p[1] - p[0]
    z = _unit(up_camera) - (_unit(up_camera) @ _unit(x)) * _unit(x)
    x, z = _unit(x), _unit(z)
    y = np.cross(z, x)
    away = float(y @ p.mean(axis=0)) > 0
    if away != wind_toward_camera:
      break
    p = p[::-1]
  rot = np.stack([x, y, z])  # rows: world axes in camera coordinates
  world = np.asarray(pins_world, np.float64)
  position = world.mean(axis=0) - rot @ p.mean(axis=0)
  return Pose(rot.astype(np.float32), position.astype(np.float32)), p


def pins_in_camera(pose: Pose, pins_world: np.ndarray) -> np.ndarray:
  """(2, 3) world pins in the camera frame of ``pose``."""
  r = np.asarray(pose.rotation, np.float64)
  return (np.asarray(pins_world, np.float64) - np.asarray(pose.position)) @ r


def iou(a: np.ndarray, b: np.ndarray) -> float:
  """Intersection over union of two bool masks (0 when both are empty)."""
  union = np.logical_or(a, b).sum()
  return float(np.logical_and(a, b).sum() / union) if union else 0.0


def visible_share(
  points_world: np.ndarray, pose: Pose, intrinsics: Intrinsics
) -> float:
  """Share of world points in front of the camera and inside its image."""
  xc = (np.asarray(points_world, np.float64) - np.asarray(pose.position)) @ np.asarray(
    pose.rotation, np.float64
  )
  z = xc[:, 2]
  safe = np.where(z > 1e-3, z, 1.0)
  u = intrinsics.fx * xc[:, 0] / safe + intrinsics.cx
  v = intrinsics.fy * xc[:, 1] / safe + intrinsics.cy
  inside = (z > 1e-3) & (u >= -0.5) & (u <= intrinsics.width - 0.5)
  inside &= (v >= -0.5) & (v <= intrinsics.height - 0.5)
  return float(inside.mean())
