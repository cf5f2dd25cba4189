"""What is known before the video: the search box's prior and the user's readings.

The second of the estimate's stages (after the intake): an anemometer's
wind, a scale's area weight and an overhang's bending length (``Measured``),
checked against the search box, and the prior they make on the search's
grid (``log_prior``: uniform in the box, bending log-uniform, times each
reading's law). The objective, the search and the posterior take them from
here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.special

import physsim
from experiments.pipeline import cli

FIELDS = physsim.params.FIELDS  # bending_scale, wind_speed, area_weight
SHORT = {'bending_scale': 'bending', 'wind_speed': 'wind', 'area_weight': 'weight'}
# The air coefficient c: a multiplier on the normal wind pressure that is the
# fabric's own (porosity, surface, drape in the flow; ArcSim's sheet is 1). The
# sheet feels c rho v^2, so the simulator blown at the effective wind
# v_eff = v sqrt(c) loads it as the fabric at v (``physsim.SimConfig``'s
# ``air_density`` times c makes such a fabric: only the flutter's air damping,
# c |v - u| against sqrt(c) |v_eff - u|, tells them apart). Its prior:
# log-uniform over AIR_RANGE, integrated on AIR_NODES nodes.
AIR_MODES = ('auto', 'fixed', 'free')
AIR_RANGE = (0.3, 1.5)
AIR_NODES = 96


@dataclasses.dataclass(frozen=True)
class Measured:
  """What the user measured besides the video (0: not measured).

  Attributes:
    wind_speed: an anemometer's reading at the cloth, m/s.
    wind_speed_sd: its standard uncertainty, m/s.
    area_weight: a scale and a ruler's reading, kg/m^2.
    area_weight_sd: its standard uncertainty, kg/m^2.
    bending_length: a cantilever test's bending length c, m (Peirce: half the
      overhang at which a strip's tip reaches a 41.5-degree slope below the
      table's edge; or ``physsim.cantilever.bending_length`` of an overhang
      and its tip's reach). It reads bending and area weight together,
      c = (bending x D0 / (w g))^(1/3) (``physsim.params.bending_length``).
    bending_length_sd: its standard uncertainty, m.
    bending_length_dof: the law of its error: 0, Gaussian (a ruler's
      reading); more than 2, Student's t of that many degrees of freedom
      with standard deviation ``bending_length_sd`` (a depth camera's
      reading, ``physsim.overhang_depth.DOF``: most readings closer than a
      Gaussian of that sd would put them, a few further off).
    air_coefficient: 'fixed': the fabric takes the wind as ArcSim's sheet does
      (what the shipped calibration holds); 'free': its own air coefficient c,
      log-uniform over 0.3-1.5, read from the wind readings and the load the
      video sees (a joint of fan settings shares one c; without a reading c
      stays the prior's and the wind widens by it; not calibrated); 'auto':
      free in a joint estimate whose every recording has a wind reading (the
      protocol: what its fan recordings measure), else fixed.
  """

  wind_speed: float = 0.0
  wind_speed_sd: float = 0.0
  area_weight: float = 0.0
  area_weight_sd: float = 0.0
  bending_length: float = 0.0
  bending_length_sd: float = 0.0
  bending_length_dof: float = 0.0
  air_coefficient: str = cli.choice('auto', AIR_MODES)

  @property
  def air_free(self) -> bool:
    """The air coefficient is the fabric's own, not ArcSim's 1 (and a wind
    reading, where given, is the true wind, the search's the effective)."""
    return self.air_coefficient == 'free'

  def to_dict(self) -> dict:
    """The readings as files hold them: a bending length only when given, so
    that files without one (and runs to resume) stay as they were written
    before it was a reading."""
    out = dataclasses.asdict(self)
    if not (self.bending_length or self.bending_length_sd):
      del out['bending_length'], out['bending_length_sd']
    if not self.bending_length_dof:  # a Gaussian reading, as files held it
      del out['bending_length_dof']
    if not self.air_free:  # ArcSim's air, as files held it
      del out['air_coefficient']
    return out

  def check(self, space: physsim.SearchSpace) -> None:
    """Raises ValueError on a reading without uncertainty, or far outside the
    box, or a bending length's error law that is neither Gaussian nor a t
    with a finite variance."""
    check_dof(self.bending_length_dof, 'bending_length_dof')
    if self.air_coefficient not in AIR_MODES:
      raise ValueError(
        f'--air_coefficient={str(self.air_coefficient)[:40]!r}: one of {AIR_MODES}'
      )
    for name in ('wind_speed', 'area_weight', 'bending_length'):
      v, sd = getattr(self, name), getattr(self, f'{name}_sd')
      if v == 0 and sd == 0:
        continue
      if v == 0:
        raise ValueError(
          f'--{name}_sd={sd} was given without --{name} (the reading it is the '
          'uncertainty of)'
        )
      lo, hi = reading_range(space, name)
      if not sd > 0:
        raise ValueError(
          f'--{name}={v} needs --{name}_sd > 0 (its uncertainty), got {sd}'
        )
      if not v > 0:
        raise ValueError(f'--{name}={v}: a reading must be > 0')
      if v + 3 * sd < lo or v - 3 * sd > hi:
        raise ValueError(
          f'--{name}={v} +- {sd} lies outside the search range [{lo}, {hi}]'
        )


def reading_range(space: physsim.SearchSpace, name: str) -> tuple[float, float]:
  """The range of reading ``name`` over the search box (a bending length's
  from its bending and area weight ranges and the fabric's rigidity).

  Raises:
    ValueError: a bending length for a box of no fabric (its rigidity 0).
  """
  if name != 'bending_length':
    return getattr(space, name)
  if not space.rigidity > 0:
    raise ValueError(
      '--bending_length: the search box has no reference rigidity to read it '
      "against (physsim.search_space gives each fabric's)"
    )
  (b0, b1), (w0, w1) = space.bending_scale, space.area_weight
  lo = physsim.params.bending_length(b0, w1, space.rigidity)
  hi = physsim.params.bending_length(b1, w0, space.rigidity)
  return float(lo), float(hi)


def unit_error(rng: np.random.Generator, dof: float = 0.0) -> float:
  """A reading's error in units of its sd: standard normal, or (``dof`` > 2)
  Student's t of ``dof`` degrees of freedom scaled to unit variance."""
  if not dof:
    return float(rng.standard_normal())
  return float(rng.standard_t(dof) * math.sqrt((dof - 2) / dof))


def simulated_reading(
  name: str, truth: dict, rel_sd: float, seed: int, seq: int,
  space: physsim.SearchSpace | None = None, dof: float = 0.0,
) -> Measured:  # fmt: skip
  """A simulated instrument's reading of ``name`` ('wind_speed': an
  anemometer; 'area_weight': a scale and a ruler; 'bending_length': an
  overhang, Peirce's c of the truth's bending and area weight against
  ``space``'s rigidity) for a recording with known ``truth``: the truth times
  ``1 + rel_sd * z``, ``z`` standard normal drawn from ``(seed, seq)`` alone,
  so recording ``seq`` gets the same reading in every study that uses the
  same seed (the calibration's post-hoc modes and a search run with the
  reading as its prior). Its uncertainty is ``rel_sd`` times the truth. A
  bending length with ``dof`` > 2 errs as Student's t of that many degrees
  of freedom scaled to the same standard deviation (``Measured``), as the
  depth reader does; ``dof`` 0 keeps the Gaussian draw, the same number."""
  names = (*FIELDS[1:], 'bending_length')
  if name not in names:
    raise ValueError(f'no instrument reads {name!r}: one of {names}')
  if dof and name != 'bending_length':
    raise ValueError(f'{name}: only a bending length has a t law, got dof={dof}')
  if name == 'bending_length':
    reading_range(space, name)  # the box knows its fabric's rigidity
    value = float(
      physsim.params.bending_length(
        truth['bending_scale'], truth['area_weight'], space.rigidity
      )
    )  # fmt: skip
  else:
    value = truth[name]
  stream = FIELDS.index(name) if name in FIELDS else len(FIELDS)
  rng = np.random.default_rng([seed, 13, seq, stream])
  z = unit_error(rng, dof)
  v = value * (1.0 + rel_sd * z)
  out = Measured(**{name: v, f'{name}_sd': rel_sd * value})
  return dataclasses.replace(out, bending_length_dof=dof) if dof else out


SUB_CELLS = (32, 4)  # a bending length's term averaged over (bending, area weight)


MAX_DOF = 1000.0  # a bending length's t law (beyond it, say 0: the Gaussian)


def check_dof(dof: float, flag: str) -> None:
  """Raises ValueError naming ``--flag`` unless ``dof`` is 0 (a Gaussian
  reading) or a t law with a finite variance (more than 2, at most
  ``MAX_DOF``)."""
  if not (dof == 0 or (math.isfinite(dof) and 2 < dof <= MAX_DOF)):
    raise ValueError(
      f'--{flag}={dof}: 0 (a Gaussian reading) or a Student-t of more than 2 '
      f'and at most {MAX_DOF:g} degrees of freedom'
    )


def length_term(b, w, space: physsim.SearchSpace, measured: Measured):
  """The bending-length reading's log likelihood at physical (b, w), up to
  a constant: Gaussian, or Student's t with the reading's standard deviation
  (``Measured.bending_length_dof``)."""
  c = physsim.params.bending_length(b, w, space.rigidity)
  dof = measured.bending_length_dof
  if not dof:
    return -0.5 * ((c - measured.bending_length) / measured.bending_length_sd) ** 2
  scale = measured.bending_length_sd * math.sqrt((dof - 2) / dof)
  r = (c - measured.bending_length) / scale
  return -0.5 * (dof + 1) * np.log1p(r**2 / dof)


def cell_offsets(grid, sub=SUB_CELLS) -> np.ndarray:
  """(K, 3) unit offsets of a cell's sub-points (bending x area weight, the
  wind at the centre) from its centre, for a grid of ``grid`` cells."""
  width = 2.0 / np.asarray(grid, np.float64)
  ub = ((np.arange(sub[0]) + 0.5) / sub[0] - 0.5) * width[0]
  uw = ((np.arange(sub[1]) + 0.5) / sub[1] - 0.5) * width[2]
  bb, ww = np.meshgrid(ub, uw, indexing='ij')
  return np.stack([bb.ravel(), np.zeros(bb.size), ww.ravel()], axis=1)


def log_prior(points, space: physsim.SearchSpace, measured: Measured,
              grid=None) -> np.ndarray:  # fmt: skip
  """(G,) log prior at unit-cube ``points (G, 3)``: uniform in the box (so
  bending log-uniform), times a Gaussian for each measured quantity (a
  bending length's in the c that each point's bending and area weight give).

  With ``grid`` (the cells per dimension whose centres ``points`` are), a
  bending length's term is the cell's mean over ``SUB_CELLS`` sub-points
  rather than its centre's value: a strip reads c to a few percent, b to
  three times that, narrower than a cell of the search's grid (x1.47 in
  bending at the paper's 12), whose centres alone would put the posterior
  on whichever centre lies nearest the reading. ``refine_draws`` then places
  the draws within their cells by the same term.
  """
  out = np.zeros(len(points))
  phys = physsim.params.from_unit(np.clip(points, -1, 1), space)
  for i, name in enumerate(FIELDS):
    if name == 'bending_scale':
      continue
    v, sd = getattr(measured, name), getattr(measured, f'{name}_sd')
    if sd > 0 and name == 'wind_speed' and measured.air_free:
      out += air_wind_log_prior(np.ravel(phys[i]), v, sd)
    elif sd > 0:
      out += -0.5 * ((np.ravel(phys[i]) - v) / sd) ** 2
  if measured.bending_length_sd > 0:
    reading_range(space, 'bending_length')  # the box knows its fabric
    if grid is None:
      out += length_term(
        np.ravel(phys.bending_scale), np.ravel(phys.area_weight), space, measured
      )
    else:
      offsets = cell_offsets(grid)
      # the term is the same for every wind: once per (bending, area weight)
      bw, which = np.unique(
        np.asarray(points, np.float64)[:, [0, 2]], axis=0, return_inverse=True
      )
      centres = np.stack([bw[:, 0], np.zeros(len(bw)), bw[:, 1]], axis=1)
      sub = np.clip(centres[:, None, :] + offsets[None], -1.0, 1.0)
      p = physsim.params.from_unit(sub.reshape(-1, 3), space)
      term = length_term(p.bending_scale, p.area_weight, space, measured)
      term = term.reshape(len(bw), -1)
      top = term.max(axis=1)  # NumPy: the cells' count varies, nothing to compile
      cell = top + np.log(np.exp(term - top[:, None]).sum(axis=1))
      out += cell[np.ravel(which)] - np.log(len(offsets))
  return out


def physical(samples_unit, space: physsim.SearchSpace) -> np.ndarray:
  """(S, 3) unit-cube draws -> (S, 3) physical values in ``FIELDS`` order."""
  p = physsim.params.from_unit(np.clip(samples_unit, -1, 1), space)
  return np.stack([np.ravel(a) for a in p], axis=1)


def air_nodes(n: int = AIR_NODES, air_range=AIR_RANGE) -> tuple[np.ndarray, np.ndarray]:
  """(c (n,), log weight (n,)): the air coefficient's log-uniform prior as
  equal-weight nodes at the centres of n equal steps in log c."""
  lo, hi = np.log(np.asarray(air_range, np.float64))
  c = np.exp(lo + (hi - lo) * (np.arange(n) + 0.5) / n)
  return c, np.full(n, -np.log(n))


def effective_wind_log_density(v_eff, reading: float, sd: float, c) -> np.ndarray:
  """log p(v_eff | c), normalised in v_eff: the simulator's effective wind
  v_eff = v sqrt(c) of a fabric of air coefficient ``c`` blown at a true
  wind v that an anemometer read as ``reading`` +- ``sd`` (Gaussian):
  N(v_eff / sqrt(c); reading, sd) / sqrt(c). Broadcasts ``v_eff`` against
  ``c``."""
  v_eff, c = np.asarray(v_eff, np.float64), np.asarray(c, np.float64)
  z = (v_eff / np.sqrt(c) - reading) / sd
  return -0.5 * z**2 - np.log(sd * np.sqrt(2.0 * np.pi)) - 0.5 * np.log(c)


def _cell_scores(lo, hi, reading: float, sd: float, c) -> tuple:
  """(a, b): the reading's standard scores of the true winds v whose
  effective wind v sqrt(c) lies in the cell [lo, hi)."""
  root = np.sqrt(np.asarray(c, np.float64))
  lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
  return (lo / root - reading) / sd, (hi / root - reading) / sd


def _upper(a, b) -> tuple:
  """(a, b, mirrored): spans above the reading mirrored below it, so that a
  far cell's normal mass and inverse CDF keep their digits."""
  mirrored = a > 0
  return np.where(mirrored, -b, a), np.where(mirrored, -a, b), mirrored


def effective_wind_log_mass(lo, hi, reading: float, sd: float, c) -> np.ndarray:
  """log P(lo <= v_eff < hi | c): the reading's Gaussian mass of the true
  winds v whose effective wind v sqrt(c) lies in the cell [lo, hi). Exact,
  where the density at the cell's centre times its width errs once a cell is
  as wide as the reading's sd (a search's grid: 4-8% cells, 2% readings).
  Broadcasts the cells against ``c``."""
  a, b, _ = _upper(*_cell_scores(lo, hi, reading, sd, c))
  mass = scipy.special.ndtr(b) - scipy.special.ndtr(a)
  return np.log(np.maximum(mass, 1e-300))


def true_wind_in_cell(lo, hi, reading: float, sd: float, c, u) -> np.ndarray:
  """(S,) true winds v, each drawn from the reading's Gaussian restricted to
  its cell's span (v sqrt(c) in [lo, hi): each draw's cell and c, (S,) each)
  by the inverse CDF at the uniforms ``u`` (S,). A uniform position within
  the cell would widen the wind by the cell's width, which on a search's
  grid is as large as the reading's sd; a cell the reading leaves no mass
  (the video insists on it) keeps the uniform position."""
  a, b, mirrored = _upper(*_cell_scores(lo, hi, reading, sd, c))
  pa, pb = scipy.special.ndtr(a), scipy.special.ndtr(b)
  z = scipy.special.ndtri(pa + np.asarray(u) * (pb - pa))
  v = reading + sd * np.where(mirrored, -z, z)
  root = np.sqrt(np.asarray(c, np.float64))
  lo_v, hi_v = np.asarray(lo) / root, np.asarray(hi) / root
  uniform = lo_v + np.asarray(u) * (hi_v - lo_v)
  v = np.where(np.isfinite(v) & (pb - pa > 1e-12), v, uniform)
  return np.clip(v, lo_v, hi_v)


def air_wind_log_prior(v_eff, reading: float, sd: float) -> np.ndarray:
  """log p(v_eff): a wind reading's law for the effective wind with the air
  coefficient unknown (``effective_wind_log_density`` averaged over
  ``air_nodes``): the reading says where v is; the fabric's air stretches it
  by sqrt(c) either way."""
  c, log_w = air_nodes()
  terms = effective_wind_log_density(np.ravel(v_eff)[:, None], reading, sd, c[None])
  top = terms.max(axis=1, keepdims=True)
  return (top + np.log(np.exp(terms - top + log_w).sum(axis=1, keepdims=True)))[:, 0]


def air_given_wind(v_eff, reading: float, sd: float, seed: int) -> np.ndarray:
  """(S,) air coefficients drawn given each effective wind ``v_eff`` (S,) and
  the reading: p(c | v_eff) proportional to p(c) p(v_eff | c), on
  ``air_nodes`` jittered within their log steps (seeded)."""
  c, log_w = air_nodes()
  v_eff = np.ravel(np.asarray(v_eff, np.float64))
  logits = log_w + effective_wind_log_density(v_eff[:, None], reading, sd, c[None])
  p = np.exp(logits - logits.max(axis=1, keepdims=True))
  cdf = np.cumsum(p, axis=1)
  rng = np.random.default_rng([seed, 31])
  k = (cdf < rng.random(len(v_eff))[:, None] * cdf[:, -1:]).sum(axis=1)
  k = np.minimum(k, len(c) - 1)
  step = np.log(c[1] / c[0]) if len(c) > 1 else 0.0
  return c[k] * np.exp(step * (rng.random(len(v_eff)) - 0.5))


def air_draws(v_eff, measured: Measured, seed: int) -> np.ndarray:
  """(S,) air coefficients for draws of the effective wind ``v_eff`` (S,):
  given each and the wind reading (``air_given_wind``), or without a reading
  from the prior alone (the video sees c v^2 only: c stays the prior's)."""
  v_eff = np.ravel(np.asarray(v_eff, np.float64))
  if measured.wind_speed_sd > 0:
    return air_given_wind(v_eff, measured.wind_speed, measured.wind_speed_sd, seed)
  lo, hi = np.log(AIR_RANGE)
  return np.exp(np.random.default_rng([seed, 37]).uniform(lo, hi, len(v_eff)))


# A reading's range a search box must hold (issue 76: a reading outside the
# box was pinned at its edge, silently): its 99.9% central range (3.29 sd;
# a t law's own quantile), and the furthest the box is ever widened to (the
# simulator's and the flutter's limits).
READING_Z = 3.29
BOX_LIMITS = {'bending_scale': (0.01, 100.0), 'wind_speed': (0.3, 12.0),
              'area_weight': (0.02, 1.0)}  # fmt: skip


def _reading_span(measured: Measured, name: str) -> tuple[float, float] | None:
  """The 99.9% central range of reading ``name`` (None: not read)."""
  v, sd = getattr(measured, name), getattr(measured, f'{name}_sd')
  if not sd > 0:
    return None
  z = READING_Z
  dof = measured.bending_length_dof if name == 'bending_length' else 0.0
  if dof:  # Student's t scaled to sd: its own 99.9% quantile
    t = float(np.quantile(np.random.default_rng(0).standard_t(dof, 200_000), 0.9995))
    z = t * math.sqrt((dof - 2) / dof)
  return max(v - z * sd, 1e-6), v + z * sd


def check_box(box) -> None:
  """Raises ValueError unless ``box`` is six finite numbers, (low, high) for
  bending, wind and area weight, each low < high within ``BOX_LIMITS``."""
  if len(box) != 6 or not all(
    isinstance(v, int | float) and math.isfinite(v) for v in box
  ):
    raise ValueError(f'--box: six numbers (bending, wind, area weight lows and '
                     f'highs in pairs), got {str(tuple(box))[:80]}')  # fmt: skip
  for name, lo, hi in zip(FIELDS, box[::2], box[1::2], strict=True):
    limit = BOX_LIMITS[name]
    if not limit[0] <= lo < hi <= limit[1]:
      raise ValueError(
        f'--box: {name} {lo:g}-{hi:g}; need low < high within {limit[0]:g}-{limit[1]:g}'
      )


def search_box(
  material: str, measured: Measured, box=()
) -> tuple[physsim.SearchSpace, list]:
  """The search box: ``box`` where given (``Search.box``), else the fabric's
  (``physsim.search_space``) widened, where a reading needs it, to hold the
  reading's 99.9% range (with the air coefficient free, the wind's stretched
  by sqrt(c)); a bending length's as the bending its range gives over the
  area weights the box (or a scale's reading) allows. Never beyond
  ``BOX_LIMITS``.

  Returns:
    The box, and one line per widened field saying what widened it.
  """
  space = physsim.search_space(material)
  if box:
    pairs = dict(zip(FIELDS, zip(box[::2], box[1::2], strict=True), strict=True))
    return dataclasses.replace(space, **pairs), []
  want = {}
  wind = _reading_span(measured, 'wind_speed')
  if wind is not None:
    lo, hi = wind
    if measured.air_free:
      lo, hi = lo * math.sqrt(AIR_RANGE[0]), hi * math.sqrt(AIR_RANGE[1])
    want['wind_speed'] = (lo, hi, 'the wind reading')
  weight = _reading_span(measured, 'area_weight')
  if weight is not None:
    want['area_weight'] = (*weight, 'the weighed area weight')
  length = _reading_span(measured, 'bending_length')
  if length is not None and space.rigidity > 0:
    w_lo, w_hi = weight if weight is not None else space.area_weight
    g = physsim.params.GRAVITY
    b = (length[0] ** 3 * w_lo * g / space.rigidity,
         length[1] ** 3 * w_hi * g / space.rigidity)  # fmt: skip
    want['bending_scale'] = (*b, "the strip's bending length")
  fields, said = {}, []
  for name, (lo, hi, what) in want.items():
    old = getattr(space, name)
    limit = BOX_LIMITS[name]
    new = (max(min(old[0], lo), limit[0]), min(max(old[1], hi), limit[1]))
    new = (min(new[0], old[0]), max(new[1], old[1]))  # never narrower
    if new != tuple(old):
      fields[name] = new
      said.append(
        f'{SHORT[name]} box {old[0]:.3g}-{old[1]:.3g} widened to '
        f'{new[0]:.3g}-{new[1]:.3g} to hold {what}'
      )
  return dataclasses.replace(space, **fields), said
