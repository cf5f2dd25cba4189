"""The table in an overhang's depth frames: its top, the front face of its
top board and so its edge, and the edge's rounding (``physsim.overhang_depth``'s
steps 1, 2 and 4). A strip hanging over the edge is measured from these:
each of its points' reach out from the face's plane and drop below the top's.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from physsim import scene as scene_lib

PLANE_TOL = 0.005  # m: a plane's inliers (depth noise at 1 m with margin)
BELOW_TOL = 0.004  # m: below the top by more than this
MIN_FACE_POINTS = 200
UP_IN_IMAGE = 0.7  # a plane seen from 20-40 degrees above: its normal this up the image
FACE_BIN = 0.005  # m: the face's line is scored by its length in these
EDGE_WINDOW = 0.008  # m: the edge's points, this far either side of its corner
EDGE_RADII = np.arange(0.0, 0.00601, 0.0001)  # m: the rounding's radii tried
EDGE_CLIP = 0.0025  # m: a point further than this from the profile counts this much
EDGE_STRIP_MARGIN = 0.02  # m: along the edge, beyond the strip's own points
# The edge's points are not independent (the depth's 1 mm steps, the planes'
# own error, the sensor's pattern): its likelihood counts them as this many.
# Chosen on ``benchmarks.overhang_check --tune``'s 60 set-ups (the ray-caster)
# and 60 of MuJoCo's at seed 2: the radius within 0.1 mm on average, 0.02 mm
# low on 1-2.5 mm roundings and 0.1-0.2 mm high on sharp edges (the posterior
# kept above 0), its sd holding it 82% of the time. Halving it held as often,
# with sharp edges read higher.
EDGE_POINTS = 400.0
EDGE_PRIOR_MAX = 0.003  # m: radii above this only where the points ask for them


class Edge(NamedTuple):
  """The table's edge as the frames' points see it.

  Attributes:
    height: (N,) each point above the top's plane, m.
    below: (N,) the points under the top (by ``BELOW_TOL``), no lower than
      the overhang and a few cm.
    out: (N,) each point out from the front face's plane, m.
    along: (N,) each point along the edge, m.
    face_points: the front face's points found.
    ray_out: (N,) the camera's ray to each point (unit), its part out from
      the face (negative: the ray runs in, towards the table).
    ray_up: (N,) and up from the top (negative: the ray runs down).
  """

  height: np.ndarray
  below: np.ndarray
  out: np.ndarray
  along: np.ndarray
  face_points: int
  ray_out: np.ndarray
  ray_up: np.ndarray


def _oriented(plane: scene_lib.Plane) -> scene_lib.Plane:
  """The plane with its normal towards the camera (the origin): offset > 0."""
  if plane.offset < 0:
    return scene_lib.Plane(-plane.normal, -plane.offset)
  return plane


def table_top(points: np.ndarray, seed: int = 0) -> tuple[scene_lib.Plane, np.ndarray]:
  """The table's top among (N, 3) camera-frame points: of the three largest
  planes, those seen from above (their normal up the image: a camera 20-40
  degrees above them), the nearest the camera (the top over a larger floor;
  not the top board's front face, which from 20 degrees may be larger than
  the top); the largest plane when none is.

  Returns:
    (plane with its normal towards the camera, (N,) inlier mask).
  """
  rest = np.ones(len(points), bool)
  found = []
  for k in range(3):
    if rest.sum() < max(0.05 * len(points), 3):
      break
    plane, inl = scene_lib.fit_plane(points[rest], PLANE_TOL, seed=seed + k)
    mask = np.zeros(len(points), bool)
    mask[np.flatnonzero(rest)[inl]] = True
    if k and mask.sum() < 0.05 * len(points):
      break
    found.append((_oriented(plane), mask))
    rest &= ~mask
  above = [f for f in found if -f[0].normal[1] > UP_IN_IMAGE]
  if not above:
    return found[0]
  return min(above, key=lambda f: f[0].offset)


def _line_ransac(q: np.ndarray, tol: float, iters: int, rng,
                 bin_m: float = 0.0) -> tuple[np.ndarray, ...]:  # fmt: skip
  """The 2-D line with the most of (N, 2) points within ``tol`` (with
  ``bin_m``: the longest, by how many ``bin_m`` stretches along it hold one,
  ties by count), refined by total least squares: (a point on it, unit
  normal, inlier mask)."""
  best, best_score = None, (-1, -1)
  for _ in range(iters):
    a, b = q[rng.choice(len(q), 2, replace=False)]
    d = b - a
    norm = np.hypot(*d)
    if norm < 1e-6:
      continue
    n = np.array([-d[1], d[0]]) / norm
    near = np.abs((q - a) @ n) < tol
    count = int(near.sum())
    span = 0
    if bin_m > 0 and count:
      span = len(np.unique(np.floor((q[near] - a) @ (d / norm) / bin_m)))
    if (span, count) > best_score:
      best, best_score = (a, n), (span, count)
  a, n = best
  inl = np.abs((q - a) @ n) < tol
  for _ in range(2):  # within half the tolerance: not what hangs just in front
    near = np.abs((q - a) @ n) < tol / 2
    centre = q[near].mean(axis=0)
    n = np.linalg.svd(q[near] - centre, full_matrices=False)[2][-1]
    a = centre
    inl = np.abs((q - a) @ n) < tol
  return a, n, inl


def _edge(flat, top: scene_lib.Plane, overhang: float, rng, name: str) -> Edge:
  """The table's edge under ``top`` among (N, 3) camera-frame points: where
  the front face's plane (the longest line under the top, in the top's
  plane) meets the top's, its outward normal towards the camera.

  Raises:
    ValueError: naming ``name``: nothing under the top, or too little of
      the face.
  """
  height = flat @ top.normal + top.offset  # (N,) above the top, m
  below = (height < -BELOW_TOL) & (height > -(overhang + 0.03))
  q = flat @ scene_lib.plane_basis(top.normal).T  # in the top's plane
  if below.sum() < MIN_FACE_POINTS:
    raise ValueError(
      f'{name}: nothing under the table top in view (found {int(below.sum())} '
      "points): film the edge from in front, a little above the table's top"
    )
  # the face: the longest line under the top (the strip's hanging part makes
  # a short one, which may hold more points than a thin board's face)
  a, n, on_face = _line_ransac(q[below], PLANE_TOL, 300, rng, FACE_BIN)
  if on_face.sum() < MIN_FACE_POINTS:
    raise ValueError(
      f"{name}: the front face of the table's top board shows "
      f'{int(on_face.sum())} points under its edge (need {MIN_FACE_POINTS}): '
      'a thin board (under 1 cm) seen from far or high; film it nearer or lower, '
      "20-40 degrees above the table's top, the board's front face in view"
    )
  if (0.0 - a) @ n < 0:  # the camera (the origin, projected) on its + side
    n = -n
  out = (q - a) @ n
  along = q @ np.array([-n[1], n[0]])
  ray = flat / np.linalg.norm(flat, axis=1, keepdims=True)
  ray_out = ray @ scene_lib.plane_basis(top.normal).T @ n
  return Edge(height, below, out, along, int(on_face.sum()), ray_out, ray @ top.normal)


def _top_behind(flat, on_top: np.ndarray, edge: Edge, name: str) -> scene_lib.Plane:
  """The top's plane again, fitted to its points behind ``edge``: its RANSAC
  inliers include a band of the face and of the strip under the edge.

  Raises:
    ValueError: naming ``name``: too few points of the top behind the edge.
  """
  behind = on_top & (edge.out < -2 * PLANE_TOL) & (np.abs(edge.height) < PLANE_TOL)
  if behind.sum() < MIN_FACE_POINTS:
    raise ValueError(
      f"{name}: {int(behind.sum())} points of the table's top behind the edge "
      f'found under it ({edge.face_points} points on its front face): film the '
      "edge with the table's top in the upper part of the frame and the top "
      "board's front face under it"
    )
  return _plane_through(flat[behind])


def _plane_through(points: np.ndarray) -> scene_lib.Plane:
  """The least-squares plane through (N, 3) points, its normal towards the
  camera."""
  centre = points.mean(axis=0)
  normal = np.linalg.svd(points - centre, full_matrices=False)[2][-1]
  return _oriented(scene_lib.Plane(normal, float(-normal @ centre)))


def find_edge(
  flat: np.ndarray, overhang: float, seed: int, rng, name: str
) -> tuple[scene_lib.Plane, Edge]:
  """The table's top among (N, 3) camera-frame points and its edge: the edge
  from the top, then the top from behind the edge, twice, and the edge from
  that top (``rng`` draws the face's lines, ``seed`` the planes').

  Raises:
    ValueError: naming ``name`` and what was not found.
  """
  top, on_top = table_top(flat, seed)
  for _ in range(2):
    top = _top_behind(flat, on_top, _edge(flat, top, overhang, rng, name), name)
  return top, _edge(flat, top, overhang, rng, name)


def _ray_distance(out, up, ray_out, ray_up, radius: float) -> np.ndarray:
  """How far (m) each point ``out`` from the face's plane and ``up`` above
  the top's lies along its camera ray (``ray_out``, ``ray_up``: running in
  and down) from the table's section, its corner rounded by ``radius``
  (positive: the point before the surface). A depth camera errs along its
  rays: measured so, a point inside a corner is not explained by the nearer
  of its two faces, which drew a fit of the nearest distance to a sharp
  corner where the rounding is of the order of the depth's noise and steps
  (mid-size radii read at half their size)."""
  to_top = -up / ray_up
  to_face = -out / ray_out
  # on the rounding: the first of the ray's two crossings of its circle
  wo, wu = out + radius, up + radius
  a = ray_out**2 + ray_up**2
  b = wo * ray_out + wu * ray_up
  disc = np.maximum(b * b - a * (wo * wo + wu * wu - radius * radius), 0.0)
  to_arc = (-b - np.sqrt(disc)) / a
  on_top = out + to_top * ray_out <= -radius
  on_face = up + to_face * ray_up <= -radius
  return np.where(on_top, to_top, np.where(on_face, to_face, to_arc))


def edge_radius(out, up, ray_out, ray_up) -> tuple[float, float]:
  """The rounding of the table's edge from its points (not the strip's:
  ``out`` from the face's plane, ``up`` above the top's, m, seen along
  rays ``ray_out``, ``ray_up``): its posterior (mean, sd), m, over
  ``EDGE_RADII``, uniform to ``EDGE_PRIOR_MAX`` and falling off beyond, its
  likelihood the points' squared distances along their rays to the rounded
  section (``_ray_distance``; each clipped at ``EDGE_CLIP``: a stray point
  weighs no more) as ``EDGE_POINTS`` independent points of their own
  scatter."""
  near = (np.abs(out) < EDGE_WINDOW) & (np.abs(up) < EDGE_WINDOW)
  out, up, ray_out, ray_up = out[near], up[near], ray_out[near], ray_up[near]
  prior = np.where(
    EDGE_RADII <= EDGE_PRIOR_MAX, 0.0, -(((EDGE_RADII - EDGE_PRIOR_MAX) / 0.001) ** 2)
  )
  if len(out) >= MIN_FACE_POINTS:
    loss = np.array([
      np.minimum(_ray_distance(out, up, ray_out, ray_up, r) ** 2, EDGE_CLIP**2).mean()
      for r in EDGE_RADII
    ])  # fmt: skip
    var = max(float(loss.min()), 1e-10)  # the points' scatter about the best
    prior = prior - 0.5 * EDGE_POINTS * (loss - loss.min()) / var
  p = np.exp(prior - prior.max())
  p /= p.sum()
  mean = float(p @ EDGE_RADII)
  return mean, float(math.sqrt(max(p @ (EDGE_RADII - mean) ** 2, 0.0)))


def beside(edge: Edge, strip: np.ndarray) -> np.ndarray:
  """(N,) the points more than ``EDGE_STRIP_MARGIN`` along the edge beyond
  those of the ``strip`` mask: the table where the strip neither hangs nor
  lies (an askew strip's part on the top stays within the margin)."""
  lo, hi = edge.along[strip].min(), edge.along[strip].max()
  return (edge.along < lo - EDGE_STRIP_MARGIN) | (edge.along > hi + EDGE_STRIP_MARGIN)


def top_beside(flat, top: scene_lib.Plane, edge: Edge, strip: np.ndarray,
               overhang: float, rng, name: str) -> tuple[scene_lib.Plane, Edge]:  # fmt: skip
  """The top's plane fitted again to its points behind the edge ``beside``
  the ``strip``, and the edge from it (``find_edge``'s, where under
  ``MIN_FACE_POINTS`` are): the strip lying on the top raised its plane by
  a share of the strip's thickness (0.05-0.2 mm), which the rounding's
  fit read as a rounder edge and the strip's drop as a lower one.

  Raises:
    ValueError: naming ``name``: the edge not found again.
  """
  behind = beside(edge, strip) & (edge.out < -2 * PLANE_TOL)
  behind &= np.abs(edge.height) < PLANE_TOL
  if behind.sum() < MIN_FACE_POINTS:
    return top, edge
  top = _plane_through(flat[behind])
  return top, _edge(flat, top, overhang, rng, name)


def rounding(
  edge: Edge, strip: np.ndarray, known_radius: float | None
) -> tuple[float, float]:
  """The edge's rounding (mean, sd), m: ``edge_radius`` of the table's points
  more than ``EDGE_STRIP_MARGIN`` along the edge beyond the ``strip`` mask's,
  or ``known_radius`` (sd 0) where given.

  Raises:
    ValueError: ``known_radius`` outside ``EDGE_RADII``.
  """
  if known_radius is not None and not (
    math.isfinite(known_radius) and 0 <= known_radius <= EDGE_RADII[-1]
  ):
    raise ValueError(f'--edge_radius={known_radius}: need 0 to {EDGE_RADII[-1]} m')
  if known_radius is None:
    side = beside(edge, strip)
    return edge_radius(
      edge.out[side], edge.height[side], edge.ray_out[side], edge.ray_up[side]
    )
  return known_radius, 0.0
