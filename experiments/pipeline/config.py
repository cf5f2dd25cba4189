"""The estimate's settings, a section per stage, and its presets.

``EstimateConfig`` holds one section per stage: ``simulation`` (the cloth and
its clock, ``simulation.Simulation``), ``scoring`` (the distance and the
likelihood), ``search`` (the design, stopping rule and posterior grid),
``hardware`` (backend and workers) and ``measured`` (the readings,
``measurements.Measured``). Scripts build it from flags and ``setup.resolve``
checks it once; each stage reads its own section.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping

import numpy as np

import bo
import physsim
from experiments.pipeline import cli, measurements
from experiments.pipeline.measurements import Measured
from experiments.pipeline.simulation import Simulation

BACKENDS = physsim.BACKENDS


DISTANCES = ('energy', 'centroid', 'shape', 'energy+shape')


# Distances that compare the sheet's mean shape (physsim.shape), and those
# that embed frames with the network.
SHAPE_DISTANCES = ('shape', 'energy+shape')


EMBEDDING_DISTANCES = ('energy', 'centroid', 'energy+shape')


# A trained network's distance (the paper's PSD): what --preset=paper and the
# studies of networks read; the estimate's default is the shape.
NETWORK_DISTANCE = 'energy'


POINTS = ('median', 'bayes', 'argmin')


LIKELIHOODS = bo.posterior.LIKELIHOODS
# Where an estimate's camera error came from (``Scoring.camera_sd_from``).
CAMERA_SOURCES = ('given', 'intake')


@dataclasses.dataclass(frozen=True)
class Scoring:
  """How a candidate's frames are scored against the recording's, and how
  the scores are read as a likelihood.

  Attributes:
    distance: the discrepancy of a candidate's frames to the recording's:
      'shape' (the default), the squared distance between the sheet's mean
      shape in the world (physsim.shape: how far it is blown back and
      lifted; no network; needs the recording's camera pose); the PSD
      between embedding sets of a trained PhySNet ('energy' or 'centroid');
      or 'energy+shape', the geometric mean of the energy PSD and that. The
      default is the one that reads more on the same real-like recordings
      (BENCHMARKS.md, "The video alone at paper size"); the paper's protocol
      (``PRESETS['paper']``) keeps the PSD.
    camera_sd_m: how far the recording's camera may be shifted from where the
      simulator's world has it, metres (1 sd per axis): every simulation is
      rendered from a camera moved by such an error and read as from the given
      one, so the shape discrepancy scatters as the recording's does and the
      posterior carries the alignment's error. 0 (with camera_sd_deg 0): a
      camera known exactly (simulated recordings). The intake's pins were
      within about 2 cm on its test recording (docs/recordings.md).
    camera_sd_deg: the same for the camera's rotation about the pins, degrees
      (1 sd per axis); the intake's camera was within 3 degrees on its test
      recording.
    camera_sd_from: where that error came from: 'given' (a user's, or none)
      or 'intake' (the intake's own claim for its alignment, which
      ``user_recordings.with_alignment_error`` carries; no flag sets it). It
      changes no search, only which calibration tables hold: those whose
      recordings' cameras were displaced as the intake actually errs against
      its claim (``experiments.calibrate --camera_errors``) hold for the
      intake's claims alone; those displaced by the full claimed error hold
      for either.
    likelihood: the posterior's approximate likelihood from the
      discrepancy, 'gibbs' or 'threshold' (BOLFI's; see bo.posterior); or,
      with ``distance='shape'``, 'synthetic': GP emulators of the shape
      summary's two components and the Gaussian likelihood their scatter
      implies (bo.synthetic).
    sharpness: the likelihood's constant, calibrated on simulations
      (experiments/calibrate.py; docs/studies/calibration.md): the default is the
      value the shipped calibration chose. For 'synthetic', the exponent
      that tempers its likelihood (1: untempered).
    model_error: the likelihood's model-discrepancy term ('gibbs',
      'threshold'; bo.posterior): scatter of the log distance that the
      simulator's own randomness does not make (a world of other physics),
      added to it in quadrature. 0: the simulator is taken as the world; the
      calibration study fits it on recordings of another physics
      (experiments/calibrate.py --physics=mismatched --model_error=...).
    calibration: a calibration file (``experiments/calibrate.py``'s
      ``calibration.json``) whose tables the estimate applies where its
      settings and network match; '' for the shipped one. It only changes how
      the posterior is read, so a resumed run may use another.
    shared_bias: a joint estimate's shared discrepancy, the sd of one log
      area weight error common to all its recordings (``posterior.joint``):
      the simulator differs from the world the same way in each, so more
      recordings do not average it away. Fitted on groups of three gentle fan
      settings recorded under another physics (``benchmarks.shared_bias``:
      at 0 their joint 90% intervals held the area weight in 10 of 16 groups).
      Only a joint that no shipped table covers reads it (a joint of two
      recordings at calibrated settings was calibrated, and checked on
      another physics, without it).
  """

  distance: str = cli.choice('shape', DISTANCES)
  camera_sd_m: float = 0.0
  camera_sd_deg: float = 0.0
  camera_sd_from: str = cli.choice('given', CAMERA_SOURCES)
  likelihood: str = cli.choice('gibbs', LIKELIHOODS)
  sharpness: float = 0.5
  model_error: float = 0.0
  calibration: str = ''
  shared_bias: float = 0.1


@dataclasses.dataclass(frozen=True)
class Search:
  """What the search reports and its budget.

  Attributes:
    point: the posterior's point with 50% and 90% credible intervals (a
      posterior search; fresh gusts and sensor noise for every simulation):
      'median', or 'bayes', the value with the least expected error (the
      factor for bending, percent for area weight; for the wind and the load
      ratio the median: ``posterior.POINT_LOSS``), which where the video says
      little stays near the guess that errs least over the search box; or
      'argmin': the paper's protocol, the lowest PSD that Bayesian optimisation found
      (common random numbers), with no calibrated interval.
    q: candidates per iteration (one simulation batch).
    n_init: initial design size (the first point is the range centre).
    max_iter: most iterations after the initial design.
    stop_rel_change: stopping rule: the best point (argmin), or every 5%,
      50% and 95% posterior quantile (median), moved less than this share of
      each range over the last stop_window iterations.
    stop_window: iterations the stopping rule looks back.
    min_iter: iterations before the stopping rule is checked.
    posterior_grid: posterior grid cells per dimension (bending, wind, area
      weight).
    replicates: candidates per iteration that repeat the most probable cell
      with fresh randomness (they measure the simulator's noise).
    box: the search box, bending scale, wind (m/s) and area weight (kg/m^2)
      as (low, high) pairs, six numbers; empty: the fabric's own, widened
      where a reading needs it (``measurements.search_box``; a joint
      estimate's recordings share the widest).
  """

  point: str = cli.choice('bayes', POINTS)
  # 120 simulations in three calls of 40: on a GPU a call of up to ~48 worlds
  # costs one call's fixed time (evaluation.FLAT_WORLDS), so fewer, larger steps
  # are faster; the shipped paper-size tables were fitted with this budget.
  q: int = 40
  n_init: int = 40
  max_iter: int = 2
  stop_rel_change: float = 0.05
  stop_window: int = 2
  min_iter: int = 2
  posterior_grid: tuple[int, ...] = (12, 64, 24)
  replicates: int = 1
  box: tuple[float, ...] = ()

  @property
  def posterior(self) -> bool:
    """A posterior search (a median or Bayes point), not the paper's argmin."""
    return self.point != 'argmin'

  @property
  def common_random_numbers(self) -> bool:
    """The paper's argmin scores every candidate with the same gusts and
    sensor noise; a posterior needs fresh ones per simulation."""
    return self.point == 'argmin'


@dataclasses.dataclass(frozen=True)
class Hardware:
  """Where the simulations run; neither changes results.

  Attributes:
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else
      MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
    workers: threads of the C backend (0: one per core); does not change
      results, so a resumed run may use another value.
  """

  backend: str = cli.choice('auto', BACKENDS)
  workers: int = 0


# EstimateConfig's sections: each flat setting name belongs to one of them.
SECTIONS = ('simulation', 'scoring', 'search', 'hardware', 'measured')


@dataclasses.dataclass(frozen=True)
class EstimateConfig:
  """Settings of one estimate (also what a resumed run must match), in
  sections; every leaf field is a flag of its own name (``cli.leaves``).

  ``replace`` and ``preset`` take the flat names
  (``config.replace(q=8, material='black_denim')``), and files hold the flat
  form (``flat``, ``from_flat``: run.json, estimate.json, calibration files).

  Attributes:
    simulation: what is simulated and rendered (``Simulation``).
    scoring: the discrepancy and the likelihood (``Scoring``).
    search: the point reported and the search's budget (``Search``).
    hardware: where simulations run (``Hardware``).
    seed: all randomness (design, gusts, sensor noise, cameras).
    measured: an anemometer's wind or a scale's area weight, as priors.
  """

  simulation: Simulation = Simulation()
  # where the camera error came from is set by the intake, never a flag
  scoring: Scoring = cli.nested(Scoring(), skip=('camera_sd_from',))
  search: Search = Search()
  hardware: Hardware = Hardware()
  seed: int = 0
  measured: Measured = Measured()

  @property
  def posterior(self) -> bool:
    """A posterior search (a median or Bayes point), not the paper's argmin."""
    return self.search.posterior

  @property
  def common_random_numbers(self) -> bool:
    """The paper's argmin scores every candidate with the same gusts and
    sensor noise; a posterior needs fresh ones per simulation."""
    return self.search.common_random_numbers

  @classmethod
  def preset(cls, name: str, **fields) -> EstimateConfig:
    """A named preset (``PRESETS``: 'default', the paper-size posterior;
    'paper', the paper's argmin; 'demo', the demo's CPU size; 'smoke', a
    quicker look) with ``fields`` (flat names, ``replace``) replaced, e.g.
    ``EstimateConfig.preset('demo', material='black_denim')``.

    Raises:
      ValueError: an unknown preset, naming the known ones; an unknown field.
    """
    if name not in PRESETS:
      raise ValueError(f'no estimate preset {name!r}: one of {sorted(PRESETS)}')
    return PRESETS[name].replace(**fields)

  def replace(self, **fields) -> EstimateConfig:
    """This config with ``fields`` replaced, by their flat names (``q=8``,
    ``material='black_denim'``, ``wind_speed=3.0``: each goes to its section)
    or by section (``search=Search(...)``, ``measured=Measured(...)``; a flat
    name given with its section applies on top of it).

    Raises:
      ValueError: a name that is no setting, naming it.
    """
    top, parts = {}, {}
    for name, value in fields.items():
      if name in _TOP_FIELDS:
        top[name] = value
      elif name in _SECTION_OF:
        parts.setdefault(_SECTION_OF[name], {})[name] = value
      else:
        raise ValueError(
          f'EstimateConfig has no setting {name!r}: one of '
          f'{sorted(_SECTION_OF) + sorted(_TOP_FIELDS)}'
        )
    for section, changed in parts.items():
      top[section] = dataclasses.replace(
        top.get(section, getattr(self, section)), **changed
      )
    return dataclasses.replace(self, **top)

  def flat(self) -> dict:
    """Every setting by its flat name (``measured`` a dict of its own): the
    form run.json, estimate.json and calibration files hold."""
    out = {'seed': self.seed, 'measured': self.measured.to_dict()}
    for section in SECTIONS:
      if section != 'measured':
        out.update(dataclasses.asdict(getattr(self, section)))
    if out['shared_bias'] == Scoring.shared_bias:  # files as before it was a setting
      del out['shared_bias']
    if out['camera_sd_from'] == 'given':  # ... and before the intake's was marked
      del out['camera_sd_from']
    if not out['hem_mass']:  # ... and before a hem could be simulated
      del out['hem_mass']
    if not out['box']:  # ... and before the box could be set
      del out['box']
    return out

  @classmethod
  def from_flat(cls, data: Mapping) -> EstimateConfig:
    """The config of a ``flat`` dict as read back from JSON (lists as tuples).
    Settings it lacks (a file from before they existed) take their defaults;
    a section given as a dict of its own (``config_io.to_dict``'s nested form)
    is read too.

    Raises:
      ValueError: a name that is no setting, or not a JSON object.
    """
    if not isinstance(data, Mapping):
      raise ValueError(f'an estimate config must be a JSON object, got {data!r}')
    fields = {}
    for name, value in data.items():
      if name in SECTIONS and isinstance(value, Mapping):
        if name == 'measured':
          unknown = sorted(set(value) - {f.name for f in dataclasses.fields(Measured)})
          if unknown:
            raise ValueError(f'measured has no setting {unknown}')
          fields['measured'] = Measured(**value)
        else:
          fields.update(value)
      else:
        fields[name] = value
    fields = {k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()}
    return cls().replace(**fields)

  from_dict = from_flat  # config_io.from_dict reads a nested config with it

  def check(self) -> None:
    """Raises ValueError naming the first field outside its allowed values
    (every number finite first: ``cli.check_numbers``)."""
    cli.check_numbers(self)
    sim, sc, se = self.simulation, self.scoring, self.search
    flat = self.flat()
    if sim.material not in physsim.FABRICS:
      raise ValueError(
        f'material {sim.material!r} is not one of {sorted(physsim.FABRICS)}'
      )
    if sim.garment and sim.garment not in physsim.GARMENTS:
      raise ValueError(f'garment {sim.garment!r} is not one of {physsim.GARMENTS}')
    if sim.garment and sim.hem_mass:
      raise ValueError(
        f"hem_mass={sim.hem_mass} kg hangs along the square cloth's free edge; "
        f'garment {sim.garment!r} has none'
      )
    flat['camera_sd_from'] = sc.camera_sd_from  # flat() leaves out 'given'
    for name, allowed in (
      ('backend', BACKENDS), ('distance', DISTANCES), ('point', POINTS),
      ('likelihood', LIKELIHOODS), ('camera_sd_from', CAMERA_SOURCES),
    ):  # fmt: skip
      if flat[name] not in allowed:
        raise ValueError(f'{name} must be one of {allowed}, got {flat[name]!r}')
    if len(se.posterior_grid) != 3 or min(se.posterior_grid) < 2 or sc.sharpness <= 0:
      raise ValueError(
        'need a posterior_grid of 3 sizes >= 2 and sharpness > 0, got '
        f'{se.posterior_grid}, {sc.sharpness}'
      )
    if sc.likelihood == 'synthetic' and sc.distance != 'shape':
      raise ValueError(
        "likelihood 'synthetic' models the shape summary: it needs "
        f"distance 'shape', got {sc.distance!r}"
      )
    if sc.likelihood == 'synthetic' and sc.model_error:
      raise ValueError(
        f"--model_error={sc.model_error}: the 'synthetic' likelihood takes the "
        "summaries' own scatter; use 'gibbs' or 'threshold'"
      )
    if self.posterior and not 0 <= se.replicates < se.q:
      raise ValueError(f'need 0 <= replicates < q, got {se.replicates}, {se.q}')
    if se.box:
      measurements.check_box(se.box)
    self.measured.check(measurements.search_box(sim.material, self.measured, se.box)[0])
    if sc.calibration and not os.path.isfile(sc.calibration):
      raise ValueError(
        f'calibration {sc.calibration!r}: no such file (experiments/calibrate.py '
        'writes one)'
      )
    for name in ('frames', 'cameras', 'q', 'n_init', 'cloth_resolution'):
      if flat[name] < 1:
        raise ValueError(f'{name} must be >= 1, got {flat[name]}')
    if not (1 <= sim.fps <= 240):
      raise ValueError(f'fps must be in [1, 240] Hz, got {sim.fps}')
    if sim.frames > 1000 or not (0 <= sim.warmup <= 10):
      raise ValueError(
        f'need frames <= 1000 and 0 <= warmup <= 10 s, got {sim.frames}, {sim.warmup}'
      )
    if not (0 <= sc.camera_sd_m <= 0.2 and 0 <= sc.camera_sd_deg <= 20):
      raise ValueError(
        'need 0 <= camera_sd_m <= 0.2 (metres) and 0 <= camera_sd_deg <= 20 '
        f'(degrees), got {sc.camera_sd_m}, {sc.camera_sd_deg}'
      )
    if not (0 <= sim.gusts <= 1) or se.max_iter < 0:
      raise ValueError(
        f'need 0 <= gusts <= 1 and max_iter >= 0, got {sim.gusts}, {se.max_iter}'
      )
    flat.setdefault('shared_bias', sc.shared_bias)  # flat() leaves out its default
    flat.setdefault('hem_mass', sim.hem_mass)  # ... and a hem's
    for name, lo, hi in _RANGES:
      v = flat[name]
      if not lo <= v <= hi:
        raise ValueError(f'--{name}={v}: must be in [{lo:g}, {hi:g}]')
    if max(se.posterior_grid) > 1000 or np.prod(se.posterior_grid) > 5e6:
      raise ValueError(
        f'--posterior_grid={",".join(map(str, se.posterior_grid))}: at most 1000 '
        'cells per dimension and 5 million in all'
      )


def record(config) -> dict:
  """``dataclasses.asdict`` of a script's config, each ``EstimateConfig`` in
  it flat (``EstimateConfig.flat``): the form its files hold."""
  if isinstance(config, EstimateConfig):
    return config.flat()
  return {
    f.name: record(v) if dataclasses.is_dataclass(v) else v
    for f in dataclasses.fields(config)
    for v in (getattr(config, f.name),)
  }


# Each flat setting name's section (EstimateConfig.replace), and the fields
# set whole.
_SECTION_OF = {
  f.name: section
  for section, kind in zip(
    SECTIONS, (Simulation, Scoring, Search, Hardware, Measured), strict=True
  )
  for f in dataclasses.fields(kind)
}


_TOP_FIELDS = tuple(f.name for f in dataclasses.fields(EstimateConfig))


# The other numeric fields' allowed ranges (EstimateConfig.check): beyond
# them a search is a typo (or would not fit in memory), never a setting.
_RANGES = (
  ('sharpness', 1e-6, 1e6), ('model_error', 0.0, 100.0), ('shared_bias', 0.0, 1.0), ('cloth_resolution', 2, 200), ('cloth_size', 0.05, 3.0),
  ('hem_mass', 0.0, 1.0),
  ('garment_spacing', 0.005, 0.5), ('cameras', 1, 64), ('q', 1, 4096),
  ('n_init', 1, 100_000), ('max_iter', 0, 10_000), ('stop_rel_change', 0.0, 1.0),
  ('stop_window', 1, 10_000), ('min_iter', 0, 10_000), ('replicates', 0, 4096),
  ('workers', 0, 4096), ('seed', 0, 2**31 - 1),
)  # fmt: skip


# The paper's protocol: Bayesian optimisation to the lowest PSD (qUCB there,
# log-EI here), from the range centre, stopped when the best point settles.
PAPER = EstimateConfig().replace(
  distance=NETWORK_DISTANCE,
  point='argmin',
  q=4,
  n_init=8,
  max_iter=30,
  stop_rel_change=0.1,
  stop_window=3,
  min_iter=5,
)


PRESETS = {
  'default': EstimateConfig(),
  'paper': PAPER,
  # What experiments.demo estimates with: the demo network's cloth and clip,
  # minutes on a CPU.
  'demo': EstimateConfig().replace(
    cloth_resolution=10, frames=16, warmup=0.5, q=8, n_init=16, max_iter=6
  ),
  # A quick look on a CPU: small cloth, short clip, few iterations.
  'smoke': EstimateConfig().replace(
    cloth_resolution=10,
    frames=16,
    warmup=0.5,
    q=8,
    n_init=16,
    max_iter=3,
    posterior_grid=(8, 32, 16),
  ),
}
