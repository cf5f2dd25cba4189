"""The scene around the cloth in a depth recording: planes and background.

A recording shows more than the cloth: a floor, a wall, a stand. The embedding
would see them (the simulations have none), so they are removed before any
comparison. ``remove_background`` keeps a pixel when it is

* inside ``depth_range`` and inside the user's mask, if given;
* farther than ``plane_tol`` from every *background plane*: a plane found by
  RANSAC in the recording's per-pixel median frame whose inliers reach
  farther than the cloth could (longest side of their in-plane bounding
  rectangle > ``1.3 x cloth_size``, once thin strips, such as where the
  floor crosses the cloth's plane, are opened away), which a floor or wall
  does and the cloth (a ``cloth_size`` square) does not;
* in the largest 8-connected region of what is left in its frame.

All NumPy/OpenCV on the host: this runs once per recording, before the search.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import cv2
import numpy as np

from physsim.camera import Intrinsics


class Plane(NamedTuple):
  """The plane ``normal . x + offset = 0`` (unit normal, camera coordinates)."""

  normal: np.ndarray
  offset: float

  def distance(self, points: np.ndarray) -> np.ndarray:
    """Unsigned distances of (..., 3) points, metres."""
    return np.abs(points @ self.normal + self.offset)


def backproject(depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
  """(..., H, W, 3) camera-frame points (OpenCV axes) of (..., H, W) depth."""
  h, w = depth.shape[-2:]
  v, u = np.mgrid[0:h, 0:w].astype(np.float64)
  x = (u - intrinsics.cx) / intrinsics.fx
  y = (v - intrinsics.cy) / intrinsics.fy
  z = np.asarray(depth, np.float64)
  return np.stack([x * z, y * z, z], axis=-1)


def fit_plane(
  points: np.ndarray, tol: float, *, iters: int = 300, seed: int = 0
) -> tuple[Plane, np.ndarray]:
  """RANSAC plane of (N, 3) points, refined by least squares on its inliers.

  Returns:
    (plane, (N,) inlier mask at ``tol`` metres).
  """
  points = np.asarray(points, np.float64)
  if len(points) < 3:
    raise ValueError(f'need >= 3 points to fit a plane, got {len(points)}')
  rng = np.random.default_rng(seed)
  sample = points[rng.choice(len(points), min(len(points), 20000), replace=False)]
  best, best_count = None, -1
  for _ in range(iters):
    a, b, c = sample[rng.choice(len(sample), 3, replace=False)]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n)
    if norm < 1e-12:
      continue
    n /= norm
    count = int((np.abs(sample @ n - n @ a) < tol).sum())
    if count > best_count:
      best, best_count = Plane(n, float(-n @ a)), count
  if best is None:
    raise ValueError('all sampled points are collinear; no plane')
  inliers = best.distance(points) < tol
  for _ in range(2):  # least squares on the inliers, then their new set
    centre = points[inliers].mean(axis=0)
    n = np.linalg.svd(points[inliers] - centre, full_matrices=False)[2][-1]
    best = Plane(n, float(-n @ centre))
    inliers = best.distance(points) < tol
  return best, inliers


def median_frame(depth: np.ndarray) -> np.ndarray:
  """(H, W) per-pixel median of the valid (> 0) depths of (T, H, W) frames; 0
  where a pixel is never valid."""
  stack = np.where(depth > 0, np.asarray(depth, np.float64), np.nan)
  with np.errstate(all='ignore'), warnings.catch_warnings():
    warnings.simplefilter('ignore', RuntimeWarning)  # all-NaN pixels: never seen
    return np.nan_to_num(np.nanmedian(stack, axis=0), nan=0.0)


def plane_basis(normal: np.ndarray) -> np.ndarray:
  """(2, 3) orthonormal in-plane axes of a plane with ``normal``."""
  helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
  a = np.cross(normal, helper)
  a /= np.linalg.norm(a)
  return np.stack([a, np.cross(normal, a)])


def in_plane_extent(points: np.ndarray, plane: Plane) -> float:
  """Longest side of the smallest rectangle around ``points`` in ``plane``, m."""
  uv = (points @ plane_basis(plane.normal).T).astype(np.float32)
  (_, _), (w, h), _ = cv2.minAreaRect(uv)
  return float(max(w, h))


class Background(NamedTuple):
  """What ``remove_background`` kept.

  Attributes:
    depth: (T, H, W) metres, 0 where not cloth.
    cloth: (T, H, W) bool, the kept pixels.
    fraction: (T,) share of each frame's pixels kept.
    planes: the background planes removed.
  """

  depth: np.ndarray
  cloth: np.ndarray
  fraction: np.ndarray
  planes: list[Plane]


def background_planes(
  depth: np.ndarray,
  intrinsics: Intrinsics,
  *,
  plane_tol: float,
  cloth_size: float,
  tries: int = 4,
  seed: int = 0,
) -> list[Plane]:
  """Planes of the median frame that reach farther than the cloth could."""
  median = median_frame(depth)
  rows, cols = np.nonzero(median > 0)
  points = backproject(median, intrinsics)[rows, cols]
  least = max(50, 0.02 * median.size)
  planes = []
  for i in range(tries):
    if len(points) < least:
      break
    plane, inliers = fit_plane(points, plane_tol, seed=seed + i)
    if inliers.sum() < least:
      break
    # Another plane's thin strip along the intersection line (the floor
    # under a cloth's plane) must not make the cloth's plane look large.
    image = np.zeros(median.shape, np.uint8)
    image[rows[inliers], cols[inliers]] = 1
    image = cv2.morphologyEx(image, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
    solid = inliers & (image[rows, cols] > 0)
    if solid.sum() >= 3 and in_plane_extent(points[solid], plane) > 1.3 * cloth_size:
      planes.append(plane)
    keep = ~inliers
    points, rows, cols = points[keep], rows[keep], cols[keep]
  return planes


def largest_region(mask: np.ndarray) -> np.ndarray:
  """The largest 8-connected region of a (H, W) bool mask."""
  n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), 8)
  if n <= 1:
    return np.zeros_like(mask, bool)
  return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


def remove_background(
  depth: np.ndarray,
  intrinsics: Intrinsics,
  *,
  depth_range: tuple[float, float] | None = None,
  mask: np.ndarray | None = None,
  planes: bool = True,
  plane_tol: float = 0.03,
  cloth_size: float = 1.0,
  seed: int = 0,
) -> Background:
  """Keeps the cloth of a (T, H, W) metric depth video (module docstring).

  Args:
    depth: (T, H, W) metres, 0 = invalid.
    intrinsics: the camera at this resolution.
    depth_range: (min, max) metres kept, or None.
    mask: (H, W) or (T, H, W) bool, True where the cloth may be, or None.
    planes: find and remove background planes.
    plane_tol: metres from a background plane that count as on it.
    cloth_size: the cloth's side, metres (a larger plane is background).
    seed: RANSAC's randomness.
  """
  depth = np.asarray(depth, np.float32)
  keep = depth > 0
  if depth_range is not None:
    lo, hi = depth_range
    if not 0 <= lo < hi:
      raise ValueError(f'depth_range must be 0 <= min < max metres, got {depth_range}')
    keep &= (depth >= lo) & (depth <= hi)
  if mask is not None:
    mask = np.asarray(mask, bool)
    if mask.shape[-2:] != depth.shape[-2:]:
      raise ValueError(f'mask is {mask.shape[-2:]} but frames are {depth.shape[-2:]}')
    keep &= mask
  found = []
  if planes:
    found = background_planes(
      np.where(keep, depth, 0), intrinsics, plane_tol=plane_tol,
      cloth_size=cloth_size, seed=seed,
    )  # fmt: skip
    if found:
      pts = backproject(depth, intrinsics)
      for plane in found:
        keep &= plane.distance(pts) >= plane_tol
  cloth = np.stack([largest_region(k) for k in keep])
  fraction = cloth.reshape(len(cloth), -1).mean(axis=1)
  return Background(
    np.where(cloth, depth, 0.0).astype(np.float32), cloth, fraction, found
  )
