"""What a depth camera reads of a protocol candidate, and how noisily.

What the camera sees is approximated from the simulated vertices by a few
statistics (``STATS``, ``summaries``), each divided by the cloth's size: where
the cloth hangs on average over the clip (its centroid out of plane and up),
where its free bottom edge hangs, how curved it is (the mean norm of the grid
Laplacian, times the size), and how much it moves (the centroid's standard
deviation over the clip). Their sensor and set-up noise (``sensor_sd``) is a
Kinect-class camera's (sigma(z) = 1.5 mm at 1 m, growing as z^2; 640 x 480 px,
58 deg horizontal field of view), placed so the cloth fills 60% of the
frame's width but no nearer than its 0.5 m minimum range
(``camera_distance``).
"""

from __future__ import annotations

import numpy as np

from experiments.studies.protocol_candidates import Candidate

STATS = ('centroid_out', 'centroid_up', 'free_edge_out', 'free_edge_up',
         'curvature', 'motion')  # fmt: skip
# Kinect-class depth camera
HFOV_DEG = 58.0
WIDTH_PX = 640
DEPTH_SD_1M = 0.0015  # m at 1 m, growing as z^2
MIN_RANGE_M = 0.5
UNUSED_SD = 1e6  # a statistic's noise that leaves it out of the information
FILL = 0.6  # of the frame's width


def camera_distance(size: float) -> float:
  """Metres from a Kinect-class camera at which the cloth fills ``FILL`` of the
  frame's width, but no nearer than its minimum range."""
  width_at_1m = 2 * np.tan(np.radians(HFOV_DEG / 2))
  return max(size / (FILL * width_at_1m), MIN_RANGE_M)


def sensor_sd(c: Candidate, clip_s: float, camera_fps: float, setup_mm: float,
              curvature_floor: float) -> np.ndarray:  # fmt: skip
  """(len(STATS),) noise standard deviations of the statistics from the depth
  sensor and the set-up, in the statistics' units (divided by the size).

  The camera at ``camera_distance``: a pixel spans ``fp`` metres on the cloth;
  depth noise ``sz = 1.5 mm (d / 1 m)^2`` per pixel and frame, independent.
  Means over the cloth's ``n`` pixels and ``T`` frames: depth-wise (out of
  plane) ``sz / sqrt(n T)``; in the image plane (up) from the silhouette's
  ``4 L / fp`` edge pixels, ``fp / sqrt(12 4 L / fp T)``; the free edge from
  its ``L / fp`` pixels; the curvature from 8 x 8 patches of side ``a = L / 8``
  (a quadratic fit's second derivative, ``~ 4 sz / (a^2 sqrt(n_patch))``);
  the motion (a standard deviation over time) like the centroid. Set-up
  repeatability (``setup_mm``: where the pins and the camera are) adds to
  every position; ``curvature_floor`` to the curvature (size x 1/m).
  """
  size = c.size
  d = camera_distance(size)
  fp = 2 * d * np.tan(np.radians(HFOV_DEG / 2)) / WIDTH_PX
  sz = DEPTH_SD_1M * d**2
  t = clip_s * camera_fps
  n = (size / fp) ** 2
  edge = size / fp
  a = size / 8
  setup = setup_mm / 1000
  sd_m = np.array([
    np.hypot(sz / np.sqrt(n * t), setup),
    np.hypot(fp / np.sqrt(12 * 4 * edge * t), setup),
    np.hypot(sz / np.sqrt(edge * t), setup),
    np.hypot(fp / np.sqrt(12 * edge * t), setup),
    0.0,
    sz / np.sqrt(n * t),
  ])  # fmt: skip
  sd = sd_m / size
  curv = 4 * sz / (a**2 * np.sqrt(n / 64)) / np.sqrt(64 * t)  # 1/m
  sd[4] = np.hypot(curv * size, curvature_floor)
  if c.overhang:
    # A resting overhang does not move; the simulated one swings after its
    # release from flat, which says nothing a real recording could show.
    sd[5] = UNUSED_SD
  return sd


def summaries(positions: np.ndarray, rest: np.ndarray, res: int, size: float):
  """(B, len(STATS)) statistics of (B, T, V, 3) positions of a res x res square
  (row 0 the pinned top edge) whose rest vertices are ``rest`` (V, 3), each
  divided by ``size`` (the curvature multiplied by it)."""
  x = np.asarray(positions, np.float64)
  b, t = x.shape[:2]
  g = x.reshape(b, t, res, res, 3)
  rest_up = rest[:, 2].mean()
  centroid = x.mean(axis=2)  # (B, T, 3)
  bottom = g[:, :, -1].mean(axis=2)  # (B, T, 3)
  h = float(np.linalg.norm(rest[1] - rest[0]))  # the spacing (row 0's first two)
  lap = (g[:, :, 2:, 1:-1] + g[:, :, :-2, 1:-1] + g[:, :, 1:-1, 2:] + g[:, :, 1:-1, :-2]
         - 4 * g[:, :, 1:-1, 1:-1]) / h**2  # fmt: skip
  curvature = np.linalg.norm(lap, axis=-1).mean(axis=(1, 2, 3))
  out = np.stack([
    centroid[:, :, 1].mean(1) / size,
    (centroid[:, :, 2].mean(1) - rest_up) / size,
    bottom[:, :, 1].mean(1) / size,
    (bottom[:, :, 2].mean(1) - rest[-1, 2]) / size,
    curvature * size,
    centroid[:, :, 1].std(1) / size,
  ], axis=1)  # fmt: skip
  return out
