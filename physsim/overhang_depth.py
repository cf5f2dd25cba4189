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
4. the top's plane is fitted again beside the strip (the strip lying on it
   raises it), and the edge's rounding fitted to the table's points there
   (``edge_radius``), each point's distance to the rounded section taken
   along its camera ray, where a depth camera errs (the nearest distance
   let a sharp corner explain the noise and read 1-2 mm roundings at half
   their size): a strip bends from where the rounding starts, about its
   radius behind the face (``physsim.tabletop``);
5. the heavy elastica of overhang L + radius over bending length c, flat
   where the rounding starts, its root half the strip's thickness above the
   top (the seen face's fitted offset), is fitted to those pairs (each
   point's distance to the curve) on a grid of L / c at the given L; with
   L's ruler uncertainty and the radius's posterior, the posterior of c.
   The curve reads the strip's shape, the ruler its length.

Using the whole curve rather than the tip alone keeps the reading off the
places a depth camera sees worst: the strip's outline (where sensors drop
pixels at depth jumps) and its free end. The fit's spread is the ruler's
share of c (about two thirds of L's sd over L: 1 mm is 1-5% of a 2-12 cm
overhang) and the shape's, which shrinks with the number of pixels; what the fit does not see
(the strip's curl and thickness, the angle it leaves the edge at, the
camera's noise pattern) would be a ``FLOOR`` on c's relative uncertainty,
and the t law's tails. A reading is a Student's t of ``DOF`` degrees of
freedom, its scale the fit's spread and the floor in quadrature: both set
on simulated set-ups (so that its 25-90% intervals hold as often as they
say; ``benchmarks.overhang_check --tune``, the ray-caster) and checked on
others (``benchmarks.overhang_check``, MuJoCo's OpenGL renderer).

Steps 1, 2 and 4 (the table, its edge and its rounding) are in
``physsim.overhang_table``, step 5 (the elastica's fit) in ``physsim.overhang_fit``;
here the strip is found (step 3) and the reading made.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from physsim import camera_files, overhang_table, video
from physsim import scene as scene_lib
from physsim.camera import Intrinsics
from physsim.overhang_fit import RATIOS, fit

# m: the strip's points in front of the face by more than this (a soft strip
# on a rounded edge hangs 2-4 mm in front of it)
STRIP_OUT = 0.002
MIN_STRIP_POINTS = 60
MAX_FIT_POINTS = 800  # subsampled for the fit (its law was fitted so)
MAX_RESIDUAL = 0.004  # m, RMS: points further from any elastica are not a strip

# c's error law: Student's t of DOF degrees of freedom, its scale the fit's
# spread (the ruler's L and the curve's L / c) and FLOOR (relative: what the
# fit cannot see) in quadrature (``benchmarks.overhang_depth``: fitted on its
# calibration set-ups, seed 0, so that its 25, 50, 75 and 90% intervals hold
# c as often as they say; checked on others). Fitted on 2026-11-29 for the
# protocol's overhang of about three bending lengths: a t of 10, no floor
# (the ruler's 1 mm, at least 0.8% of a strip up to 12 cm, is in the spread).
# Before, at Peirce's two bending lengths: a t of 4 with a 0.8% floor.
# Kept with the edge's rounding in the reading (issue 77): on the 60 tuning
# set-ups of ``benchmarks.overhang_check --tune`` (real tables: rounded edges,
# curl, askew, flying pixels, depth-scale bias), with the shape fitted at each
# of the ruler's L (c moves with about two thirds of L's error), its 90% / 50%
# intervals held 93% / 47% and the fitted law is this one again; checked on
# MuJoCo's renders (BENCHMARKS).
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


def _depth_frame(depth, intrinsics: Intrinsics, overhang: float,
                 overhang_sd: float, name: str) -> np.ndarray:  # fmt: skip
  """The (H, W) frame ``read`` measures: the frames' per-pixel median, its
  size checked against the camera's, with the overhang and its ruler sd.

  Raises:
    ValueError: naming ``name`` or the flag: frames of another size, an
      overhang outside (0, 0.5] m, a ruler sd of a third of it or more.
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
  return depth


def _strip(valid: np.ndarray, edge: overhang_table.Edge, name: str) -> np.ndarray:
  """(N,) the strip's points among the ``valid`` pixels': the largest
  8-connected patch of those under the top and more than ``STRIP_OUT`` in
  front of the face.

  Raises:
    ValueError: naming ``name``: no such patch, or one under
      ``MIN_STRIP_POINTS`` pixels.
  """
  strip = edge.below & (edge.out > STRIP_OUT)
  mask = np.zeros(valid.shape, np.uint8)
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
  return keep


def _checked_fit(profile: np.ndarray, overhang: float, overhang_sd: float,
                 seed: int, rng, radius: float, radius_sd: float,
                 name: str) -> dict:  # fmt: skip
  """``fit`` of the strip's profile (at most ``MAX_FIT_POINTS`` of it, drawn
  by ``rng``), refused where the points are no elastica's or c is unbounded.

  Raises:
    ValueError: naming ``name``: points over ``MAX_RESIDUAL`` (RMS) from
      the best curve, or the posterior's mass at the ends of ``RATIOS``.
  """
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
  return f


def read(depth: np.ndarray, intrinsics: Intrinsics, overhang: float,
         overhang_sd: float = 0.001, seed: int = 0, name: str = 'the recording',
         known_radius: float | None = None) -> Reading:  # fmt: skip
  """The bending length of the strip in (H, W) or (T, H, W) depth frames, m
  (0 invalid), filmed by a camera of ``intrinsics``, with ``overhang`` (m)
  of it past the front face of the table's top (ruler sd ``overhang_sd``);
  the edge's rounding fitted (``overhang_table.edge_radius``) or ``known_radius`` (m: 0
  for a sharp edge).

  Raises:
    ValueError: naming ``name`` and what was not found (the table, its front
      face, a strip) or why the fit cannot bound c.
  """
  depth = _depth_frame(depth, intrinsics, overhang, overhang_sd, name)
  valid = np.isfinite(depth) & (depth > 0)
  if valid.sum() < 1000:
    raise ValueError(
      f'{name}: {int(valid.sum())} valid depth pixels; need a table in view'
    )
  flat = scene_lib.backproject(depth, intrinsics)[valid]
  rng = np.random.default_rng(seed)
  top, edge = overhang_table.find_edge(flat, overhang, seed, rng, name)
  keep = _strip(valid, edge, name)
  top, edge = overhang_table.top_beside(flat, top, edge, keep, overhang, rng, name)
  keep = _strip(valid, edge, name)
  profile = np.stack([edge.out[keep], -edge.height[keep]], axis=1)
  radius, radius_sd = overhang_table.rounding(edge, keep, known_radius)
  f = _checked_fit(profile, overhang, overhang_sd, seed, rng, radius, radius_sd, name)
  return Reading(
    bending_length=f['c'], bending_length_sd=reading_sd(f['c_sd'], f['c']),
    bending_length_dof=DOF, fit_sd=f['c_sd'],
    overhang=f['length'], ratio=f['ratio'], reach=f['reach'], drop=f['drop'],
    residual_m=f['residual'], points=int(keep.sum()), face_points=edge.face_points,
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
