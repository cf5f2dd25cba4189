"""The bending a MuJoCo flex needs at a given mesh to hang as the measured fabric.

A fabric's bending rigidity D (N m) and area weight w (kg/m^2) fix its bending
length c = (D / (w g))^(1/3), and a strip of it overhanging a table's edge by
L takes the heavy elastica's shape (``physsim.cantilever``). MuJoCo's flex of
the same nominal D does not: on the estimator's alternating-diagonal grid it
bends as 0.6-0.76 of it, less on coarser meshes and differently at other
overhangs (``benchmarks/overhang_mesh.py``), so an exported file at the user's
mesh, written at the nominal D, is another fabric. ``fit`` puts the simulator
in the loop instead: a strip of the user's spacing, its first two rows held
on the table and ``free`` spacings over the edge, is released flat under
gravity (MuJoCo C, the exported MJCF itself: ``physsim.export.mujoco_xml``,
with a damping that settles it and leaves the rest shape alone), and the
flex's bending scale is moved by secant steps on its log until the strip's tip
reaches as far from the edge as the elastica of c does. The scale found is
what ``experiments.export --mesh=N`` writes.

The strip is ``STRIP_COLUMNS`` vertices wide (a plate bent about one axis at
Poisson 0 is a strip of any width; the boundary hinges of a narrower one bend
it a little more, about half a percent at 5 columns). The overhang is the
cantilever test's ``OVERHANG_RATIO`` bending lengths (what a reading of c is
made from), whole spacings, or one given; a mesh too coarse to bend a strip of
that length (its spacing over a bending length or more) cannot be fitted: the
fit says so and keeps the nominal scale.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from physsim import cantilever, cloth, export
from physsim.mesh import Mesh
from physsim.params import GRAVITY

OVERHANG_RATIO = 3.0  # the fit's default overhang, in bending lengths
MAX_RATIO = 4.5  # beyond it the strip hangs nearly straight down: reads nothing
MIN_RATIO = 1.0  # below it the strip hardly droops: reads little
MIN_FREE = 2  # spacings over the edge, at least
STRIP_COLUMNS = 9
TOLERANCE = 0.002  # relative reach error at which the fit stops
MAX_ROLLOUTS = 8
SETTLE_CHUNK_S = 0.05  # simulated seconds between checks that the strip is at rest
SETTLE_MOVE = 1e-5  # of the overhang: at rest when the tip moves less per chunk
MAX_SETTLE_S = 8.0
MAX_HALVINGS = 3  # of the step, where a rollout blows up
SCALE_RANGE = 30.0  # the flex's scale is searched within nominal / and * this


@dataclasses.dataclass(frozen=True)
class Fit:
  """What the flex at one mesh needs to bend as the fabric does.

  Attributes:
    flex_scale: the flex's bending over the material's reference rigidity D0
      (``cloth.reference_rigidity``): what the export writes.
    nominal_scale: the fabric's own D over D0.
    fitted: whether the strip was simulated (False: a mesh too coarse, see
      ``note``; ``flex_scale`` is then the nominal one).
    spacing: the mesh's spacing, m.
    overhang: the strip's overhang, m (whole spacings).
    bending_length: the fabric's c, m.
    reach: the fitted strip's tip reach from the edge, m.
    elastica_reach: the elastica's, m.
    nominal_reach: the strip's at the nominal scale, m.
    shape_rms: RMS distance of the fitted strip's centre line from the
      elastica's, over the overhang.
    rollouts: strips simulated.
    timestep: the MuJoCo step the strips held at (the export's, or shorter
      where a rollout blew up).
    note: what the fit could not do, or ''.
  """

  flex_scale: float
  nominal_scale: float
  fitted: bool
  spacing: float
  overhang: float
  bending_length: float
  reach: float = math.nan
  elastica_reach: float = math.nan
  nominal_reach: float = math.nan
  shape_rms: float = math.nan
  rollouts: int = 0
  timestep: float = math.nan
  note: str = ''

  @property
  def reach_error(self) -> float:
    """The fitted strip's reach over the elastica's, minus 1."""
    return self.reach / self.elastica_reach - 1.0

  @property
  def nominal_error(self) -> float:
    """The strip's at the nominal scale over the elastica's, minus 1."""
    return self.nominal_reach / self.elastica_reach - 1.0

  def record(self) -> dict:
    """JSON-ready fields, lengths in mm (NaN as None)."""
    out = {
      'fitted': self.fitted, 'flex_bending_scale': self.flex_scale,
      'nominal_bending_scale': self.nominal_scale,
      'spacing_mm': 1e3 * self.spacing, 'overhang_mm': 1e3 * self.overhang,
      'bending_length_mm': 1e3 * self.bending_length,
      'reach_mm': 1e3 * self.reach, 'elastica_reach_mm': 1e3 * self.elastica_reach,
      'nominal_reach_mm': 1e3 * self.nominal_reach,
      'reach_error': self.reach_error if self.fitted else math.nan,
      'nominal_error': self.nominal_error if self.fitted else math.nan,
      'shape_rms_over_overhang': self.shape_rms, 'rollouts': self.rollouts,
      'timestep_s': self.timestep, 'note': self.note,
    }  # fmt: skip
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}  # fmt: skip


def strip(spacing: float, free: int, columns: int = STRIP_COLUMNS) -> Mesh:
  """A strip lying flat on a table, reaching out along +y: ``free + 2`` rows of
  ``columns`` vertices ``spacing`` apart, rows 0 and 1 held (row 1 on the
  edge, y = 0; the table clamps the slope too), ``free`` spacings over it."""
  if not (spacing > 0 and free >= 1 and columns >= 2):
    raise ValueError(
      f'a strip needs spacing > 0, free >= 1, columns >= 2; got {spacing}, '
      f'{free}, {columns}'
    )
  rows = free + 2
  y = (np.arange(rows) - 1) * spacing
  x = (np.arange(columns) - (columns - 1) / 2) * spacing
  xx, yy = np.meshgrid(x, y)
  vertices = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, 0.5)], axis=1)
  faces = _faces(rows, columns)
  return Mesh(vertices, faces, np.arange(2 * columns), f'strip{rows}x{columns}')


def _faces(rows: int, columns: int) -> np.ndarray:
  """The alternating-diagonal triangles of a rows x columns grid, as
  ``physsim.square`` cuts its cells."""
  idx = np.arange(rows * columns).reshape(rows, columns)
  out = []
  for i in range(rows - 1):
    for j in range(columns - 1):
      a, b, c, d = idx[i, j], idx[i, j + 1], idx[i + 1, j], idx[i + 1, j + 1]
      out += [(a, c, d), (a, d, b)] if (i + j) % 2 == 0 else [(a, c, b), (b, c, d)]
  return np.asarray(out, dtype=np.int64)


def settle(
  mesh: Mesh,
  material: str,
  flex_scale: float,
  area_weight: float,
  config: cloth.SimConfig,
  bending_length: float,
) -> np.ndarray | None:
  """(rows, 3) the rest shape of a ``strip`` released flat under gravity: each
  row's mean position once its tip has stopped moving (None where the rollout
  blew up). MuJoCo C steps the exported MJCF (``export.mujoco_xml``,
  ``export.load``) with a joint damping of twice the strip's lowest
  frequency (cantilever and pendulum in quadrature), which shortens the swing
  and leaves the rest shape as it is."""
  m = export.load(export.mujoco_xml(mesh, material, flex_scale, area_weight, config))
  columns = int(np.sum(np.isclose(mesh.vertices[:, 1], mesh.vertices[0, 1])))
  rows = len(mesh.vertices) // columns
  length = (rows - 2) * float(mesh.vertices[columns, 1] - mesh.vertices[0, 1])
  c = bending_length * flex_scale ** (1 / 3)  # the flex's nominal length
  beam = 3.516 * math.sqrt(GRAVITY * c**3) / length**2
  omega = math.hypot(beam, 1.2 * math.sqrt(GRAVITY / length))
  m.dof_damping[:] = 2.0 * omega * m.body_mass[m.dof_bodyid]
  d = mujoco.MjData(m)
  chunk = max(1, round(SETTLE_CHUNK_S / m.opt.timestep))
  last, t = None, 0.0
  while t < MAX_SETTLE_S:
    for _ in range(chunk):
      mujoco.mj_step(m, d)
    t += chunk * m.opt.timestep
    x = d.flexvert_xpos.reshape(rows, columns, 3).mean(axis=1)
    if not np.all(np.isfinite(x)) or np.abs(x).max() > 10 * length + 1:
      return None
    if last is not None and abs(x[-1, 1] - last) < SETTLE_MOVE * length:
      break
    last = x[-1, 1]
  return x.copy()


def _elastica_shape(ratio: float, length: float, rows: int) -> np.ndarray:
  """(rows - 1, 2) the elastica's centre line (reach, drop) in metres at the
  strip's rows from the edge (arc length k spacings)."""
  line = cantilever.shape(ratio) * length  # (steps + 1, 2), equal arc steps
  s = np.linspace(0.0, 1.0, len(line))
  k = np.linspace(0.0, 1.0, rows - 1)
  return np.stack([np.interp(k, s, line[:, 0]), np.interp(k, s, line[:, 1])], 1)


def fit(
  material: str,
  rigidity: float,
  area_weight: float,
  spacing: float,
  config: cloth.SimConfig,
  overhang: float = 0.0,
  columns: int = STRIP_COLUMNS,
  tolerance: float = TOLERANCE,
) -> Fit:
  """The flex's bending scale at ``spacing`` whose cantilever reaches as far as
  the elastica of a fabric of ``rigidity`` (N m) and ``area_weight``
  (kg/m^2), by secant steps on its log (module doc).

  Args:
    material: the fabric whose reference rigidity D0 the scale multiplies.
    rigidity: the fabric's D, N m (the measured one).
    area_weight: kg/m^2.
    spacing: the user's mesh spacing, m.
    config: the export's step and edges (``physsim.config_for_mesh`` of the
      user's mesh).
    overhang: the strip's overhang, m (0: ``OVERHANG_RATIO`` bending lengths);
      rounded to whole spacings, at least ``MIN_FREE``.
    columns: the strip's width in vertices.
    tolerance: the relative reach error at which to stop.

  Raises:
    ValueError: a value not finite and > 0, or a given overhang outside
      ``MIN_RATIO``-``MAX_RATIO`` bending lengths (named).
  """
  _check(rigidity, area_weight, spacing, overhang)
  nominal = rigidity / cloth.reference_rigidity(material)
  c = (rigidity / (area_weight * GRAVITY)) ** (1 / 3)
  free = _free_spacings(overhang, c, spacing)
  length = free * spacing
  base = Fit(nominal, nominal, False, spacing, length, c)
  if length / c > MAX_RATIO:
    return dataclasses.replace(base, overhang=0.0, note=_too_coarse_note(spacing, c))
  mesh = strip(spacing, free, columns)
  target_reach = float(cantilever.tip(length / c)[0][0]) * length
  strips = _Strips(mesh, material, area_weight, config, c)
  xs, fs, shapes = _secant_search(strips, nominal, target_reach, length, c, tolerance)
  best = min(range(len(fs)), key=lambda k: abs(fs[k]))
  x = shapes[best]
  note = ''
  if abs(fs[best]) > tolerance:
    note = (
      f'the fit stopped {100 * (math.exp(fs[best]) - 1):+.2f}% off the elastica '
      f'reach after {len(fs)} strips'
    )
  return dataclasses.replace(
    base, flex_scale=math.exp(xs[best]), fitted=True, reach=float(x[-1, 1]),
    elastica_reach=target_reach, nominal_reach=float(shapes[0][-1, 1]),
    shape_rms=_shape_rms(x, length, c) / length, rollouts=strips.rollouts,
    timestep=strips.config.timestep, note=note,
  )  # fmt: skip


def _check(rigidity: float, area_weight: float, spacing: float, overhang: float):
  """Raises ValueError (naming it) unless each of ``fit``'s values is finite
  and > 0 (the overhang >= 0: 0 is the default)."""
  for name, v in (('rigidity', rigidity), ('area_weight', area_weight),
                  ('spacing', spacing)):  # fmt: skip
    if not (math.isfinite(v) and v > 0):
      raise ValueError(f'{name}={v}: need a finite value > 0')
  if not (math.isfinite(overhang) and overhang >= 0):
    raise ValueError(f'overhang={overhang}: need a finite value >= 0 (0: default)')


def _free_spacings(overhang: float, c: float, spacing: float) -> int:
  """Spacings over the edge: the given ``overhang`` (m; 0: ``OVERHANG_RATIO``
  bending lengths ``c``) in whole spacings, at least ``MIN_FREE``. Raises
  ValueError where a given overhang is outside ``MIN_RATIO``-``MAX_RATIO``
  bending lengths: its reach would read nothing of the bending."""
  if overhang and not MIN_RATIO <= overhang / c <= MAX_RATIO:
    raise ValueError(
      f'overhang={overhang:g} m is {overhang / c:.2f} bending lengths ({1e3 * c:.1f} '
      f'mm): need {MIN_RATIO:g}-{MAX_RATIO:g} for a reach that reads the bending'
    )
  return max(MIN_FREE, round((overhang or OVERHANG_RATIO * c) / spacing))


def _too_coarse_note(spacing: float, c: float) -> str:
  """Why a mesh of ``spacing`` is not fitted to a bending length ``c``."""
  return (
    f'not fitted: a spacing of {1e3 * spacing:.1f} mm is {spacing / c:.2f} '
    f'bending lengths ({1e3 * c:.1f} mm); a strip of {MIN_FREE} spacings '
    'hangs straight down at this mesh, so its bending reads nothing: the '
    'nominal scale (refine the mesh to fit it)'
  )


class _Strips:
  """The fit's strip, settled at one flex scale after another (``settle``),
  counting its rollouts and halving the step (``MAX_HALVINGS`` times at
  most) where one blows up; later rollouts keep the shorter step."""

  def __init__(self, mesh: Mesh, material: str, area_weight: float,
               config: cloth.SimConfig, bending_length: float):  # fmt: skip
    self.mesh, self.material, self.area_weight = mesh, material, area_weight
    self.config, self.bending_length = config, bending_length
    self.rollouts = 0

  def __call__(self, scale: float) -> np.ndarray:
    """The strip's rest shape at ``scale`` (``settle``). Raises ValueError
    where it blows up at every step tried."""
    for _ in range(MAX_HALVINGS + 1):
      self.rollouts += 1
      x = settle(self.mesh, self.material, scale, self.area_weight, self.config,
                 self.bending_length)  # fmt: skip
      if x is not None:
        return x
      step = self.config.timestep / 2
      self.config = dataclasses.replace(
        self.config, timestep=step, edge_solref=max(self.config.edge_solref, 2 * step)
      )
    raise ValueError(
      f'the strip at bending scale {scale:.3g} blew up down to a step of '
      f'{self.config.timestep:.3g} s'
    )


def _secant_search(strips: _Strips, nominal: float, target_reach: float,
                   length: float, c: float, tolerance: float):  # fmt: skip
  """Log flex scales tried from ``nominal`` until a strip's reach is within
  ``tolerance`` of ``target_reach`` (or ``MAX_ROLLOUTS`` strips, or a step
  that repeats one): ``(xs, fs, shapes)``, each scale's log, its log reach
  error and its strip's rest shape."""

  def error(x):
    return math.log(max(x[-1, 1], 1e-12) / target_reach)

  lo_x, hi_x = math.log(nominal / SCALE_RANGE), math.log(nominal * SCALE_RANGE)
  xs, shapes = [math.log(nominal)], [strips(nominal)]
  fs = [error(shapes[0])]
  while abs(fs[-1]) > tolerance and len(fs) < MAX_ROLLOUTS:
    x = min(hi_x, max(lo_x, _next_log_scale(xs, fs, shapes[0], length, c)))
    if any(abs(x - v) < 1e-9 for v in xs):
      break
    xs.append(x)
    shapes.append(strips(math.exp(x)))
    fs.append(error(shapes[-1]))
  return xs, fs, shapes


def _next_log_scale(xs: list, fs: list, first: np.ndarray, length: float,
                    c: float) -> float:  # fmt: skip
  """The next log scale to try, from the log scales ``xs`` tried and their log
  reach errors ``fs`` (``first``: the nominal scale's rest shape): the secant
  of the closest pair on each side once bracketed; after one strip, the scale
  of its reach's bending length (as if the flex's ratio were constant); else
  the secant of the last two, at most x4."""
  below = [i for i, f in enumerate(fs) if f < 0]
  above = [i for i, f in enumerate(fs) if f > 0]
  if below and above:
    i = max(below, key=lambda k: fs[k])
    j = min(above, key=lambda k: fs[k])
    return xs[i] - fs[i] * (xs[j] - xs[i]) / (fs[j] - fs[i])
  if len(fs) == 1:
    try:
      found = cantilever.bending_length(length, float(first[-1, 1]))
      return xs[0] + 3.0 * math.log(c / found)
    except ValueError:
      return xs[0] + (math.log(2.0) if fs[0] < 0 else -math.log(2.0))
  slope = (fs[-1] - fs[-2]) / (xs[-1] - xs[-2])
  step = -fs[-1] / slope if slope > 0 else math.copysign(math.log(2.0), -fs[-1])
  return xs[-1] + max(-math.log(4.0), min(math.log(4.0), step))


def _shape_rms(x: np.ndarray, length: float, c: float) -> float:
  """RMS distance, m, of a settled strip's centre line (``settle``'s rows)
  from the elastica's at its rows."""
  line = x[1:, 1:] - x[1, 1:]  # from the edge: (reach, height)
  sim = np.stack([line[:, 0], -line[:, 1]], axis=1)
  return float(
    np.sqrt(
      np.mean(np.sum((sim - _elastica_shape(length / c, length, len(x))) ** 2, 1))
    )
  )
