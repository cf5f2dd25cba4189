"""A strip of fabric overhanging a table's edge: the heavy elastica.

The textile cantilever test (Peirce 1930; ASTM D1388) reads a fabric's bending
from how far a strip hangs when a length L of it overhangs a table's edge. A
strip of bending rigidity D (N m) and area weight w (kg/m^2), clamped flat at
the edge, takes the shape of the heavy elastica: with theta(s) its angle below
the horizontal at arc length s from the edge,

  D theta''(s) = -w g (L - s) cos theta(s),   theta(0) = 0,   theta'(L) = 0,

so its shape over L depends on L / c alone, c = (D / (w g))^(1/3) the bending
length. A small mass m taped to the strip (a coin: ``Load``) adds its weight
to the shear inboard of where it sits, and stiffens the span it covers (the
strip does not bend under a coin): the shape then depends on L / c and
m / (w b c) too, b the strip's width, so a coin of known mass could read the
area weight w (a Fisher bound, docs/studies/protocol.md, says how well: too
poorly to build a reader). ``tip`` solves it in float64 (RK4 from the free
end, bisection on the tip's angle; NumPy, vectorised over ratios): the
reference the simulator's overhang is checked against
(``experiments.studies.protocol_elastica``), and, inverted
(``bending_length``), what a measured overhang says about D.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from physsim.params import GRAVITY as G  # m/s^2

_STEPS = 200  # RK4 steps over the overhang: relative error below 1e-6
_BISECTIONS = 44  # on the tip's angle: to 1e-13 rad
# Beyond about five bending lengths the free part hangs nearly straight down:
# its shape hardly depends on c, and shooting from the free end loses the root
# (its angle is within float64's reach of vertical from 5.6 on).
MAX_RATIO = 5.0
MIN_RATIO = 0.05


@dataclasses.dataclass(frozen=True)
class Load:
  """A small mass taped to the strip near its free end, in units of the
  bending length c (each a float or an array broadcasting with the ratios).

  Attributes:
    mass: m / (w b c), the mass over that of a bending length of strip.
    at: its centre's distance from the free end, over c.
    span: the length of strip it stiffens (a coin's diameter), from the free
      end, over c; 0 for a point mass.
  """

  mass: float | np.ndarray = 0.0
  at: float | np.ndarray = 0.0
  span: float | np.ndarray = 0.0

  def carried(self) -> bool:
    """Whether any strip carries a mass or a stiffened span (a place alone
    changes nothing)."""
    return bool(np.any(np.asarray(self.mass)) or np.any(np.asarray(self.span)))


NO_LOAD = Load()


def _shoot(ratio: np.ndarray, alpha: np.ndarray, path: bool = False,
           load: Load = NO_LOAD, root_moment: bool = False):  # fmt: skip
  """From the free end (s = L, angle ``alpha``, no moment) back to the edge,
  in units of c: (theta(0), reach, droop), the last two over L; with
  ``path``, also the (steps + 1, ..., 2) centre line (reach, droop) over L
  from the edge (s = 0) to the free end (s = L); with ``root_moment``, last,
  the moment over D at the edge (its curvature times c). ``y[1]`` is the
  moment over D: it sets the curvature except under the load's span, where
  the strip stays straight."""
  h = ratio / _STEPS
  mass, at, span = (np.asarray(v, np.float64) for v in (load.mass, load.at, load.span))

  loaded = load.carried()

  def f(s, y):
    th, moment = y[0], y[1]
    if not loaded:  # the plain strip (the readers' many shots): no masks
      return np.stack([moment, -(ratio - s) * np.cos(th), np.cos(th), np.sin(th)])
    shear = (ratio - s) + np.where(s < ratio - at, mass, 0.0)
    bend = np.where(s < ratio - span, moment, 0.0)
    return np.stack([bend, -shear * np.cos(th), np.cos(th), np.sin(th)])

  y = np.stack(
    [alpha, np.zeros_like(alpha), np.zeros_like(alpha), np.zeros_like(alpha)]
  )
  s = ratio.copy()
  trail = [y[2:]]
  for _ in range(_STEPS):  # backwards: step -h
    k1 = f(s, y)
    k2 = f(s - h / 2, y - h / 2 * k1)
    k3 = f(s - h / 2, y - h / 2 * k2)
    k4 = f(s - h, y - h * k3)
    y = y - h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    s = s - h
    if path:
      trail.append(y[2:])
  # integrated backwards, x and z hold minus the integrals over [s, L]
  out = (y[0], -y[2] / ratio, -y[3] / ratio)
  if path:
    # from the edge: int_0^s = int_0^L - int_s^L, that is y(s) - y(0)
    xz = np.stack(trail[::-1])  # (steps + 1, 2, ...), s = 0 first
    out = (*out, np.moveaxis((xz - xz[:1]) / ratio, 1, -1))
  return (*out, y[1]) if root_moment else out


# A load's shot from a free end this close to vertical (rad) has lost its
# root to float64, as an unloaded strip's does beyond MAX_RATIO.
_VERTICAL_MARGIN = 1e-7


def _tip_angle(ratio: np.ndarray, load: Load = NO_LOAD) -> np.ndarray:
  """The free end's angle below the horizontal whose shot leaves the edge
  flat (bisection: theta(0) rises with it).

  Raises:
    ValueError: a ratio that is not positive and finite, a load that is
      negative or not finite, or a loaded strip that hangs too nearly
      straight down for its shape to be solved.
  """
  if not np.all(np.isfinite(ratio) & (ratio > 0) & (ratio <= MAX_RATIO)):
    raise ValueError(
      f'need overhangs of 0 to {MAX_RATIO:g} bending lengths, got {ratio}'
    )
  loaded = load.carried()
  if loaded:
    mass, at, span = (
      np.asarray(v, np.float64) for v in (load.mass, load.at, load.span)
    )
    if not (np.all(np.isfinite(mass) & (mass >= 0)) and np.all(np.isfinite(at) & (at >= 0))
            and np.all(np.isfinite(span) & (span >= 0) & (span < ratio))):  # fmt: skip
      raise ValueError(
        f'a load needs a finite mass >= 0, a place >= 0 from the free end and '
        f'a span shorter than the overhang (units of c), got {load}'
      )
  lo, hi = np.zeros_like(ratio), np.full_like(ratio, np.pi / 2)
  for _ in range(_BISECTIONS):
    mid = (lo + hi) / 2
    above = _shoot(ratio, mid, load=load)[0] > 0
    hi = np.where(above, mid, hi)
    lo = np.where(above, lo, mid)
  alpha = (lo + hi) / 2
  if loaded:
    # a heavy load's shot can also leave the edge flat after a loop: the
    # strip's root is the one whose every point lies out and down from the
    # last (its angle within [0, pi / 2] all along)
    xz = _shoot(ratio, alpha, path=True, load=load)[3]
    step = np.diff(xz, axis=0)
    looped = np.any(step < -1e-9, axis=(0, 2))
    if np.any(looped | (alpha > np.pi / 2 - _VERTICAL_MARGIN)):
      raise ValueError(
        f'a strip of {np.max(ratio):.3g} bending lengths under a load of '
        f'{np.max(load.mass):.3g} hangs too nearly straight down to be solved: '
        'a shorter overhang or a lighter load'
      )
  return alpha


def tip(ratio, load: Load = NO_LOAD) -> tuple[np.ndarray, np.ndarray]:
  """The free end of a strip overhanging by ``ratio`` = L / c bending lengths:
  its horizontal reach from the edge and its drop below the table, each over
  L (``ratio`` -> 0: reach 1, drop (L/c)^3 / 8; large: reach 0, drop 1);
  under ``load`` (its fields broadcasting with ``ratio``), a coin's.

  Raises:
    ValueError: a ratio that is not positive and finite, or a load
      ``_tip_angle`` refuses.
  """
  ratio, load = _broadcast(ratio, load)
  _, reach, droop = _shoot(ratio, _tip_angle(ratio, load), load=load)
  return reach, droop


def shape(ratio, load: Load = NO_LOAD) -> np.ndarray:
  """The strip's centre line: (..., _STEPS + 1, 2) points (reach, drop), each
  over L, at equal steps of arc length from the edge (0, 0) to the free end
  (``tip``), for overhangs of ``ratio`` = L / c bending lengths under
  ``load`` (any shape; the load's fields broadcast with it).

  Raises:
    ValueError: a ratio that is not positive and finite, or a load
      ``_tip_angle`` refuses.
  """
  shape_ = np.broadcast_shapes(
    np.shape(ratio), *(np.shape(v) for v in dataclasses.astuple(load))
  )
  flat, load = _broadcast(ratio, load)
  xz = _shoot(flat, _tip_angle(flat, load), path=True, load=load)[
    3
  ]  # (steps + 1, R, 2)
  return np.moveaxis(xz, 0, 1).reshape(*shape_, _STEPS + 1, 2)


_LEAVING_BISECTIONS = 32  # on the free end's angle: to 4e-10 rad


def leaving(ratio, angle) -> tuple[np.ndarray, np.ndarray]:
  """A strip that leaves its support at ``angle`` (rad below the horizontal,
  0 to pi / 2; each broadcasting with ``ratio`` = L / c of its free part): the
  centre line of its free part, (..., _STEPS + 1, 2) points (reach, drop)
  over L from where it leaves, and its curvature there times c (what it asks
  of the support: over a rounded edge of radius R it leaves where this is
  c / R). ``angle`` 0 is ``shape``'s flat clamp.

  Raises:
    ValueError: a ratio that is not within (0, ``MAX_RATIO``] or an angle
      outside [0, pi / 2).
  """
  ratio, angle = np.broadcast_arrays(
    np.asarray(ratio, np.float64), np.asarray(angle, np.float64)
  )
  shape_ = ratio.shape
  ratio, angle = np.atleast_1d(ratio).ravel(), np.atleast_1d(angle).ravel()
  if not np.all(np.isfinite(ratio) & (ratio > 0) & (ratio <= MAX_RATIO)):
    raise ValueError(
      f'need overhangs of 0 to {MAX_RATIO:g} bending lengths, got {ratio}'
    )
  if not np.all((angle >= 0) & (angle < np.pi / 2)):
    raise ValueError(f'need angles of 0 to pi / 2, got {angle}')
  lo, hi = angle.copy(), np.full_like(ratio, np.pi / 2)  # the free end's angle
  for _ in range(_LEAVING_BISECTIONS):
    mid = (lo + hi) / 2
    above = _shoot(ratio, mid)[0] > angle
    hi = np.where(above, mid, hi)
    lo = np.where(above, lo, mid)
  _, _, _, xz, moment = _shoot(ratio, (lo + hi) / 2, path=True, root_moment=True)
  return np.moveaxis(xz, 0, 1).reshape(*shape_, _STEPS + 1, 2), moment.reshape(shape_)


def _broadcast(ratio, load: Load) -> tuple[np.ndarray, Load]:
  """The ratios and the load's fields broadcast together, flattened to 1-D
  float64 (at least one element)."""
  arrays = np.broadcast_arrays(
    np.asarray(ratio, np.float64),
    *(np.asarray(v, np.float64) for v in dataclasses.astuple(load)),
  )
  flat = [np.atleast_1d(a).ravel().copy() for a in arrays]
  return flat[0], Load(*flat[1:])


@functools.cache
def _reach_table() -> tuple[np.ndarray, np.ndarray]:
  """(ratios, reaches over L): the coarse table ``bending_length`` brackets
  a reading in before refining (computed once: half a second)."""
  grid = np.geomspace(MIN_RATIO, MAX_RATIO, 120)
  return grid, tip(grid)[0]


@functools.lru_cache(maxsize=1024)
def bending_length(overhang: float, reach: float) -> float:
  """The bending length c (m) of a strip overhanging by ``overhang`` (m) whose
  free end reaches ``reach`` (m) out from the edge (kept for repeated
  readings: each solve takes about half a second).

  Raises:
    ValueError: a reach outside what overhangs of ``MIN_RATIO`` to
      ``MAX_RATIO`` bending lengths give (a strip hanging straight down says
      nothing about c; a stiff one hardly droops).
  """
  grid, reaches = _reach_table()  # reaches fall as the ratio rises
  if not (overhang > 0 and reaches[-1] < reach / overhang < reaches[0]):
    raise ValueError(
      f'a reach of {reach} m over an overhang of {overhang} m: need between '
      f'{reaches[-1] * overhang:.3g} and {reaches[0] * overhang:.3g} m '
      f'({MIN_RATIO:g}-{MAX_RATIO:g} bending lengths)'
    )
  k = int(
    np.searchsorted(-reaches, -reach / overhang)
  )  # reaches[k-1] > r >= reaches[k]
  fine = np.geomspace(grid[k - 1], grid[k], 120)
  log_ratio = np.interp(-reach / overhang, -tip(fine)[0], np.log(fine))
  return float(overhang / np.exp(log_ratio))


def rigidity(length: float, area_weight: float) -> float:
  """D = w g c^3 (N m) of a bending length ``length`` (m) and an area weight
  (kg/m^2)."""
  return float(area_weight * G * length**3)


def bending_length_sd(
  overhang: float, reach: float, reach_sd: float, overhang_sd: float = 0.0
) -> tuple[float, float]:
  """(c, its standard uncertainty) in metres from a ruler's reading of an
  overhang: ``bending_length`` of the readings, and the spread a ruler's
  standard uncertainties on the reach and the overhang (independent) give it,
  each by a secant over +-1 sd through the elastica (first order, but over the
  reading's own scale rather than an infinitesimal step: at short overhangs c
  is steep in the reach).

  Raises:
    ValueError: a negative or non-finite sd, or a reading within one sd of
      the range ``bending_length`` takes (the reading cannot bound c there).
  """
  for name, v in (('reach_sd', reach_sd), ('overhang_sd', overhang_sd)):
    if not (np.isfinite(v) and v >= 0):
      raise ValueError(f'{name} must be finite and >= 0, got {v}')
  c = bending_length(overhang, reach)
  var = 0.0
  for d_overhang, d_reach in ((overhang_sd, 0.0), (0.0, reach_sd)):
    if not (d_overhang or d_reach):
      continue
    try:
      up = bending_length(overhang + d_overhang, reach + d_reach)
      down = bending_length(overhang - d_overhang, reach - d_reach)
    except ValueError:
      raise ValueError(
        f'a reach of {reach} m over {overhang} m is within one sd '
        f'({max(d_overhang, d_reach)} m) of a strip that hangs straight down or '
        f'hardly droops ({MIN_RATIO:g}-{MAX_RATIO:g} bending lengths): the reading '
        f'cannot bound the bending length'
      ) from None
    var += ((up - down) / 2) ** 2
  return c, float(np.sqrt(var))
