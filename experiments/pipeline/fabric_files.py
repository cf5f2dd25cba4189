"""An estimate's fabric as files another simulation loads (``experiments.export``).

From an estimate's workdir (one recording's ``estimate.json`` and
``posterior.npz``, or a joint estimate's ``joint.json`` and
``joint_posterior.npz``) this writes, all of them or none (made in a
temporary folder beside ``out``, then renamed into place):

- ``fabric.xml``: MuJoCo MJCF of a pinned square sheet of the user's mesh
  (``physsim.export.mujoco_xml``; load it with ``physsim.export.load`` for the
  estimator's edges) whose bending is the one that mesh needs to hang as the
  measured fabric does (``physsim.mesh_fit``: a cantilever strip of its spacing
  simulated until it reaches as far as the elastica of the measured bending
  length); its masses from the area weight; the mesh in its name and comment;
- ``fabric_arcsim.json``: the ArcSim material (ArcSim's own units, no mesh),
  with ArcSim's licence beside it (``LICENSE_ARCSIM.txt``: its data's terms);
- ``fabric_draws.csv``: posterior draws in physical units and as the flex's
  scale at this mesh, for a simulation that randomises over what the
  recordings left open;
- ``fabric.json``: the fabric in the units a lab reports (bending rigidity in
  uN m, bending length in mm, area weight in g/m^2), the mesh it was made for,
  the fit, the internal bending scales (labelled), what was written and from
  what.

Everything read is checked finite and in range, and everything written too:
a corrupt or incomplete estimate is refused naming its file.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import shutil
import tempfile

import numpy as np

import physsim
from experiments.pipeline import files, layout
from physsim import export, mesh_fit

FABRIC_FILE = 'fabric.json'
MJCF_FILE = 'fabric.xml'
ARCSIM_FILE = 'fabric_arcsim.json'
DRAWS_FILE = 'fabric_draws.csv'
LICENSE_FILE = 'LICENSE_ARCSIM.txt'
ALL_FILES = (MJCF_FILE, ARCSIM_FILE, LICENSE_FILE, DRAWS_FILE, FABRIC_FILE)
# The estimate's files it reads: one recording's, else a joint's.
_SOURCES = (layout.ESTIMATE_FILE, layout.JOINT_FILE)
_NAMES = ('bending_scale', 'area_weight')

# What is read and written is refused outside these: beyond them a number is
# a corrupt file or a typo, never a fabric (kg/m^2: tissue paper to a heavy
# canvas; the estimate's own cloth sizes, meshes and rates).
AREA_WEIGHT_RANGE = (0.005, 5.0)
BENDING_SCALE_RANGE = (1e-4, 1e4)
CLOTH_SIZE_RANGE = (0.05, 3.0)
RESOLUTION_RANGE = (3, 200)
FPS_RANGE = (1.0, 240.0)
MAX_DRAWS = 100_000


def out_dir(workdir: str, resolution: int) -> str:
  """The default folder of an export: ``<workdir>/fabric_<n>x<n>`` (named by
  the mesh it was made for)."""
  return os.path.join(workdir, f'fabric_{resolution}x{resolution}')


@dataclasses.dataclass(frozen=True)
class Point:
  """What an estimate says of its fabric.

  Attributes:
    source: the file read.
    material: the fabric.
    bending_scale, area_weight: the estimate's point (the scale: times the
      material's reference rigidity, ``physsim.reference_rigidity``).
    intervals: each parameter's 90% interval.
    cloth_size, cloth_resolution, fps: the estimate's sheet and clock.
    air: the fabric's air coefficient and its 90% interval where the estimate
      read one (``measurements``; the normal wind pressure over an ArcSim
      sheet's), else None: ArcSim's 1.
  """

  source: str
  material: str
  bending_scale: float
  area_weight: float
  intervals: dict
  cloth_size: float
  cloth_resolution: int
  fps: float
  air: dict | None = None

  @property
  def rigidity(self) -> float:
    """The fabric's bending rigidity D, N m."""
    return self.bending_scale * physsim.reference_rigidity(self.material)

  @property
  def bending_length(self) -> float:
    """Its bending length c = (D / (w g))^(1/3), m."""
    return (self.rigidity / (self.area_weight * physsim.params.GRAVITY)) ** (1 / 3)


def in_range(path: str, key: str, v, lo: float, hi: float) -> float:
  """``v`` as a float, refused (naming the file and key) unless a finite
  number in [lo, hi]."""
  try:
    x = float(v)
  except (TypeError, ValueError):
    raise ValueError(f'{path}: {key} is a {type(v).__name__}, not a number') from None
  if not (math.isfinite(x) and lo <= x <= hi):
    raise ValueError(f'{path}: {key}={x:.6g} outside [{lo:g}, {hi:g}]')
  return x


def read_point(workdir: str) -> Point:
  """The fabric an estimate's workdir holds (its ``estimate.json``, else a
  joint's ``joint.json``).

  Raises:
    ValueError: neither file, a corrupt one, or one without the fabric's
      parameters or with one not finite or out of range (named).
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
  data = layout.read_json(path)
  shared = data.get('estimate', data)  # a joint's are at the top
  config = data.get('config', {})
  try:
    entries = {k: shared[k] for k in _NAMES}
    raw = {k: e['value'] if 'value' in e else e['median'] for k, e in entries.items()}
    raw_iv = {k: list(e['interval_90']) for k, e in entries.items()}
    material = data['material']
  except (KeyError, TypeError, AttributeError) as e:
    raise ValueError(
      f'{path}: no bending and area weight estimate in it ({type(e).__name__}: '
      f'{str(e)[:60]})'
    ) from None
  if not isinstance(material, str) or material not in physsim.FABRICS:
    raise ValueError(f'{path}: material {str(material)[:40]!r} is no known fabric')
  if not isinstance(config, dict):
    raise ValueError(f'{path}: config is a {type(config).__name__}, not an object')
  ranges = {'bending_scale': BENDING_SCALE_RANGE, 'area_weight': AREA_WEIGHT_RANGE}
  point = {k: in_range(path, k, raw[k], *ranges[k]) for k in _NAMES}
  intervals = {}
  for k in _NAMES:
    if len(raw_iv[k]) != 2:
      raise ValueError(f'{path}: {k}.interval_90 holds {len(raw_iv[k])} values, not 2')
    lo, hi = (in_range(path, f'{k}.interval_90', v, *ranges[k]) for v in raw_iv[k])
    if lo > hi:
      raise ValueError(f'{path}: {k}.interval_90 [{lo:.6g}, {hi:.6g}] is reversed')
    intervals[k] = [lo, hi]
  return Point(
    source=path,
    material=material,
    intervals=intervals,
    cloth_size=in_range(
      path, 'config.cloth_size', config.get('cloth_size', 1.0), *CLOTH_SIZE_RANGE
    ),  # fmt: skip
    cloth_resolution=round(
      in_range(
        path,
        'config.cloth_resolution',
        config.get('cloth_resolution', 25),
        *RESOLUTION_RANGE,
      )
    ),  # fmt: skip
    fps=in_range(path, 'config.fps', config.get('fps', 20.0), *FPS_RANGE),
    air=_air(path, shared.get('air_coefficient')),
    **point,
  )


AIR_RANGE = (0.05, 10.0)  # an air coefficient beyond it is no fabric's


def _air(path: str, entry) -> dict | None:
  """An estimate's air coefficient entry as ``{'value', 'interval_90'}``
  (None: not read), refused naming the file if not finite or out of range."""
  if entry is None:
    return None
  if not isinstance(entry, dict) or 'interval_90' not in entry:
    raise ValueError(f'{path}: air_coefficient is no estimate entry')
  value = in_range(
    path, 'air_coefficient', entry.get('value', entry.get('median')), *AIR_RANGE
  )
  iv = [in_range(path, 'air_coefficient.interval_90', v, *AIR_RANGE)
        for v in list(entry['interval_90'])[:3]]  # fmt: skip
  if len(iv) != 2 or iv[0] > iv[1]:
    raise ValueError(f'{path}: air_coefficient.interval_90 is not a (low, high) pair')
  return {'value': value, 'interval_90': iv}


def check_flags(draws: int, cloth_size: float, resolution: int, overhang: float,
                seed: int, mesh_flag: str = 'mesh') -> None:  # fmt: skip
  """Refuses, before anything is read or allocated, a count or size out of
  range (0 means the estimate's own, or none), naming the flag (the mesh's
  as ``mesh_flag``)."""
  checks = (
    ('draws', draws, 0, MAX_DRAWS),
    ('seed', seed, 0, 2**31 - 1),
  )
  for name, v, lo, hi in checks:
    if not (isinstance(v, int | np.integer) and lo <= v <= hi):
      raise ValueError(f'--{name}={v}: need a whole number in [{lo}, {hi}]')
  lo, hi = RESOLUTION_RANGE
  if not (isinstance(resolution, int | np.integer) and
          (resolution == 0 or lo <= resolution <= hi)):  # fmt: skip
    raise ValueError(
      f"--{mesh_flag}={resolution}: need 0 (the estimate's) or {lo}-{hi} vertices a side"
    )
  lo, hi = CLOTH_SIZE_RANGE
  if not (math.isfinite(cloth_size) and (cloth_size == 0 or lo <= cloth_size <= hi)):
    raise ValueError(
      f"--cloth_size={cloth_size}: need 0 (the estimate's) or {lo:g}-{hi:g} m, "
      'the sizes an estimate takes'
    )
  if not (math.isfinite(overhang) and 0 <= overhang <= 1.0):
    raise ValueError(
      f'--overhang={overhang}: need 0 (the default, fit_overhang) or a length up to 1 m'
    )


def fit_overhang(size: float, bending_length: float) -> float:
  """The overhang the export fits its bending at, by default (m; 0:
  ``mesh_fit.OVERHANG_RATIO`` bending lengths): the sheet's own side where it
  is ``mesh_fit.MIN_RATIO``-``MAX_RATIO`` bending lengths (a swatch or strip,
  what it shows hanging over an edge; the flex's effective rigidity at a coarse
  mesh differs from one overhang to another), else three bending lengths (the
  cantilever test a reading of the bending length is made from)."""
  ratio = size / bending_length
  return size if mesh_fit.MIN_RATIO <= ratio <= mesh_fit.MAX_RATIO else 0.0


def _units(point: Point) -> dict:
  """The fabric in a lab's units, each with its 90% interval where the
  estimate gives one (bending rigidity and area weight; the bending length,
  of both, from the point)."""
  d0 = physsim.reference_rigidity(point.material)
  b, w = point.intervals['bending_scale'], point.intervals['area_weight']
  return {
    'bending_rigidity_uNm': {
      'value': 1e6 * point.rigidity, 'interval_90': [1e6 * v * d0 for v in b],
    },
    'bending_length_mm': {'value': 1e3 * point.bending_length},
    'area_weight_gsm': {
      'value': 1e3 * point.area_weight, 'interval_90': [1e3 * v for v in w],
    },
  }  # fmt: skip


def write(
  workdir: str,
  out: str = '',
  *,
  draws: int = 200,
  cloth_size: float = 0.0,
  resolution: int = 0,
  overhang: float = 0.0,
  seed: int = 0,
  mesh_flag: str = 'mesh',
) -> dict:
  """Writes the fabric of the estimate in ``workdir`` for a sheet of
  ``resolution`` vertices a side into ``out`` (module doc); returns
  ``fabric.json``'s record.

  Args:
    workdir: an estimate's workdir.
    out: where the files go ('': ``out_dir``); all of them or none.
    draws: posterior draws in ``fabric_draws.csv`` (0: none; an estimate
      without saved draws, the paper's argmin, writes none).
    cloth_size, resolution: the exported sheet's side (m) and vertices a
      side (0: the estimate's own); the bending is fitted at its spacing.
    overhang: the fit's cantilever overhang, m (0: ``fit_overhang``).
    seed: which of the saved draws (a random subset when it holds more).
    mesh_flag: the mesh's flag, for a refusal.

  Raises:
    ValueError: a flag out of range, a workdir without an estimate, a
      corrupt or incomplete estimate file (named), or a point out of range.
  """
  check_flags(draws, cloth_size, resolution, overhang, seed, mesh_flag)
  point = read_point(workdir)
  size = cloth_size or point.cloth_size
  n = resolution or point.cloth_resolution
  out = out or out_dir(workdir, n)
  log_draws = _read_draws(workdir) if draws > 0 else None
  mesh = physsim.square(n, size)
  fit, config = _fitted(point, mesh, size, size / (n - 1), overhang)
  b, w, s = point.bending_scale, point.area_weight, fit.flex_scale
  units = _units(point)
  comment = '; '.join(_comment(point, units, size, n, fit))
  xml = export.mujoco_xml(mesh, point.material, s, w, config, comment=comment)
  texts = {
    MJCF_FILE: xml,
    ARCSIM_FILE: json.dumps(export.arcsim_material(point.material, b, w), indent=1),
    LICENSE_FILE: physsim.materials.license_text(),
  }
  if log_draws is not None:
    texts[DRAWS_FILE] = _draws_table(log_draws, point, s / b, draws, seed)
  kinds = {MJCF_FILE: 'mujoco', ARCSIM_FILE: 'arcsim', DRAWS_FILE: 'draws'}
  written = {kinds[f]: os.path.join(out, f) for f in texts if f in kinds}
  record = {**_record(point, units, fit, config, mesh, size, n), 'files': written}
  texts[FABRIC_FILE] = _json(record, FABRIC_FILE)
  _commit(texts, out)
  return record


def _fitted(point: Point, mesh: physsim.Mesh, size: float, spacing: float,
            overhang: float) -> tuple[mesh_fit.Fit, physsim.SimConfig]:  # fmt: skip
  """The flex's bending fitted at the spacing of ``mesh`` (a sheet of side
  ``size``: ``mesh_fit.fit``, at ``overhang`` m or 0: ``fit_overhang``) and
  the mesh's simulation config, its step no longer than the one the fit held
  at and its edges no stiffer than that step resolves."""
  config = physsim.config_for_mesh(mesh, point.fps)
  overhang = overhang or fit_overhang(size, point.bending_length)
  fit = mesh_fit.fit(point.material, point.rigidity, point.area_weight, spacing,
                     config, overhang=overhang)  # fmt: skip
  config = dataclasses.replace(
    config, timestep=min(config.timestep, fit.timestep if fit.fitted else math.inf)
  )
  config = dataclasses.replace(
    config, edge_solref=max(config.edge_solref, 2 * config.timestep)
  )
  return fit, config


def _comment(point: Point, units: dict, size: float, n: int,
             fit: mesh_fit.Fit) -> list[str]:  # fmt: skip
  """The lines of ``fabric.xml``'s comment: the fabric in a lab's units
  (``units``: ``_units``), the sheet of ``n`` vertices a side over ``size`` m
  it was made for and its fit, where it came from and how to load it."""
  spacing = size / (n - 1)
  return [
    f'{point.material}: bending rigidity {units["bending_rigidity_uNm"]["value"]:.4g} '
    f'uN m, bending length {units["bending_length_mm"]["value"]:.3g} mm, area '
    f'weight {units["area_weight_gsm"]["value"]:.4g} g/m^2',
    f'made for a {size:g} m sheet of {n} x {n} vertices ({1e3 * spacing:.3g} mm '
    f'apart): flex bending scale {fit.flex_scale:.6g} ({_fit_words(fit)})',
    f'from {os.path.abspath(point.source)}; pinned at its top corners; no air '
    '(add your own wind: physsim.face_wind_forces'
    + (
      f", density={point.air['value']:.4g}: this fabric's air coefficient)"
      if point.air
      else ')'
    ),
    'load with physsim.export.load (or copy the custom numeric '
    f"{export.INVWEIGHT_KEY} into flexedge_invweight0) for the estimator's edges",
  ]


def _record(point: Point, units: dict, fit: mesh_fit.Fit, config: physsim.SimConfig,
            mesh: physsim.Mesh, size: float, n: int) -> dict:  # fmt: skip
  """``fabric.json``'s record but its ``files``: the fabric in a lab's units
  (``units``), the sheet ``mesh`` (``n`` vertices a side over ``size`` m) and
  its step, the simulator's internal scales and the fit (labelled), the
  estimate's point and intervals, and its air coefficient where it read one."""
  s = fit.flex_scale
  return {
    'source': os.path.abspath(point.source),
    'material': point.material,
    'fabric': units,
    'mesh': {
      'name': mesh.name,
      'vertices_per_side': n,
      'size_m': size,
      'spacing_mm': 1e3 * (size / (n - 1)),
      'timestep_s': config.timestep,
      'fps': point.fps,
    },  # fmt: skip
    'simulator': {
      'flex_bending_scale': s,
      'young_Pa': export.young_modulus(s, point.material),
      'thickness_m': physsim.cloth.THICKNESS,
      'reference_rigidity_uNm': 1e6 * physsim.reference_rigidity(point.material),
      'meaning': (
        "internal bending scales, times the material's reference rigidity: "
        "flex_bending_scale is what MuJoCo's flex at this mesh needs "
        "(fit), point.bending_scale the estimate's own"
      ),
      'fit': fit.record(),
    },
    'point': {'bending_scale': point.bending_scale, 'area_weight': point.area_weight},
    'interval_90': point.intervals,
    **(
      {
        'air_coefficient': {
          **point.air,
          'meaning': "the normal wind pressure on this fabric over an ArcSim sheet's: "
          'blow it with physsim.face_wind_forces(..., density=value)',
        }
      }
      if point.air
      else {}
    ),  # fmt: skip
  }


def _fit_words(fit: mesh_fit.Fit) -> str:
  if not fit.fitted:
    return fit.note
  return (
    f'its cantilever of {1e3 * fit.overhang:.3g} mm reaches {1e3 * fit.reach:.3g} mm, '
    f'the elastica {1e3 * fit.elastica_reach:.3g} mm ({100 * fit.reach_error:+.2f}%; '
    f'at the nominal scale {100 * fit.nominal_error:+.1f}%)'
  )


def summary(record: dict) -> list[str]:
  """What ``experiments.export`` prints of a ``write`` record: the fabric in
  physical units, the mesh and its fit, the internal scales labelled."""
  f, m, sim = record['fabric'], record['mesh'], record['simulator']
  fit = sim['fit']

  def iv(entry, digits=3):
    if 'interval_90' not in entry:
      return ''
    return ' (90% [' + ', '.join(f'{v:.{digits}g}' for v in entry['interval_90']) + '])'

  out = [
    f'{record["material"]}: bending rigidity '
    f'{f["bending_rigidity_uNm"]["value"]:.4g} uN m{iv(f["bending_rigidity_uNm"])}, '
    f'bending length {f["bending_length_mm"]["value"]:.3g} mm, area weight '
    f'{f["area_weight_gsm"]["value"]:.4g} g/m^2{iv(f["area_weight_gsm"])}',
    f'for MuJoCo at {m["vertices_per_side"]} x {m["vertices_per_side"]} vertices over '
    f'{m["size_m"]:g} m ({m["spacing_mm"]:.3g} mm apart, step {m["timestep_s"]:.3g} s): '
    f"Young's modulus {sim['young_Pa']:.4g} Pa at {1e3 * sim['thickness_m']:g} mm",
  ]
  if fit['fitted']:
    out.append(
      f'fitted: a {fit["overhang_mm"]:.3g} mm cantilever at this mesh reaches '
      f'{fit["reach_mm"]:.3g} mm, the elastica {fit["elastica_reach_mm"]:.3g} mm '
      f'({100 * fit["reach_error"]:+.2f}%; at the nominal rigidity '
      f'{100 * fit["nominal_error"]:+.1f}%), {fit["rollouts"]} strips simulated'
    )
  if fit['note']:
    out.append(fit['note'])
  if 'air_coefficient' in record:
    a = record['air_coefficient']
    out.append(
      f'air coefficient {a["value"]:.3g}{iv(a)}: blow it with '
      f'physsim.face_wind_forces(..., density={a["value"]:.3g})'
    )
  out.append(
    f'internal bending scale (x the reference {sim["reference_rigidity_uNm"]:.3g} '
    f"uN m): the flex's {sim['flex_bending_scale']:.4g}, the estimate's "
    f'{record["point"]["bending_scale"]:.4g}'
  )
  return out


def _json(obj, name: str) -> str:
  """JSON text of ``obj``; ValueError naming ``name`` if a number in it is not
  finite (never "NaN" or "Infinity" in a file)."""
  try:
    return json.dumps(obj, indent=1, sort_keys=True, allow_nan=False) + '\n'
  except ValueError:
    raise ValueError(f'{name}: a number to write is not finite') from None


def _read_draws(workdir: str) -> np.ndarray | None:
  """(S, 2) log bending scale and log area weight of the estimate's saved
  draws, None where it kept none (the paper's argmin); a corrupt, incomplete
  or out-of-range file refused naming it (``layout.read_draws``)."""
  names = (layout.POSTERIOR_FILE, layout.JOINT_POSTERIOR_FILE)
  if not any(os.path.exists(os.path.join(workdir, f)) for f in names):
    return None
  _, log_draws, _ = layout.read_draws(workdir)
  path = os.path.join(workdir, names[0])
  if not os.path.exists(path):
    path = os.path.join(workdir, names[1])
  for k, (name, (lo, hi)) in enumerate(
    (('bending_scale', BENDING_SCALE_RANGE), ('area_weight', AREA_WEIGHT_RANGE))
  ):
    v = np.exp(log_draws[:, k])
    if not (np.all(np.isfinite(v)) and v.min() >= lo and v.max() <= hi):
      raise ValueError(
        f'{path}: {name} draws in [{v.min():.3g}, {v.max():.3g}], outside '
        f'[{lo:g}, {hi:g}]'
      )
  return log_draws


def _draws_table(log_draws, point: Point, correction: float, n: int, seed: int) -> str:
  """``fabric_draws.csv``'s text: up to ``n`` of the saved draws, each in
  physical units and as the flex's scale at the export's mesh (the draw's
  scale times the point's fitted correction, ``correction``)."""
  rng = np.random.default_rng(seed)
  pick = rng.permutation(len(log_draws))[: min(n, len(log_draws))]
  d0 = physsim.reference_rigidity(point.material)
  g = physsim.params.GRAVITY
  rows = [
    'bending_scale,flex_bending_scale,young_Pa,bending_rigidity_uNm,'
    'bending_length_mm,area_weight_gsm'
  ]
  for lb, lw in log_draws[pick]:
    b, w = float(np.exp(lb)), float(np.exp(lw))
    c = (b * d0 / (w * g)) ** (1 / 3)
    s = b * correction
    rows.append(
      f'{b:.6g},{s:.6g},{export.young_modulus(s, point.material):.6g},'
      f'{1e6 * b * d0:.6g},{1e3 * c:.6g},{1e3 * w:.6g}'
    )
  return '\n'.join(rows) + '\n'


def _commit(texts: dict[str, str], out: str) -> None:
  """Writes every file of ``texts`` into ``out``, all or none: into a
  temporary folder beside it, then renamed into place (the whole folder when
  ``out`` is new; else file by file, the files they replace, and an earlier
  export's that this one lacks, kept aside until every rename is done and put
  back if one fails)."""
  out = os.path.abspath(out)
  if os.path.exists(out) and not os.path.isdir(out):
    raise ValueError(f'{out}: exists and is not a folder')
  parent = os.path.dirname(out)
  os.makedirs(parent, exist_ok=True)
  tmp = tempfile.mkdtemp(prefix=f'.{os.path.basename(out)}.', dir=parent)
  try:
    new = os.path.join(tmp, 'new')
    os.mkdir(new)
    for name, text in texts.items():
      files.write_text(os.path.join(new, name), text)
    if not os.path.exists(out):
      os.rename(new, out)
      return
    old = os.path.join(tmp, 'old')
    os.mkdir(old)
    moved, placed = [], []
    try:
      for name in ALL_FILES:
        if os.path.exists(os.path.join(out, name)):
          os.rename(os.path.join(out, name), os.path.join(old, name))
          moved.append(name)
      for name in texts:
        os.rename(os.path.join(new, name), os.path.join(out, name))
        placed.append(name)
    except OSError:
      for name in placed:
        with contextlib.suppress(OSError):
          os.remove(os.path.join(out, name))
      for name in moved:
        with contextlib.suppress(OSError):
          os.rename(os.path.join(old, name), os.path.join(out, name))
      raise
  finally:
    shutil.rmtree(tmp, ignore_errors=True)
