"""The heavy elastica fitted to a strip's profile: what ``physsim.overhang_depth``
reads a bending length with, once the strip's (reach, drop) points are found.

The curve gives the strip's shape, L / c, and the ruler its length (``fit``).
The elastica's shapes are shot once per process (``cantilever.shape``, the
slow part of a reading) on a coarse grid of L / c and, around the best of
it, a fine one; each point's signed distance to each curve gives a
posterior over L / c, and with the ruler's L and the edge's rounding (the
strip bends from that far behind the face) a posterior over c.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from physsim import cantilever

RATIOS = np.geomspace(0.2, cantilever.MAX_RATIO, 160)  # L / c fitted
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
  """The curves of ``RATIOS`` (``_curve_set``), made once per process."""
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


LIFT_STEPS = 4


def _root_lift(few, overhang: float, setback: float, point_sd) -> np.ndarray:
  """The (reach, drop) shift that puts the strip's centre line's root on the
  top's plane: the centre line rests half the strip's thickness above the
  top, and the seen face lies the same offset off it along its normal (the
  fitted offset, ``_misfit``). A normal offset alone leaves the root half a
  thickness high, which the curve's shape took up as a softer strip (c 2-4%
  low at 1.5 mm of a soft strip's thickness). The lift is where the offset
  fitted to the lifted points equals it (a few halved steps from none)."""
  lift = 0.0
  for _ in range(LIFT_STEPS):
    _, _, _, offset = _posterior(
      few + np.array([0.0, lift]), overhang + setback, RATIOS, _coarse_curves(),
      point_sd, setback,
    )  # fmt: skip
    lift = 0.5 * (lift + max(offset, 0.0))
  return np.array([0.0, lift])


def fit(profile: np.ndarray, overhang: float, overhang_sd: float,
        point_sd: float | None = None, seed: int = 0, setback: float = 0.0,
        setback_sd: float = 0.0) -> dict:  # fmt: skip
  """The elastica fitted to (N, 2) (reach, drop) points, m, from the front
  face's plane and the top's.

  The curve gives the strip's shape, L / c, and the ruler its length: L is
  Gaussian (``overhang`` +- ``overhang_sd``; exact when the sd is 0), the
  shape is fitted at each of its nodes, and c = L / (L / c) over both. The
  shape at a longer L than the strip's is a stiffer one (the seen curve's
  root, in metres, holds c), so c moves with about two thirds of L's
  relative error, not all of it: a shape fitted at the given L alone read
  c's sd half again too wide. The curve is not let refine L: what scales it
  besides L (the sensor's noise along its rays, the strip's thickness, curl,
  and fibres of unequal overhang when it lies askew) moved a refined L by
  3-8% on short strips, more than the ruler's 1 mm, and c with it
  (docs/studies/protocol.md, "Limits"). On a rounded edge the strip bends from
  ``setback`` behind the face (the rounding's radius, Gaussian with sd
  ``setback_sd``, at three nodes): the elastica starts there, flat, its
  free length L + setback, and c = (L + setback) / (its L / c). L / c is
  log-uniform over ``RATIOS``; the seen face lies at an unknown offset from
  the centre line (fitted, within ``OFFSET_RANGE``), and the centre line's
  root as far above the top (``_root_lift``). Each point's distance
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
  shift = _root_lift(few, overhang, setback, point_sd)
  profile, few = profile + shift, few + shift
  p, j, _, _ = _posterior(
    few, overhang + setback, RATIOS, _coarse_curves(), point_sd, setback
  )
  edge_mass = float(p[:2].sum() + p[-2:].sum())
  ratios, curves = _fine_grid(j)
  ls, weight = _ruler(overhang, overhang_sd)
  nodes, node_weight = _setbacks(setback, setback_sd)
  c, joint = [], []
  for k, (back, w) in enumerate(zip(nodes, node_weight, strict=True)):
    # (L, R): L / c's posterior at each of the ruler's L, at this setback
    # (the ruler's L is one of its nodes: the best fit is reported there)
    post = [
      _posterior(profile, length + back, ratios, curves, point_sd, back)
      for length in ls
    ]  # fmt: skip
    if k == len(nodes) // 2:
      _, j, residual, offset = post[int(np.argmin(np.abs(ls - overhang)))]
    joint.append(w * weight[:, None] * np.stack([q[0] for q in post]))
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
