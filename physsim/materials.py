"""ArcSim measured cloth materials (Wang et al. 2011) and the paper's seven fabrics.

The JSON files in ``physsim/data/arcsim_materials`` are verbatim ArcSim 0.2.1 data,
distributed under ``LICENSE_ARCSIM.txt`` (shown by ``license_text()``).

Units (ArcSim source): ``density`` is area density in kg/m^2; ``stretching`` is a 6x4
table in N/m; ``bending`` is a 3x5 table in N*m, rows = hinge direction 0/45/90
degrees, columns = curvature samples 0, 5, 10, 15, 20 m^-1.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import json

import numpy as np

_DATA = 'data/arcsim_materials'

# Curvature of bending column j, in 1/m (ArcSim dde.cpp: "samples are per 5 m^-1").
BENDING_CURVATURES = np.array([0.0, 5.0, 10.0, 15.0, 20.0])
# Hinge direction of bending row i, in degrees.
BENDING_ANGLES = np.array([0.0, 45.0, 90.0])


@dataclasses.dataclass(frozen=True)
class Material:
  """One ArcSim material.

  Attributes:
    name: file stem, e.g. ``'gray-interlock'``.
    density: area weight, kg/m^2.
    stretching: (6, 4) stretching samples, N/m.
    bending: (3, 5) bending samples, N*m.
  """

  name: str
  density: float
  stretching: np.ndarray
  bending: np.ndarray


@dataclasses.dataclass(frozen=True)
class Fabric:
  """One of the paper's seven fabrics.

  Attributes:
    name: the paper's name in snake case, e.g. ``'white_tablecloth'``.
    material: the ArcSim material it maps to (SOURCE.md gives the evidence).
    area_weight_range: (low, high) search range in kg/m^2, the paper's Table.
    real_area_weight: the paper's measured real area weight, kg/m^2.
  """

  name: str
  material: str
  area_weight_range: tuple[float, float]
  real_area_weight: float


FABRICS: dict[str, Fabric] = {
  f.name: f
  for f in (
    Fabric('white_tablecloth', 'white-dots-on-blk', (0.10, 0.17), 0.140),
    Fabric('gray_interlock', 'gray-interlock', (0.15, 0.22), 0.184),
    Fabric('black_denim', '11oz-black-denim', (0.30, 0.37), 0.328),
    Fabric('sparkle_fleece', 'navy-sparkle-sweat', (0.23, 0.30), 0.270),
    Fabric('pink_nylon', 'white-swim-solid', (0.16, 0.23), 0.195),
    Fabric('ponte_roma', 'camel-ponte-roma', (0.23, 0.30), 0.264),
    Fabric('red_violet', 'tango-red-jet-set', (0.10, 0.17), 0.144),
  )
}


def _files():
  return importlib.resources.files('physsim').joinpath(_DATA)


def material_names() -> list[str]:
  """Names of every shipped ArcSim material."""
  return sorted(
    p.name[: -len('.json')] for p in _files().iterdir() if p.name.endswith('.json')
  )


@functools.cache
def load_material(name: str) -> Material:
  """Loads an ArcSim material by file stem or by the paper's fabric name.

  Args:
    name: e.g. ``'gray-interlock'`` or ``'gray_interlock'``.

  Returns:
    The validated material.

  Raises:
    ValueError: unknown name, or a file whose tables have the wrong shape or
      non-finite or negative density.
  """
  stem = FABRICS[name].material if name in FABRICS else name
  path = _files().joinpath(f'{stem}.json')
  if not path.is_file():
    raise ValueError(
      f'unknown material {name!r}; fabrics: {sorted(FABRICS)}, '
      f'materials: {material_names()}'
    )
  raw = json.loads(path.read_text())
  density = float(raw['density'])
  stretching = np.asarray(raw['stretching'], dtype=np.float64)
  bending = np.asarray(raw['bending'], dtype=np.float64)
  if stretching.shape != (6, 4) or bending.shape != (3, 5):
    raise ValueError(
      f'{path}: expected stretching (6, 4) and bending (3, 5), got '
      f'{stretching.shape} and {bending.shape}'
    )
  if not (np.isfinite(density) and density > 0 and np.all(np.isfinite(bending))):
    raise ValueError(f'{path}: density and bending must be finite, density > 0')
  return Material(stem, density, stretching, bending)


def fabric(name: str) -> Fabric:
  """The paper's fabric by name; raises ValueError naming the choices."""
  if name not in FABRICS:
    raise ValueError(f'unknown fabric {name!r}; choose one of {sorted(FABRICS)}')
  return FABRICS[name]


def license_text() -> str:
  """ArcSim's licence, which must accompany the material data."""
  return _files().joinpath('LICENSE_ARCSIM.txt').read_text()
