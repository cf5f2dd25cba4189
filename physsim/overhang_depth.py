"""A fabric's bending length read from a depth recording of an overhang.

The cantilever test (``physsim.cantilever``) with a depth camera instead of a
ruler: a strip lies on a table with a known length ``overhang`` of it slid
past the edge (ruler marks on the strip), and a depth camera in front of the
edge, a little above the table, films it hanging still. From the frames'
per-pixel median:

1. the table's top is, of the largest planes in view, the nearest the
   camera of those seen from above (not the floor; not the top board's front
   face, larger than the top from 20 degrees up): "up" is its normal, the
   camera's side;
2. the front face of the top board is the longest vertical plane just under
   the top (a line in the top's plane, found by RANSAC on the points below
   it projected onto it, scored by its length: a thin board's face is a
   few pixels tall, the strip's hanging part a short line of many): where
   its plane meets the top's is the edge, the outward direction its normal
   towards the camera. The overhang and the reach are measured from that
   plane (the table's outermost line seen from above: README, "How to
   record"; ``experiments.overhang``'s ruler reading alike);
3. the strip is the largest connected patch of pixels below the top and in
   front of the face (no lower than the overhang, so not the floor): each
   of its points is a (reach out from the edge, drop below the top) pair;
4. the edge's rounding is fitted to the table's points beside the strip
   (``edge_radius``): a strip bends from where the rounding starts, about
   its radius behind the face (``physsim.tabletop``);
5. the heavy elastica of overhang L + radius over bending length c, flat
   where the rounding starts, is fitted to those pairs (each point's
   distance to the curve) on a grid of L / c at the given L; with L's ruler
   uncertainty and the radius's (its posterior: under about 1.5 mm a
   rounding looks sharp at 0.35-0.55 m), the posterior of c. The curve
   reads the strip's shape, the ruler its length.

Using the whole curve rather than the tip alone keeps the reading off the
places a depth camera sees worst: the strip's outline (where sensors drop
pixels at depth jumps) and its free end. The fit's spread is the ruler's
share of c (L's sd over L: 1 mm is 1-5% of a 2-12 cm overhang) and the
shape's, which shrinks with the number of pixels; what the fit does not see
(the strip's curl and thickness, the angle it leaves the edge at, the
camera's noise pattern) would be a ``FLOOR`` on c's relative uncertainty,
and the t law's tails. A reading is a Student's t of ``DOF`` degrees of
freedom, its scale the fit's spread and the floor in quadrature: both set
on simulated set-ups (so that its 25-90% intervals hold as often as they
say; ``benchmarks.overhang_check --tune``, the ray-caster) and checked on
others (``benchmarks.overhang_check``, MuJoCo's OpenGL renderer).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import cv2
import numpy as np

from physsim import camera_files, cantilever, video
from physsim import scene as scene_lib
from physsim.camera import Intrinsics

PLANE_TOL = 0.005  # m: a plane's inliers (depth noise at 1 m with margin)
BELOW_TOL = 0.004  # m: below the top by more than this
# m: the strip's points in front of the face by more than this (a soft strip
# on a rounded edge hangs 2-4 mm in front of it)
STRIP_OUT = 0.002
PARALLEL_COS = math.cos(math.radians(5.0))  # planes this close are parallel
VERTICAL_SIN = math.sin(math.radians(8.0))  # the face's normal off horizontal
MIN_FACE_POINTS = 200
MIN_STRIP_POINTS = 60
MAX_FIT_POINTS = 800  # subsampled for the fit (its law was fitted so)
MAX_RESIDUAL = 0.004  # m, RMS: points further from any elastica are not a strip
RATIOS = np.geomspace(0.2, cantilever.MAX_RATIO, 160)  # L / c fitted
# c's error law: Student's t of DOF degrees of freedom, its scale the fit's
# spread (the ruler's L and the curve's L / c) and FLOOR (relative: what the
# fit cannot see) in quadrature (``benchmarks.overhang_depth``: fitted on its
# calibration set-ups, seed 0, so that its 25, 50, 75 and 90% intervals hold
# c as often as they say; checked on others). Fitted on 2026-11-29 for the
# protocol's overhang of about three bending lengths: a t of 10, no floor
# (the ruler's 1 mm, at least 0.8% of a strip up to 12 cm, is in the spread).
# Before, at Peirce's two bending lengths: a t of 4 with a 0.8% floor.
# Kept with the edge's rounding in the reading (issue 77): on 33 tuning set-ups
# of ``benchmarks.overhang_check --tune`` (real tables: rounded edges, curl,
# askew, flying pixels, depth-scale bias) its 90% / 50% intervals held 97% /
# 52% (a t of 6 with a 0.4% floor fitted no closer); checked on MuJoCo's
# renders (BENCHMARKS).
DOF = 10.0
FLOOR = 0.0
# The protocol's overhang (README, "How to record"): about three bending
# lengths, the tip near vertical. Under SHORT_RATIO, ``advice`` says so: at
# Peirce's two the same set-ups read c with about 1.5 times the error (the
# ruler's 1 mm a larger share of a shorter strip; benchmarks.overhang_depth,
# --setups=peirce).
PROTOCOL_RATIO = 3.0
SHORT_RATIO = 2.3


@dataclasses.dataclass(frozen=True)
class Reading:
  """What a depth recording of an overhang says.

  Attributes:
    bending_length: posterior mean of c, m.
    bending_length_sd: its standard deviation, m: of a t law of
      ``bending_length_dof`` degrees of freedom whose scale is the fit's
      spread and ``FLOOR`` in quadrature (``measurements.Measured`` reads it so).
    bending_length_dof: that law's degrees of freedom (``DOF``).
    fit_sd: the fit's own part, m.
    overhang: L, m (the given one: the ruler's, not refined by the curve).
    ratio: L / c at the best fit.
    reach: the best fit's free end out from the edge, m.
    drop: and below the table's top, m.
    residual_m: RMS distance of the strip's points to the best fit, m.
    points: the strip's pixels found.
    face_points: the front face's.
    camera_height_m: the camera above the table's top, m.
    profile: (N, 2) the strip's (reach, drop) points, m (for figures).
    edge_radius: the table edge's rounding fitted beside the strip, m: the
      strip bends from that far behind the face (``fit``).
    edge_radius_sd: its sd, m (in ``bending_length_sd``).
  """

  bending_length: float
  bending_length_sd: float
  bending_length_dof: float
  fit_sd: float
  overhang: float
  ratio: float
  reach: float
  drop: float
  residual_m: float
  points: int
  face_points: int
  camera_height_m: float
  profile: np.ndarray = dataclasses.field(repr=False, compare=False)
  edge_radius: float = 0.0
  edge_radius_sd: float = 0.0

  def to_dict(self) -> dict:
    out = dataclasses.asdict(self)
    del out['profile']
    return out


def advice(reading: Reading) -> str | None:
  """One line for a strip slid over fewer than ``SHORT_RATIO`` bending
  lengths (None otherwise): how far to slide it for the protocol's reading."""
  if reading.ratio >= SHORT_RATIO:
    return None
  return (
    f'the strip hangs {reading.ratio:.1f} bending lengths over the edge: slid out to '
    f'about {PROTOCOL_RATIO:g} ({100 * PROTOCOL_RATIO * reading.bending_length:.1f} cm, '
    'its tip near vertical) the same camera reads c to about two thirds of the '
    'error (README, "How to record")'
  )


def reading_sd(fit_sd: float, c: float, floor: float = FLOOR,
               dof: float = DOF) -> float:  # fmt: skip
  """The standard deviation of a reading of ``c`` whose fit spreads
  ``fit_sd``: its t law's scale (``fit_sd`` and ``floor * c`` in quadrature)
  times sqrt(dof / (dof - 2))."""
  return math.hypot(fit_sd, floor * c) * math.sqrt(dof / (dof - 2.0))


def _oriented(plane: scene_lib.Plane) -> scene_lib.Plane:
  """The plane with its normal towards the camera (the origin): offset > 0."""
  if plane.offset < 0:
    return scene_lib.Plane(-plane.normal, -plane.offset)
  return plane


UP_IN_IMAGE = 0.7  # a plane seen from 20-40 degrees above: its normal this up the image


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


FACE_BIN = 0.005  # m: the face's line is scored by its length in these
OFFSET_RANGE = (-0.001, 0.003)  # m: the seen face off the centre line
COARSE_POINTS = 400  # the coarse grid's points; the fine grid takes them all


def _curve_set(ratios) -> tuple[np.ndarray, np.ndarray]:
  """The elastica's centre line over L for each of ``ratios``, (R, S, 2), and
  its unit normals up and out of the strip (the side a camera above the
  table and in front of its edge sees), (R, S, 2), float32."""
  line = cantilever.shape(ratios)
  tangent = np.gradient(line, axis=1)
  tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
  normal = np.stack([tangent[..., 1], -tangent[..., 0]], axis=-1)
  return line.astype(np.float32), normal.astype(np.float32)


@functools.cache
def _coarse_curves() -> tuple[np.ndarray, np.ndarray]:
  return _curve_set(RATIOS)


FINE_SPAN = 4  # coarse steps either side of the coarse best fit
FINE_RATIOS = 81


@functools.cache
def _fine_grid(j: int) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
  """The fine ratios around coarse ratio ``j`` and their curves: one set per
  coarse ratio, made once per process (the elastica's shooting is the slow
  part of a reading)."""
  lo = RATIOS[max(j - FINE_SPAN, 0)]
  hi = RATIOS[min(j + FINE_SPAN, len(RATIOS) - 1)]
  ratios = np.geomspace(lo, hi, FINE_RATIOS)
  return ratios, _curve_set(ratios)


def _misfit(profile: np.ndarray, length: float, curves,
            setback: float = 0.0) -> tuple[np.ndarray, ...]:  # fmt: skip
  """Per curve of ``curves`` (``_curve_set``'s, scaled by ``length`` and
  starting ``setback`` behind the face, where a rounded edge lets the strip
  bend): the sum of the points' squared signed distances (m^2) from it,
  positive up and out (by the nearest of its points, 1/200 of L apart), once
  the seen face's offset from the centre line (the fabric's half thickness,
  its curl) is taken out; and that offset, within ``OFFSET_RANGE``."""
  p = ((profile + np.array([setback, 0.0])) / length).astype(np.float32)
  line, normal = curves
  d = np.empty((len(line), len(p)), np.float32)
  sq = (line**2).sum(-1)  # (R, S)
  for i in range(len(line)):
    # nearest sample: |l|^2 - 2 p.l orders them as |p - l|^2 does (one product,
    # no (N, S, 2) temporary)
    k = np.argmin(sq[i][None, :] - 2.0 * (p @ line[i].T), axis=1)
    d[i] = ((p - line[i][k]) * normal[i][k]).sum(-1)
  d = d.astype(np.float64) * length
  offset = np.clip(d.mean(axis=1), *OFFSET_RANGE)
  return ((d - offset[:, None]) ** 2).sum(axis=1), offset


def _ruler(overhang: float, overhang_sd: float, nodes: int = 9):
  """L's nodes over +-3 sd of the ruler and their Gaussian weights, summing
  to 1 (the given L alone when the sd is 0)."""
  if overhang_sd <= 0:
    return np.array([overhang]), np.ones(1)
  ls = overhang + overhang_sd * np.linspace(-3, 3, nodes)
  ls = ls[ls > 0]
  weight = np.exp(-0.5 * ((ls - overhang) / overhang_sd) ** 2)
  return ls, weight / weight.sum()


def _setbacks(setback: float, setback_sd: float):
  """The strip's setback behind the face (a rounded edge's radius) at three
  Gauss-Hermite nodes of its Gaussian (none below 0) and their weights; the
  given one alone when its sd is 0."""
  if setback_sd <= 0:
    return np.array([setback]), np.ones(1)
  nodes = setback + setback_sd * math.sqrt(3.0) * np.array([-1.0, 0.0, 1.0])
  return np.maximum(nodes, 0.0), np.array([1.0, 4.0, 1.0]) / 6.0


def _posterior(profile, length, ratios, curves, point_sd, setback=0.0):
  """The (R,) posterior over the curves of ``ratios`` scaled by ``length``
  and set ``setback`` behind the face (the grid's log-uniform prior), the
  best fit's index, its RMS residual and the seen face's offset there."""
  sq, offsets = _misfit(profile, length, curves, setback)
  j = int(np.argmin(sq))
  residual = math.sqrt(sq[j] / len(profile))
  sd = point_sd or max(residual, 1e-5)
  log_p = -0.5 * sq / sd**2
  p = np.exp(log_p - log_p.max())
  return p / p.sum(), j, residual, offsets[j]


def fit(profile: np.ndarray, overhang: float, overhang_sd: float,
        point_sd: float | None = None, seed: int = 0, setback: float = 0.0,
        setback_sd: float = 0.0) -> dict:  # fmt: skip
  """The elastica fitted to (N, 2) (reach, drop) points, m, from the front
  face's plane and the top's.

  The curve gives the strip's shape, L / c, and the ruler its length: the
  shape is fitted at the given overhang L, and c = L / (L / c) with L
  Gaussian (``overhang`` +- ``overhang_sd``; exact when the sd is 0) and
  independent of the shape. The curve is not let refine L: what scales it
  besides L (the sensor's noise along its rays, the strip's thickness, curl,
  and fibres of unequal overhang when it lies askew) moved a refined L by
  3-8% on short strips, more than the ruler's 1 mm, and c with it
  (docs/studies/protocol.md, "Limits"). On a rounded edge the strip bends from
  ``setback`` behind the face (the rounding's radius, Gaussian with sd
  ``setback_sd``, at three nodes): the elastica starts there, flat, its
  free length L + setback, and c = (L + setback) / (its L / c). L / c is
  log-uniform over ``RATIOS``; the seen face lies at an unknown offset from
  the centre line (fitted, within ``OFFSET_RANGE``). Each point's distance
  to the curve is Gaussian with sd ``point_sd`` (default: the RMS distance
  at the best fit). A coarse grid (``RATIOS``, ``COARSE_POINTS`` points)
  finds the best fit, a fine one around it (81 ratios over 8 coarse steps)
  gives the posterior.

  Returns:
    dict: ``c`` and ``c_sd`` (posterior mean and sd, m), ``length`` (L's
    mean: ``overhang``), ``ratio``, ``reach``, ``drop`` (from the face and
    the top), ``offset`` and ``residual`` (the best fit's at the setback's
    middle node), ``edge_mass`` (the coarse posterior's share in the two
    outermost ratios at either end: the reading cannot bound c there).
  """
  rng = np.random.default_rng(seed)
  few = profile
  if len(few) > COARSE_POINTS:
    few = profile[rng.choice(len(profile), COARSE_POINTS, replace=False)]
  p, j, _, _ = _posterior(
    few, overhang + setback, RATIOS, _coarse_curves(), point_sd, setback
  )
  edge_mass = float(p[:2].sum() + p[-2:].sum())
  ratios, curves = _fine_grid(j)
  ls, weight = _ruler(overhang, overhang_sd)
  nodes, node_weight = _setbacks(setback, setback_sd)
  c, joint = [], []
  for k, (back, w) in enumerate(zip(nodes, node_weight, strict=True)):
    p, jk, res, off = _posterior(
      profile, overhang + back, ratios, curves, point_sd, back
    )
    if k == len(nodes) // 2:
      j, residual, offset = jk, res, off
    # (L, R): the ruler's L, apart from L / c, at this setback
    joint.append(w * weight[:, None] * p[None, :])
    c.append((ls[:, None] + back) / ratios[None, :])
  c, joint = np.stack(c), np.stack(joint)
  mean = float((joint * c).sum())
  reach, drop = cantilever.tip(ratios[j])
  free = overhang + setback
  return {
    'c': mean,
    'c_sd': float(math.sqrt(max((joint * (c - mean) ** 2).sum(), 0.0))),
    'length': float(overhang),
    'ratio': float(ratios[j]),
    'reach': float(reach[0] * free - setback),
    'drop': float(drop[0] * free),
    'offset': float(offset),
    'residual': residual,
    'edge_mass': edge_mass,
  }


EDGE_WINDOW = 0.008  # m: the edge's points, this far either side of its corner
EDGE_RADII = np.arange(0.0, 0.00601, 0.0001)  # m: the rounding's radii tried
EDGE_CLIP = 0.0025  # m: a point further than this from the profile counts this much
EDGE_STRIP_MARGIN = 0.02  # m: along the edge, beyond the strip's own points
# The edge's points are not independent (the depth's 1 mm steps, the planes'
# own error, the sensor's pattern): its likelihood counts them as this many
# (chosen, not fitted; on ``benchmarks.overhang_check --tune``'s 33 set-ups
# the radius came out 0.16 mm low on average, 68% within 0.38 mm). A rounding under about 1.5 mm is
# then as likely as a sharp edge at 0.35-0.55 m: the radius's posterior over
# the envelope's 0-3 mm keeps it (the reading's sd carries it).
EDGE_POINTS = 100.0
EDGE_PRIOR_MAX = 0.003  # m: radii above this only where the points ask for them


def _corner_distance(out: np.ndarray, up: np.ndarray, radius: float) -> np.ndarray:
  """Signed distance (m, positive outside the table) of points ``out`` from
  the face's plane and ``up`` above the top's to the table's section, its
  corner rounded by ``radius``."""
  on_arc = (out > -radius) & (up > -radius)
  arc = np.hypot(out + radius, up + radius) - radius
  return np.where(on_arc, arc, np.where(out <= -radius, np.maximum(up, out), out))


def edge_radius(out: np.ndarray, up: np.ndarray) -> tuple[float, float]:
  """The rounding of the table's edge from its points (not the strip's:
  ``out`` from the face's plane, ``up`` above the top's, m): its posterior
  (mean, sd), m, over ``EDGE_RADII``, uniform to ``EDGE_PRIOR_MAX`` and
  falling off beyond, its likelihood the points' squared distances to the
  rounded section (each clipped at ``EDGE_CLIP``: a stray point weighs no
  more) as ``EDGE_POINTS`` independent points of their own scatter."""
  near = (np.abs(out) < EDGE_WINDOW) & (np.abs(up) < EDGE_WINDOW)
  out, up = out[near], up[near]
  prior = np.where(
    EDGE_RADII <= EDGE_PRIOR_MAX, 0.0, -(((EDGE_RADII - EDGE_PRIOR_MAX) / 0.001) ** 2)
  )
  if len(out) >= MIN_FACE_POINTS:
    loss = np.array([
      np.minimum(_corner_distance(out, up, r) ** 2, EDGE_CLIP**2).mean()
      for r in EDGE_RADII
    ])  # fmt: skip
    var = max(float(loss.min()), 1e-10)  # the points' scatter about the best
    prior = prior - 0.5 * EDGE_POINTS * (loss - loss.min()) / var
  p = np.exp(prior - prior.max())
  p /= p.sum()
  mean = float(p @ EDGE_RADII)
  return mean, float(math.sqrt(max(p @ (EDGE_RADII - mean) ** 2, 0.0)))


def _edge(flat, top: scene_lib.Plane, overhang: float, rng, name: str):
  """The table's edge under ``top``: (heights above the top, the mask of
  points under it, the points in its plane (N, 2), (a point on the edge, its
  outward normal towards the camera, the face's points))."""
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
  return height, below, q, (a, n, int(on_face.sum()))


def read(depth: np.ndarray, intrinsics: Intrinsics, overhang: float,
         overhang_sd: float = 0.001, seed: int = 0, name: str = 'the recording',
         known_radius: float | None = None) -> Reading:  # fmt: skip
  """The bending length of the strip in (H, W) or (T, H, W) depth frames, m
  (0 invalid), filmed by a camera of ``intrinsics``, with ``overhang`` (m)
  of it past the front face of the table's top (ruler sd ``overhang_sd``);
  the edge's rounding fitted (``edge_radius``) or ``known_radius`` (m: 0
  for a sharp edge).

  Raises:
    ValueError: naming ``name`` and what was not found (the table, its front
      face, a strip) or why the fit cannot bound c.
  """
  depth = np.asarray(depth, np.float64)
  if depth.ndim == 3:
    depth = scene_lib.median_frame(depth)
  if depth.shape != (intrinsics.height, intrinsics.width):
    raise ValueError(
      f'{name}: frames of {depth.shape} pixels, the camera has '
      f'{(intrinsics.height, intrinsics.width)}'
    )
  if not (math.isfinite(overhang) and 0 < overhang <= 0.5):
    raise ValueError(f'--overhang={overhang}: need 0 < overhang <= 0.5 m')
  if not (math.isfinite(overhang_sd) and 0 <= overhang_sd < overhang / 3):
    raise ValueError(f'--overhang_sd={overhang_sd}: need 0 <= sd < overhang / 3')
  valid = np.isfinite(depth) & (depth > 0)
  if valid.sum() < 1000:
    raise ValueError(
      f'{name}: {int(valid.sum())} valid depth pixels; need a table in view'
    )
  pts = scene_lib.backproject(depth, intrinsics)
  flat = pts[valid]
  rng = np.random.default_rng(seed)
  top, on_top = table_top(flat, seed)
  for _ in range(2):  # the edge from the top, then the top from behind the edge
    height, below, q, (a, n, face_points) = _edge(flat, top, overhang, rng, name)
    out = (q - a) @ n  # (N,) out from the edge, m
    # the top again from its points behind the edge: its RANSAC inliers
    # include a band of the face and of the strip under the edge
    behind = on_top & (out < -2 * PLANE_TOL) & (np.abs(height) < PLANE_TOL)
    if behind.sum() < MIN_FACE_POINTS:
      raise ValueError(
        f"{name}: {int(behind.sum())} points of the table's top behind the edge "
        f'found under it ({face_points} points on its front face): film the '
        "edge with the table's top in the upper part of the frame and the top "
        "board's front face under it"
      )
    centre = flat[behind].mean(axis=0)
    normal = np.linalg.svd(flat[behind] - centre, full_matrices=False)[2][-1]
    top = _oriented(scene_lib.Plane(normal, float(-normal @ centre)))
  height, below, q, (a, n, face_points) = _edge(flat, top, overhang, rng, name)
  out = (q - a) @ n
  strip = below & (out > STRIP_OUT)
  mask = np.zeros(depth.shape, np.uint8)
  mask[valid] = strip
  count, labels = cv2.connectedComponents(mask, connectivity=8)
  if count < 2:
    raise ValueError(
      f'{name}: no strip hanging over the edge in view (or it hardly droops: '
      'slide more of it over)'
    )
  sizes = np.bincount(labels[valid][strip], minlength=count)
  sizes[0] = 0
  keep = labels[valid] == int(np.argmax(sizes))
  keep &= strip
  if keep.sum() < MIN_STRIP_POINTS:
    raise ValueError(
      f'{name}: {int(keep.sum())} pixels of strip over the edge; need '
      f'{MIN_STRIP_POINTS} (move the camera nearer, or slide more over)'
    )
  profile = np.stack([out[keep], -height[keep]], axis=1)
  # the edge's rounding, from the table's points beside the strip
  along = q @ np.array([-n[1], n[0]])
  lo, hi = along[keep].min(), along[keep].max()
  beside = (along < lo - EDGE_STRIP_MARGIN) | (along > hi + EDGE_STRIP_MARGIN)
  if known_radius is not None and not (
    math.isfinite(known_radius) and 0 <= known_radius <= EDGE_RADII[-1]
  ):
    raise ValueError(f'--edge_radius={known_radius}: need 0 to {EDGE_RADII[-1]} m')
  if known_radius is None:
    radius, radius_sd = edge_radius(out[beside], height[beside])
  else:
    radius, radius_sd = known_radius, 0.0
  sub = profile
  if len(sub) > MAX_FIT_POINTS:
    sub = profile[rng.choice(len(profile), MAX_FIT_POINTS, replace=False)]
  f = fit(sub, overhang, overhang_sd, seed=seed, setback=radius, setback_sd=radius_sd)
  if f['residual'] > MAX_RESIDUAL:
    raise ValueError(
      f'{name}: the points over the edge lie {1000 * f["residual"]:.1f} mm (RMS) '
      f'from the best elastica of a {overhang} m overhang: not a strip hanging '
      'still (is --overhang its length past the edge?)'
    )
  if f['edge_mass'] > 0.05:
    raise ValueError(
      f'{name}: the strip is {f["ratio"]:.2g} bending lengths over the edge, '
      f'where the reading cannot bound its bending length '
      f'({RATIOS[0]:.2g}-{RATIOS[-1]:.2g}): slide '
      + ('more over' if f['ratio'] < 1 else 'some back')
    )
  return Reading(
    bending_length=f['c'], bending_length_sd=reading_sd(f['c_sd'], f['c']),
    bending_length_dof=DOF, fit_sd=f['c_sd'],
    overhang=f['length'], ratio=f['ratio'], reach=f['reach'], drop=f['drop'],
    residual_m=f['residual'], points=int(keep.sum()), face_points=face_points,
    camera_height_m=float(top.offset), profile=profile, edge_radius=radius,
    edge_radius_sd=radius_sd,
  )  # fmt: skip


def read_recording(path: str, camera_file: str, overhang: float,
                   overhang_sd: float = 0.001, depth_scale: float = 0.001,
                   seed: int = 0, known_radius: float | None = None
                   ) -> Reading:  # fmt: skip
  """``read`` of a depth recording as a camera's tools write it (a folder of
  16-bit PNG frames, an .npy/.npz or a video: ``physsim.video``) and its
  camera file (``physsim.camera_files``; frames of another size scale it,
  lens distortion is undone).

  Raises:
    ValueError: naming the file: unreadable, without absolute depth, or
      what ``read`` does not find in it.
  """
  if not camera_file:
    raise ValueError(f"{path}: needs its camera file (the depth camera's intrinsics)")
  cam = camera_files.read_camera(camera_file)
  recording = video.load_depth_video(path, fps=None, size=None, depth_scale=depth_scale)
  if recording.normalised:
    raise ValueError(f'{path}: frames without absolute depth (8-bit images?)')
  depth = recording.depth
  h, w = depth.shape[1:]
  if (w, h) != (cam.intrinsics.width, cam.intrinsics.height):
    cam = camera_files.scaled_to(cam, w, h)
  if cam.distorted:
    depth = camera_files.undistort(depth, cam)
  return read(depth, cam.intrinsics, overhang, overhang_sd, seed=seed, name=path,
              known_radius=known_radius)  # fmt: skip
