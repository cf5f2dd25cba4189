"""Physical parameters of one simulated fabric and the optimiser's [-1, 1]^3 box.

The search space is the paper's: bending 0.1x-10x of the material's measured
matrix, wind 1-6 m/s, and a per-material area-weight range (kg/m^2).

Normalisation (``to_unit`` / ``from_unit``), per field:
  * bending scale: log-uniform, ``u = 2 (log b - log lo) / (log hi - log lo) - 1``.
    For the default 0.1-10 range this is exactly ``u = log10(b)``: a factor of 10
    is as far as 0.1 -> 1, which is how stiffness errors are judged.
  * wind speed and area weight: linear, ``u = 2 (x - lo) / (hi - lo) - 1``.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from physsim import materials

FIELDS = ('bending_scale', 'wind_speed', 'area_weight')
UNITS = {'bending_scale': 'x measured', 'wind_speed': 'm/s', 'area_weight': 'kg/m^2'}
AIR_DENSITY = 1.0  # kg/m^3, ArcSim's wind model (physsim.forces)
GRAVITY = 9.81  # m/s^2


class Params(NamedTuple):
  """Physical parameters; each field a scalar or an array of one batch shape.

  Attributes:
    bending_scale: multiplier of the material's measured bending, (B,).
    wind_speed: mean flow speed of the fan's wind, m/s, (B,).
    area_weight: mass per area of the cloth, kg/m^2, (B,).
  """

  bending_scale: np.ndarray
  wind_speed: np.ndarray
  area_weight: np.ndarray


@dataclasses.dataclass(frozen=True)
class SearchSpace:
  """Allowed (low, high) range per field; ``log_bending`` picks the bending map.
  ``rigidity``: the fabric's reference bending rigidity D0 (N m) that bending
  scale 1 stands for (``cloth.reference_rigidity``; 0: a box of no fabric), so
  that a measured bending length can be read against bending and area weight."""

  bending_scale: tuple[float, float] = (0.1, 10.0)
  wind_speed: tuple[float, float] = (1.0, 6.0)
  area_weight: tuple[float, float] = (0.1, 0.37)
  log_bending: bool = True
  rigidity: float = 0.0

  def bounds(self) -> np.ndarray:
    """(3, 2) physical bounds in field order."""
    return np.array([getattr(self, f) for f in FIELDS], dtype=np.float64)

  def center(self) -> Params:
    """The trivial estimate: the middle of the normalised box (u = 0)."""
    return from_unit(np.zeros(3), self)


def search_space(fabric_name: str) -> SearchSpace:
  """The paper's search space for one of its seven fabrics (with its
  reference rigidity)."""
  from physsim import cloth  # noqa: PLC0415 (cloth imports MuJoCo)

  fabric = materials.fabric(fabric_name)
  return SearchSpace(
    area_weight=fabric.area_weight_range,
    rigidity=float(cloth.reference_rigidity(fabric.material)),
  )


def bending_length(bending_scale, area_weight, rigidity: float):
  """Peirce's bending length c = (D / (w g))^(1/3), m, of a fabric of bending
  ``bending_scale`` x ``rigidity`` (N m) and ``area_weight`` (kg/m^2): what a
  cantilever test measures (``physsim.cantilever``)."""
  d = np.asarray(bending_scale, np.float64) * rigidity
  return (d / (np.asarray(area_weight, np.float64) * GRAVITY)) ** (1.0 / 3.0)


def load_ratio(wind_speed, area_weight):
  """rho v^2 / (w g): wind pressure over cloth weight per area (dimensionless).

  A sheet's static shape depends on wind and area weight only through this
  ratio, so a video constrains it better than either (experiments.landscape).
  """
  v = np.asarray(wind_speed, np.float64)
  return AIR_DENSITY * v**2 / (np.asarray(area_weight, np.float64) * GRAVITY)


def make(bending_scale, wind_speed, area_weight) -> Params:
  """Params as float64 arrays broadcast to one shape."""
  b, w, a = np.broadcast_arrays(
    *(np.asarray(x, dtype=np.float64) for x in (bending_scale, wind_speed, area_weight))
  )
  return Params(b.copy(), w.copy(), a.copy())


def validate(params: Params, space: SearchSpace | None = None) -> Params:
  """Checks every field is finite, positive and inside ``space``.

  Raises:
    ValueError: naming the field, the offending value and the allowed range.
  """
  space = space or SearchSpace()
  params = make(*params)
  for name in FIELDS:
    value = getattr(params, name)
    lo, hi = getattr(space, name)
    bad = ~np.isfinite(value) | (value < lo * (1 - 1e-9)) | (value > hi * (1 + 1e-9))
    if np.any(bad):
      first = value.ravel()[np.flatnonzero(bad.ravel())[0]]
      raise ValueError(
        f'{name}={first!r} {UNITS[name]} is outside the allowed range '
        f'[{lo}, {hi}] (or not finite)'
      )
  return params


def _edges(space: SearchSpace, name: str) -> tuple[float, float, bool]:
  lo, hi = getattr(space, name)
  log = name == 'bending_scale' and space.log_bending
  return (np.log(lo), np.log(hi), True) if log else (lo, hi, False)


def to_unit(params: Params, space: SearchSpace | None = None) -> np.ndarray:
  """Maps validated physical params to the optimiser box, shape (..., 3)."""
  space = space or SearchSpace()
  params = validate(params, space)
  cols = []
  for name in FIELDS:
    lo, hi, log = _edges(space, name)
    x = getattr(params, name)
    x = np.log(x) if log else x
    cols.append(2.0 * (x - lo) / (hi - lo) - 1.0)
  return np.stack(cols, axis=-1)


def from_unit(u, space: SearchSpace | None = None) -> Params:
  """Maps points of [-1, 1]^3, shape (..., 3), to physical params.

  Raises:
    ValueError: if ``u`` has the wrong trailing size, is not finite or leaves
      the box (by more than rounding).
  """
  space = space or SearchSpace()
  u = np.asarray(u, dtype=np.float64)
  if u.shape[-1:] != (3,):
    raise ValueError(f'normalised params need a trailing axis of 3, got {u.shape}')
  if not np.all(np.isfinite(u)) or np.any(np.abs(u) > 1 + 1e-9):
    raise ValueError(f'normalised params must be finite and in [-1, 1], got {u}')
  u = np.clip(u, -1.0, 1.0)
  out = []
  for i, name in enumerate(FIELDS):
    lo, hi, log = _edges(space, name)
    x = lo + (u[..., i] + 1.0) * 0.5 * (hi - lo)
    out.append(np.exp(x) if log else x)
  return make(*out)


def unit_map(
  space: SearchSpace | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
  """``(lo, hi, log)`` per field, each (3,): the map ``from_unit_traced`` applies
  (bending's bounds are logs when ``space.log_bending``)."""
  space = space or SearchSpace()
  edges = [_edges(space, name) for name in FIELDS]
  lo, hi, log = (np.array(col) for col in zip(*edges, strict=True))
  return lo.astype(np.float64), hi.astype(np.float64), log.astype(bool)


def from_unit_traced(u, lo, hi, log):
  """``from_unit`` without checks, for inside ``jit``: ``u (..., 3)`` clipped to
  the box, with ``unit_map``'s arrays (which may carry leading batch axes).

  Returns:
    (..., 3) physical values in field order.
  """
  u = jnp.clip(u, -1.0, 1.0)
  x = lo + (u + 1.0) * 0.5 * (hi - lo)
  return jnp.where(log, jnp.exp(x), x)


def sample(rng: np.random.Generator, n: int, space: SearchSpace | None = None):
  """``n`` parameter sets uniform in the normalised box (log-uniform bending)."""
  return from_unit(rng.uniform(-1.0, 1.0, size=(n, 3)), space)
