"""The estimate's objective: one fused, jitted simulate-render-sense-embed-score.

A candidate is a point ``u`` of the unit cube ``[-1, 1]^3`` (bending
log-uniform, wind and area weight linear over the material's search box).
``Objective`` maps a batch of candidates of one or several recordings to their
physics similarity distance (PSD) in one ``jax.jit``::

  u (P, q, 3), keys ──► physical parameters ──► rollout (MJX, or MuJoCo C
  through a host callback) ──► blown-up worlds replaced by the rest mesh ──►
  ray-cast from each recording's camera(s) ──► depth-sensor model ──►
  network inputs ──► embedding (each recording's own network params; every
  member of an ensemble) ──► energy distance to the recording's embedding
  (an ensemble's: the members' geometric mean) ──► PSD (P, q), NaN where the
  simulation blew up

or, with ``distance='shape'``, no network: the squared distance between the
sheet's mean shape in the world (``physsim.shape``) in each candidate's frames
and in the recording's (the recording's camera pose is needed), and with
``'energy+shape'`` the geometric mean of that and the PSD.

Nothing returns to the host in between; only the scores come back (and, when
asked, the best candidate's frames or every candidate's positions). The
program depends on the ``Problem.structure`` (mesh, clock, camera model,
network architecture, sensor, distance); recordings of one structure share one
compile and are scored in one call, with their arrays (poses, network params,
embedding of the recording, search box) stacked on a leading axis.

Randomness: every candidate has its own gust and sensor-noise key (explicit
arguments). A posterior search (``point='median'``) draws fresh keys for every
evaluation, so repeated candidates show the simulator's noise, which its GP
models; the paper's argmin (``point='argmin'``) gives all candidates of a
search the same keys (common random numbers: a smoother objective for a
minimiser, at the price of one gust history's bias).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import bo
import model as model_lib
import physsim
from experiments.pipeline import cli, embedding
from experiments.pipeline.measurements import Measured
from experiments.pipeline.recording import Recording

# The simulation section and its cloth, re-exported (objective.mesh, ...).
from experiments.pipeline.simulation import Simulation as Simulation
from experiments.pipeline.simulation import cloth as cloth
from experiments.pipeline.simulation import mesh as mesh
from experiments.pipeline.simulation import pin_centre as pin_centre
from experiments.pipeline.simulation import sim_config as sim_config

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
    likelihood: the posterior's approximate likelihood from the
      discrepancy, 'gibbs' or 'threshold' (BOLFI's; see bo.posterior); or,
      with ``distance='shape'``, 'synthetic': GP emulators of the shape
      summary's two components and the Gaussian likelihood their scatter
      implies (bo.synthetic).
    sharpness: the likelihood's constant, calibrated on simulations
      (experiments/calibrate.py; docs/calibration.md): the default is the
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
  """

  point: str = cli.choice('bayes', POINTS)
  # 120 simulations in three calls of 40: on a GPU a call of up to ~48 worlds
  # costs one call's fixed time (search.FLAT_WORLDS), so fewer, larger steps
  # are faster; the shipped paper-size tables were fitted with this budget.
  q: int = 40
  n_init: int = 40
  max_iter: int = 2
  stop_rel_change: float = 0.05
  stop_window: int = 2
  min_iter: int = 2
  posterior_grid: tuple[int, ...] = (12, 64, 24)
  replicates: int = 1

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
  scoring: Scoring = Scoring()
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
    if not out['hem_mass']:  # ... and before a hem could be simulated
      del out['hem_mass']
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
    for name, allowed in (
      ('backend', BACKENDS), ('distance', DISTANCES), ('point', POINTS),
      ('likelihood', LIKELIHOODS),
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
    self.measured.check(physsim.search_space(sim.material))
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


class ProblemData(NamedTuple):
  """One recording's arrays (stack several on a leading axis to score them together).

  Attributes:
    lo, hi: (3,) the search box in the optimiser's coordinates
      (``physsim.params.unit_map``: bending as logs).
    log: (3,) which fields map log-uniformly.
    rigidity_ratio: () the fabric's reference bending over the cloth model's.
    poses: ``physsim.Pose`` of its C cameras, rotation (C, 3, 3), position (C, 3).
    color: (3,) the fabric's RGB colour (RGB networks; unused for depth).
    params: its network's params (an ensemble's stacked, leading axis K).
    rec_points: (N, D) the recording's embedding ((K, N, D) for an ensemble).
    rec_shape: (2,) the recording's ``physsim.shape.summary`` (zeros when the
      distance does not use it).
  """

  lo: jax.Array
  hi: jax.Array
  log: jax.Array
  rigidity_ratio: jax.Array
  poses: physsim.Pose
  color: jax.Array
  params: object
  rec_points: jax.Array
  rec_shape: jax.Array


class Problem(NamedTuple):
  """One recording's objective: host-side description plus its arrays.

  Attributes:
    config: its settings.
    source: the recording's path (for messages).
    space: the material's search space.
    n_frames: frames simulated (the recording's, at ``config.simulation.fps``).
    intr: camera intrinsics (the recording's or a default field of view).
    net: its embedding network.
    data: its ``ProblemData``.
  """

  config: EstimateConfig
  source: str
  space: physsim.SearchSpace
  n_frames: int
  intr: physsim.Intrinsics
  net: embedding.EmbeddingNet
  data: ProblemData

  def structure(self) -> tuple:
    """What the fused program is compiled for: problems with equal structure
    share one ``Objective`` and are scored in one call."""
    c, n = self.config, self.net
    s, h = c.simulation, c.hardware
    return (
      s.garment, s.garment_spacing if s.garment else 0.0,
      0 if s.garment else s.cloth_resolution, 0.0 if s.garment else s.cloth_size,
      s.hem_mass,
      self.n_frames, s.fps, s.warmup,
      s.gusts, physsim.resolve_backend(h.backend), h.workers, self.intr,
      self.data.poses.position.shape[0], s.sensor_noise, c.scoring.distance,
      c.scoring.camera_sd_m, c.scoring.camera_sd_deg,
      n.modality, n.input_mode, n.clip_frames, n.architecture, n.members,
      jax.tree.structure(n.params),
    )  # fmt: skip


def make_problem(
  config: EstimateConfig, net: embedding.EmbeddingNet, recording: Recording
) -> Problem:
  """Sets up one recording's objective: checks it against the network, picks
  its cameras and embeds it.

  Raises:
    ValueError: a bad config, a recording whose frames do not fit the network
      (size, modality, shorter than an SDN clip), naming the recording.
  """
  config.check()
  sim, distance = config.simulation, config.scoring.distance
  if net.network is None and distance in EMBEDDING_DISTANCES:
    raise ValueError(
      f'{recording.source}: distance {distance!r} embeds frames with a '
      "trained network, and none was given; only 'shape' needs none (--model)"
    )
  size = tuple(net.image_size)
  if tuple(recording.depth.shape[1:]) != size:
    raise ValueError(
      f'{recording.source}: frames of {recording.depth.shape[1:]} but the '
      f'network takes {size}; load the recording at that size'
    )
  rec_frames = recording.rgb if net.modality == 'rgb' else recording.depth
  if rec_frames is None:
    raise ValueError(
      f'{recording.source}: no RGB frames, but the network embeds colour frames '
      '(load_recording(..., rgb=True) of a sequence with cam0/rgb_*.png)'
    )
  n_frames = rec_frames.shape[0]
  if net.clip_frames and n_frames < net.clip_frames:
    raise ValueError(
      f'{recording.source}: {n_frames} frames at {recording.fps} fps, shorter '
      f'than one SDN clip of {net.clip_frames} frames; use a longer recording '
      '(and --frames >= the clip)'
    )
  shaped = distance in SHAPE_DISTANCES
  if shaped and (recording.pose is None or net.modality != 'depth'):
    raise ValueError(
      f"{recording.source}: distance {distance!r} compares the sheet's "
      "shape in the world, so it needs the recording's camera pose "
      '(--camera_json) and a depth network'
    )
  rec_points = jnp.zeros((1, 1), jnp.float32)  # no network: nothing embedded
  if net.network is not None:  # on the network's device
    inputs = embedding.network_inputs(
      jnp.asarray(rec_frames)[None], net.modality, net.input_mode
    )
    # (N, D), or (K, N, D) for an ensemble of K: each member's own embedding.
    rec_points = jax.jit(embedding.embed_videos, static_argnums=(0, 3, 4))(
      net.network, net.params, inputs, net.clip_frames, net.members
    )[..., 0, :, :]
  with physsim.devices.on_host():  # small arrays: placed by each call
    space, intr, poses, rec_shape = _recording_view(config, recording, shaped)
    lo, hi, log = physsim.params.unit_map(space)
    model = cloth(sim)
    data = ProblemData(
      jnp.asarray(lo, jnp.float32), jnp.asarray(hi, jnp.float32), jnp.asarray(log),
      jnp.float32(physsim.reference_rigidity(sim.material) / model.rigidity),
      poses, jnp.asarray(embedding.rgb_color(sim.material), jnp.float32),
      net.params, rec_points, rec_shape,
    )  # fmt: skip
  return Problem(config, recording.source, space, n_frames, intr, net, data)


# A recording's shape summary as one program, compiled once per frame shape and
# camera model (``Intrinsics`` is hashable) for every recording a process reads.
_shape_summary = jax.jit(physsim.shape.summary, static_argnums=1)


def _recording_view(config: EstimateConfig, recording: Recording, shaped: bool):
  """The recording's search box, camera model, camera poses and (for a shape
  distance) its sheet's shape summary (``physsim.shape.summary``, one jitted
  program rather than an eager operation at a time)."""
  sim = config.simulation
  space = physsim.search_space(sim.material)
  h, w = recording.depth.shape[1:]
  key = jax.random.key(config.seed)
  # A known field of view is used even when the pose is unknown.
  intr = recording.intrinsics or physsim.Intrinsics(width=w, height=h)
  if recording.pose is not None:
    poses = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32)[None], recording.pose)
  else:
    ranges = physsim.PoseRanges()
    if not sim.garment:
      ranges = ranges.for_cloth(sim.cloth_size)
    poses = physsim.sample_poses(jax.random.fold_in(key, 1), sim.cameras, ranges)
  rec_shape = jnp.zeros(len(physsim.shape.SUMMARY), jnp.float32)
  if shaped:
    rec_shape = _shape_summary(
      jnp.asarray(recording.depth), intr, jax.tree.map(lambda a: a[0], poses)
    )
    if not np.all(np.isfinite(np.asarray(rec_shape))):
      raise ValueError(f'{recording.source}: no frame has a valid depth pixel')
  return space, intr, poses, rec_shape


class Scores(NamedTuple):
  """What one ``Objective`` call returns (host arrays).

  Attributes:
    psd: (P, q) float64 PSD, NaN where the simulation blew up.
    valid: (P, q) bool, False where it blew up.
    frames: (P, T, H, W) depth or (P, T, H, W, 3) uint8 colour of each
      problem's lowest-PSD candidate, camera 0, as its network saw them; or
      None when not asked.
    positions: (P, q, T, V, 3) simulated vertex positions, or None.
    residual: (P, q, 2) float64 the candidates' ``physsim.shape.summary``
      minus the recording's (NaN where the PSD is; zeros without a shape
      distance): what the 'synthetic' likelihood is told.
  """

  psd: np.ndarray
  valid: np.ndarray
  frames: np.ndarray | None = None
  positions: np.ndarray | None = None
  residual: np.ndarray | None = None


class Objective:
  """The fused program of one ``Problem.structure``, compiled once per
  (P, q) shape (and count of distinct simulations, where worlds repeat:
  ``distinct_worlds``) and kept by this object (no global caches).

  Call it with stacked ``ProblemData`` of P problems of that structure,
  candidates ``u (P, q, 3)`` and per-candidate keys ``(P, q)``. Worlds whose
  simulations are the same are simulated once and scored each against its own
  recording.
  """

  def __init__(self, problem: Problem):
    c, net = problem.config, problem.net
    s, hw, sc = c.simulation, c.hardware, c.scoring
    self.structure = problem.structure()
    self.cloth = cloth(s)
    self.mesh = self.cloth.mesh
    self.n_frames = problem.n_frames
    self._rollout = physsim.rollout_fn(
      self.cloth, frames=problem.n_frames, fps=s.fps, warmup=s.warmup,
      backend=hw.backend, workers=hw.workers or None,
    )  # fmt: skip
    self._wind = physsim.Wind(gust_intensity=s.gusts)
    self._intr = problem.intr
    self._net = net
    self._sensor = s.sensor_noise and net.modality == 'depth'
    self._distance = sc.distance
    self._camera_sd = (sc.camera_sd_m, sc.camera_sd_deg)
    self._pins = pin_centre(s)
    cams, (h, w) = (
      problem.data.poses.position.shape[0],
      (problem.intr.height, problem.intr.width),
    )
    # Worlds scored at once per device (render, sensor, network), from the
    # device's free memory: the network's activations dominate.
    per_world = (
      cams
      * problem.n_frames
      * h
      * w
      * _bytes_per_pixel(net.params)
      * max(net.members, 1)
    )
    self._chunk = physsim.devices.chunk_size(per_world)
    # The worlds of a call split over every local device (MuJoCo Warp), but
    # for a call small enough to cost one step's fixed time on one device
    # (``physsim.devices.mesh_for``); MuJoCo C runs on the host through a
    # callback, whose process pool is the parallelism.
    on_device = physsim.resolve_backend(hw.backend) != 'c'
    self.world_mesh = physsim.devices.world_mesh() if on_device else None
    self._program = jax.jit(
      self._fused, static_argnames=('with_frames', 'with_positions', 'worlds_on')
    )
    self.simulated = 0  # simulations run by the calls so far (``distinct_worlds``)

  def _frames(self, positions, poses, noise_keys, colors):
    """Worlds' frames as their network sees them: (B, C, T, H, W) depth after
    the sensor model, or (B, C, T, H, W, 3) uint8 colour."""
    faces = jnp.asarray(self.mesh.faces, jnp.int32)
    if self._net.modality == 'rgb':  # each fabric's colour, 8 bits, as datasets are
      return physsim.render_rgb8(positions, faces, self._intr, poses, colors)
    frames = physsim.render_depth(positions, faces, self._intr, poses)
    if self._sensor:
      frames = jax.vmap(lambda k, f: physsim.apply_noise_frames(k, f, self._intr))(
        noise_keys, frames
      )
    return frames

  def _simulate(self, x, ratio, gust_keys):
    """One device's worlds simulated: positions (B, T, V, 3) (the rest mesh
    where a world blew up) and validity (B,)."""
    w = physsim.world_inputs(
      self.cloth, x[:, 0], x[:, 1], x[:, 2], gust_keys, self._wind, ratio
    )
    positions, valid = self._rollout(w)  # (B, T, V, 3), (B,)
    rest = jnp.asarray(self.mesh.vertices, positions.dtype)
    return jnp.where(valid[:, None, None, None], positions, rest), valid

  def _score(self, data: ProblemData, positions, owner, noise_keys):
    """One device's simulated worlds rendered, sensed, embedded and scored,
    each against its problem's recording: PSDs (B,) and the shape summaries'
    residuals to the recording's (B, 2) (zeros without a shape distance)."""
    net = self._net

    kind = self._distance

    def score(args):  # one world: render, sense, then its discrepancy
      i, pos, key = args
      pose = jax.tree.map(lambda a: a[i], data.poses)  # (C,)
      seen_from = pose
      if any(self._camera_sd):  # the recording's camera, misplaced as it may be
        seen_from = physsim.shape.misplaced_poses(
          camera_key(key), pose, *self._camera_sd, self._pins
        )
      frames = self._frames(
        pos[None], jax.tree.map(lambda a: a[None], seen_from), key[None],
        data.color[i][None],
      )[0]  # fmt: skip
      d, resid = [], jnp.zeros(len(physsim.shape.SUMMARY), jnp.float32)
      if kind in EMBEDDING_DISTANCES:  # embed with its problem's net, PSD
        x = embedding.network_inputs(frames, net.modality, net.input_mode)
        params = jax.tree.map(lambda a: a[i], data.params)
        pts = embedding.embed_videos(
          net.network, params, x, net.clip_frames, net.members
        )  # ([K,] C, N, D)
        pts = pts.reshape(*pts.shape[:-3], -1, pts.shape[-1])  # cameras pooled
        psd_kind = 'energy' if kind == 'energy+shape' else kind
        d.append(embedding.video_distance(net, pts, data.rec_points[i], psd_kind))
      if kind in SHAPE_DISTANCES:  # the recording's own camera (C = 1)
        cam = jax.tree.map(lambda a: a[0], pose)
        s = physsim.shape.summary(frames[0], self._intr, cam)
        d.append(physsim.shape.summary_distance(s, data.rec_shape[i]))
        resid = s - data.rec_shape[i]
      d = d[0] if len(d) == 1 else model_lib.psd.geometric_mean(jnp.stack(d))
      return d, resid

    # Worlds in chunks sized from free memory: the network's activations of
    # every frame at once would not fit (paper size: ~8 MB per frame).
    return jax.lax.map(score, (owner, positions, noise_keys), batch_size=self._chunk)

  def _worlds(self, data: ProblemData, x, ratio, gust_keys, owner, noise_keys):
    """One device's worlds: simulate, render, sense, embed and score each
    against its problem's recording (``_simulate``, then ``_score``, on the
    device that simulated them). Returns PSDs (B,), residuals (B, 2), validity
    (B,) and positions (B, T, V, 3)."""
    positions, valid = self._simulate(x, ratio, gust_keys)
    d, resid = self._score(data, positions, owner, noise_keys)
    return d, resid, valid, positions

  def _fused(self, data: ProblemData, u, gust_keys, noise_keys, sims=None, *,
             with_frames, with_positions, worlds_on=None):  # fmt: skip
    p, q = u.shape[:2]
    x = physsim.params.from_unit_traced(
      u, data.lo[:, None], data.hi[:, None], data.log[:, None]
    ).reshape(p * q, 3)  # (Pq, 3) physical
    ratio = jnp.repeat(data.rigidity_ratio, q)
    owner = jnp.arange(p * q) // q  # each world's problem
    noise_keys = noise_keys.reshape(-1)
    gust_keys = gust_keys.reshape(-1)
    # worlds_on: the mesh this call's worlds split over (``__call__``)
    if sims is None:  # every world its own simulation, scored where it ran
      worlds = physsim.devices.shard_worlds(self._worlds, worlds_on, replicated=(0,))
      d, resid, valid, positions = worlds(data, x, ratio, gust_keys, owner, noise_keys)
    else:  # the distinct simulations once (``distinct_worlds``), then every world
      rows, inverse = sims
      simulate = physsim.devices.shard_worlds(self._simulate, worlds_on)
      positions, valid = simulate(x[rows], ratio[rows], gust_keys[rows])
      positions, valid = positions[inverse], valid[inverse]
      score = physsim.devices.shard_worlds(self._score, worlds_on, replicated=(0,))
      d, resid = score(data, positions, owner, noise_keys)
    d = d.reshape(p, q)
    ok = valid.reshape(p, q) & jnp.isfinite(d)
    d = jnp.where(ok, d, jnp.nan)
    resid = jnp.where(ok[..., None], resid.reshape(p, q, -1), jnp.nan)
    out = {'psd': d, 'residual': resid, 'valid': valid.reshape(p, q)}
    if with_frames:  # the best candidate of each problem, rendered again (same keys)
      best = jnp.arange(p) * q + jnp.argmin(jnp.where(ok, d, jnp.inf), axis=1)
      frames = self._frames(
        positions[best], data.poses, noise_keys[best], data.color
      )  # (P, C, T, ...)
      out['frames'] = frames[:, 0]
    if with_positions:
      out['positions'] = positions.reshape(p, q, *positions.shape[1:])
    return out

  def _arguments(self, data: ProblemData, u, gust_keys, noise_keys):
    """A call's program arguments, checked, on the host, and the mesh its
    worlds split over."""
    u = np.asarray(u, np.float64)
    p = data.lo.shape[0]
    if u.ndim != 3 or u.shape[0] != p or u.shape[2] != 3:
      raise ValueError(f'candidates must be (P={p}, q, 3), got {u.shape}')
    if not np.all(np.isfinite(u)) or np.any(np.abs(u) > 1 + 1e-9):
      raise ValueError('candidates must be finite and inside [-1, 1]^3')
    if gust_keys.shape != u.shape[:2] or noise_keys.shape != u.shape[:2]:
      raise ValueError(
        f'need (P, q) = {u.shape[:2]} keys, got {gust_keys.shape}, {noise_keys.shape}'
      )
    u, n = u.astype(np.float32), u.shape[0] * u.shape[1]
    on_device = self.world_mesh is not None
    min_saved = DEVICE_SAVED_CALLS * physsim.devices.FLAT_WORLDS if on_device else 0
    sims = distinct_worlds(data, u, gust_keys, min_saved=min_saved)
    mesh = physsim.devices.mesh_for(self.world_mesh, n)
    return (data, u, gust_keys, noise_keys, sims), mesh

  def compile(self, data: ProblemData, u, gust_keys: jax.Array,
              noise_keys: jax.Array, *, frames: bool = False,
              positions: bool = False) -> None:  # fmt: skip
    """Compiles the program that ``__call__`` with these arguments runs,
    without running it: only their shapes, and whether their worlds repeat
    (``distinct_worlds``), matter. A driver calls it in a thread while an
    earlier call of another shape runs; the call then finds the program
    compiled (JAX's caches). MuJoCo Warp's own set-up for a batch size
    (buffers, the frame's graph) still happens on the first call."""
    args, mesh = self._arguments(data, u, gust_keys, noise_keys)
    self._compile(physsim.devices.abstract(args, mesh), mesh, frames, positions)

  def _compile(self, args, mesh, frames: bool, positions: bool) -> None:
    """The program for ``args`` (arrays, or their ``abstract`` shapes) lowered
    and compiled into JAX's caches, where its call finds it."""
    self._program.lower(
      *args, with_frames=frames, with_positions=positions, worlds_on=mesh
    ).compile()

  def __call__(
    self,
    data: ProblemData,
    u,
    gust_keys: jax.Array,
    noise_keys: jax.Array,
    *,
    frames: bool = False,
    positions: bool = False,
    compiled: Callable[[], object] | None = None,
  ) -> Scores:
    """Scores candidates ``u (P, q, 3)`` of the P stacked problems in ``data``.

    Args:
      data: stacked ``ProblemData`` (leading axis P).
      u: (P, q, 3) unit-cube candidates.
      gust_keys, noise_keys: (P, q) typed PRNG keys, one per candidate.
      frames: also return each problem's best candidate's camera-0 frames.
      positions: also return every candidate's vertex positions.
      compiled: called once the program is compiled, before it runs (a
        driver starts work there that should not contend with the compile
        for Python's lock, whether or not the run blocks this thread).

    Raises:
      ValueError: ``u`` of the wrong shape, not finite or outside the cube.
    """
    args, mesh = self._arguments(data, u, gust_keys, noise_keys)
    sims = args[-1]
    self.simulated += args[1].size // 3 if sims is None else len(sims[0])
    placed = physsim.devices.place(args, mesh)
    if compiled is not None:
      self._compile(placed, mesh, frames, positions)
      compiled()
    out = self._program(
      *placed, with_frames=frames, with_positions=positions, worlds_on=mesh
    )
    out = jax.device_get(out)
    # A Ctrl-C during the simulator's callbacks left NaN worlds: not scores.
    physsim.interrupt.raise_if_pending()
    return Scores(
      np.asarray(out['psd'], np.float64),
      np.asarray(out['valid']),
      out.get('frames'),
      out.get('positions'),
      np.asarray(out['residual'], np.float64),
    )


def camera_key(noise_key: jax.Array) -> jax.Array:
  """The key of a candidate's camera error (``Scoring.camera_sd_m``),
  drawn from its sensor-noise key."""
  return jax.random.fold_in(noise_key, 7)


# A call that simulates only its distinct worlds pads their count up to a
# multiple of 1/SIM_BUCKETS of its worlds: a few program shapes per call
# shape, not one for every count. It does so only where that at least halves
# its simulations: each count is a program of its own to compile (seconds on
# a CPU, where a small cloth simulates in milliseconds).
SIM_BUCKETS = 16


# On a device a call simulates its distinct worlds alone only where that saves
# at least this many times FLAT_WORLDS worlds: a call of up to FLAT_WORLDS costs
# one step's fixed time however many it simulates (a padded call runs the
# design's program, ``search._call_size``), and a new program shape costs its
# compile and the simulator's graph, about 6 s on an H200 (an estimate's first
# step against its later ones, BENCHMARKS.md), what some 200 worlds take to
# simulate there at scale (28 a second).
DEVICE_SAVED_CALLS = 4


def distinct_worlds(
  data: ProblemData, u: np.ndarray, gust_keys: jax.Array, *, min_saved: int = 0
):
  """The simulations a call of candidates ``u (P, q, 3)`` needs: one per set of
  worlds with equal inputs (the same unit-cube point in the same search box
  and fabric, with the same gust key), which then differ only in how they are
  seen and scored.

  Searches of one fabric with one seed share their initial design and its
  keys (a calibration's recordings, several recordings of one fabric), and a
  call's padding rows repeat a problem: without this every such world would
  be simulated again.

  Args:
    data: the call's stacked ``ProblemData``.
    u: (P, q, 3) float32 unit-cube candidates.
    gust_keys: (P, q) their gust keys.
    min_saved: fewest worlds sharing must save (on a device:
      ``DEVICE_SAVED_CALLS`` x ``FLAT_WORLDS``).

  Returns:
    None when fewer than half of the worlds, or than ``min_saved``, would be
    saved (the call then simulates every world, as one program), else
    ``(rows, inverse)`` int32: the worlds to simulate (the first of each set,
    in call order, the last repeated to the padded count) and, for each of the
    P*q worlds, its simulation's index in ``rows``.
  """
  p, q = u.shape[:2]
  per_problem = np.concatenate(
    [
      np.asarray(data.lo, np.float32),
      np.asarray(data.hi, np.float32),
      np.asarray(data.log, np.float32),
      np.asarray(data.rigidity_ratio, np.float32).reshape(p, 1),
    ],
    axis=1,
  )  # (P, 10): what maps a problem's unit point to its simulation
  owner = np.repeat(np.arange(p), q)
  keys = np.asarray(jax.random.key_data(gust_keys), np.uint32).reshape(p * q, -1)
  inputs = np.concatenate(
    [
      np.ascontiguousarray(u, np.float32).reshape(p * q, 3).view(np.uint32),
      per_problem[owner].view(np.uint32),
      keys,
    ],
    axis=1,
  )  # bit patterns: equal rows simulate alike
  _, first, inverse = np.unique(inputs, axis=0, return_index=True, return_inverse=True)
  order = np.argsort(first)  # the sets in call order
  rank = np.empty_like(order)
  rank[order] = np.arange(len(order))
  n = physsim.devices.padded(len(first), max(1, (p * q) // SIM_BUCKETS))
  if 2 * n > p * q or p * q - n < min_saved:
    return None
  rows = first[order]
  rows = np.concatenate([rows, np.repeat(rows[-1:], n - len(rows))])
  return rows.astype(np.int32), rank[inverse.reshape(-1)].astype(np.int32)


def _bytes_per_pixel(params) -> int:
  """Working memory per rendered pixel while a frame is sensed and embedded:
  float32 activations of the widest convolution, in and out, plus the
  renderer's and sensor's buffers (per network: an ensemble's kernels carry
  a leading member axis); without a network, the latter alone."""
  if not jax.tree.leaves(params):
    return 4 * 2 * 16
  widest = max(
    (leaf.shape[-1] for leaf in jax.tree.leaves(params) if np.ndim(leaf) >= 4),
    default=32,
  )
  return 4 * 2 * (int(widest) + 16)


def stack(datas: list[ProblemData]) -> ProblemData:
  """ProblemData of several problems (same structure) on a leading axis."""
  return jax.tree.map(lambda *a: jnp.stack(a), *datas)


def candidate_keys(config: EstimateConfig, first: int, q: int):
  """(gust keys, noise keys), each (q,), of a search's evaluations
  ``first .. first + q - 1`` (its running count, so a resumed search draws the
  same keys). With ``common_random_numbers`` every evaluation gets the
  search's one pair of keys."""
  key = jax.random.key(config.seed)
  gust, noise = jax.random.fold_in(key, 2), jax.random.fold_in(key, 3)
  if config.common_random_numbers:
    return (
      jnp.broadcast_to(gust, (q,)),
      jnp.broadcast_to(noise, (q,)),
    )
  idx = jnp.arange(first, first + q)
  fold = jax.vmap(jax.random.fold_in, in_axes=(None, 0))
  return fold(gust, idx), fold(noise, idx)


class BestSeen:
  """The lowest PSD a search has scored and its candidate's camera-0 frames.

  A finished search shows its best candidate beside the recording; keeping
  those frames while scoring saves re-simulating it. A resumed search has not
  seen its earlier candidates' frames, so ``frames_of`` then returns None.
  """

  def __init__(self):
    self.u, self.y, self.frames = None, np.inf, None

  def update(self, u, y, frames) -> None:
    """Candidates ``u (q, 3)``, their PSDs ``y (q,)`` (NaN: failed) and the
    lowest one's frames ``(T, ...)``."""
    y = np.where(np.isfinite(y), y, np.inf)
    i = int(np.argmin(y)) if len(y) else 0
    if len(y) and y[i] < self.y:
      self.u, self.y = np.array(u[i], np.float64), float(y[i])
      self.frames = None if frames is None else np.asarray(frames)

  def frames_of(self, u) -> np.ndarray | None:
    """The kept frames if ``u`` is the kept candidate, else None."""
    if self.u is None or not np.array_equal(self.u, np.asarray(u, np.float64)):
      return None
    return self.frames
