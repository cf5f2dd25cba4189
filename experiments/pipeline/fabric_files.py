"""An estimate's fabric as files another simulation loads (``experiments.export``).

From an estimate's workdir (one recording's ``estimate.json`` and
``posterior.npz``, or a joint estimate's ``joint.json`` and
``joint_posterior.npz``) this writes, atomically:

- ``fabric.xml``: MuJoCo MJCF of a pinned square sheet at the estimate's point
  (``physsim.export.mujoco_xml``; load it with ``physsim.export.load`` for the
  estimator's edges), its provenance in a comment;
- ``fabric_arcsim.json``: the ArcSim material at that point, with ArcSim's
  licence beside it (``LICENSE_ARCSIM.txt``: its data's terms ask for it);
- ``fabric_draws.csv``: posterior draws of bending and area weight, for a
  simulation that randomises over what the recordings left open;
- ``fabric.json``: what was written, from what, with the point and the
  intervals.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

import physsim
from experiments.pipeline import files, layout
from experiments.pipeline import posterior as posterior_lib
from physsim import export

FABRIC_FILE = 'fabric.json'
MJCF_FILE = 'fabric.xml'
ARCSIM_FILE = 'fabric_arcsim.json'
DRAWS_FILE = 'fabric_draws.csv'
LICENSE_FILE = 'LICENSE_ARCSIM.txt'
# The estimate's files it reads: one recording's, else a joint's.
_SOURCES = (layout.ESTIMATE_FILE, layout.JOINT_FILE)
_NAMES = ('bending_scale', 'area_weight')


@dataclasses.dataclass(frozen=True)
class Point:
  """What an estimate says of its fabric.

  Attributes:
    source: the file read.
    material: the fabric.
    bending_scale, area_weight: the estimate's point.
    intervals: each parameter's 90% interval.
    cloth_size, cloth_resolution, fps: the estimate's sheet and clock.
  """

  source: str
  material: str
  bending_scale: float
  area_weight: float
  intervals: dict
  cloth_size: float
  cloth_resolution: int
  fps: float


def read_point(workdir: str) -> Point:
  """The fabric an estimate's workdir holds (its ``estimate.json``, else a
  joint's ``joint.json``).

  Raises:
    ValueError: neither file, or one without the fabric's parameters (named).
  """
  path = next(
    (p for p in (os.path.join(workdir, f) for f in _SOURCES) if os.path.isfile(p)),
    None,
  )
  if path is None:
    raise ValueError(
      f"{workdir}: no {' or '.join(_SOURCES)} (an estimate's workdir, written by "
      'experiments.estimate)'
    )
  data = physsim.dataset.read_json(path)
  shared = data.get('estimate', data)  # a joint's are at the top
  config = data.get('config', {})
  try:
    entries = {k: shared[k] for k in _NAMES}
    point = {k: float(e.get('value', e['median'])) for k, e in entries.items()}
    intervals = {k: [float(v) for v in e['interval_90']] for k, e in entries.items()}
    return Point(
      source=path,
      material=str(data['material']),
      intervals=intervals,
      cloth_size=float(config.get('cloth_size', 1.0)),
      cloth_resolution=int(config.get('cloth_resolution', 25)),
      fps=float(config.get('fps', 20.0)),
      **point,
    )
  except (KeyError, TypeError, ValueError) as e:
    raise ValueError(
      f'{path}: no bending and area weight estimate in it ({e!r})'
    ) from e


def write(
  workdir: str,
  out: str,
  *,
  draws: int = 200,
  cloth_size: float = 0.0,
  resolution: int = 0,
  seed: int = 0,
) -> dict:
  """Writes the fabric of the estimate in ``workdir`` into ``out`` (module
  doc); returns ``fabric.json``'s record.

  Args:
    workdir: an estimate's workdir.
    out: where the files go (made if missing).
    draws: posterior draws in ``fabric_draws.csv`` (0: none; an estimate
      without saved draws, the paper's argmin, writes none).
    cloth_size, resolution: the exported sheet's side (m) and vertices a
      side (0: the estimate's own).
    seed: which of the saved draws (a random subset when it holds more).

  Raises:
    ValueError: a workdir without an estimate, a bad size, or a point out
      of range (named).
  """
  point = read_point(workdir)
  size = cloth_size or point.cloth_size
  n = resolution or point.cloth_resolution
  mesh = physsim.square(n, size)  # checks the size and resolution
  config = physsim.config_for_mesh(mesh, point.fps)
  b, w = point.bending_scale, point.area_weight
  iv = {
    k: '[' + ', '.join(f'{v:.3g}' for v in i) + ']' for k, i in point.intervals.items()
  }
  lines = [
    f'{point.material}: bending scale {b:.6g} (90% {iv["bending_scale"]}), '
    f'area weight {w:.6g} kg/m^2 (90% {iv["area_weight"]})',
    f'from {os.path.abspath(point.source)}; a {size:g} m sheet, {n} x {n} vertices, '
    'pinned at its top corners; no air (add your own wind)',
    'load with physsim.export.load (or copy the custom numeric '
    f"{export.INVWEIGHT_KEY} into flexedge_invweight0) for the estimator's edges",
  ]
  xml = export.mujoco_xml(mesh, point.material, b, w, config, comment='; '.join(lines))
  arcsim = export.arcsim_material(point.material, b, w)
  os.makedirs(out, exist_ok=True)
  written = {}
  path = os.path.join(out, MJCF_FILE)
  files.write_text(path, xml)
  written['mujoco'] = path
  path = os.path.join(out, ARCSIM_FILE)
  files.write_json(path, arcsim)
  written['arcsim'] = path
  files.write_text(os.path.join(out, LICENSE_FILE), physsim.materials.license_text())
  table = _draws(workdir, point.material, draws, seed) if draws > 0 else None
  if table is not None:
    path = os.path.join(out, DRAWS_FILE)
    files.write_text(path, table)
    written['draws'] = path
  record = {
    'source': os.path.abspath(point.source),
    'material': point.material,
    'point': {'bending_scale': b, 'area_weight': w},
    'interval_90': point.intervals,
    'bending_rigidity_Nm': b * physsim.reference_rigidity(point.material),
    'young_Pa': export.young_modulus(b, point.material),
    'sheet': {'size_m': size, 'resolution': n, 'timestep': config.timestep},
    'files': written,
  }
  files.write_json(os.path.join(out, FABRIC_FILE), record)
  return record


def _draws(workdir: str, material: str, n: int, seed: int) -> str | None:
  """``fabric_draws.csv``'s text: up to ``n`` of the saved posterior draws,
  each with the rigidity and Young's modulus its scale means; None where the
  estimate kept no draws."""
  try:
    _, log_draws, _ = posterior_lib.read_draws(workdir)
  except ValueError:
    return None
  rng = np.random.default_rng(seed)
  pick = rng.permutation(len(log_draws))[: min(n, len(log_draws))]
  d0 = physsim.reference_rigidity(material)
  rows = ['bending_scale,bending_rigidity_Nm,young_Pa,area_weight_kg_m2']
  for lb, lw in log_draws[pick]:
    s = float(np.exp(lb))
    rows.append(
      f'{s:.6g},{s * d0:.6g},{export.young_modulus(s, material):.6g},{np.exp(lw):.6g}'
    )
  return '\n'.join(rows) + '\n'
