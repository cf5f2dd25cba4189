"""The calibration study's design: its config and presets, the modes it reads
each recording in, the truths it draws, its networks (seeds, folders, which
recording each estimates) and the training, recording and estimate configs
it runs (``experiments.studies.calibration`` runs it)."""

from __future__ import annotations

import dataclasses
import functools
import math
import os

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, measurements
from experiments.pipeline import datasets as gen
from experiments.pipeline import demo as demo_lib
from experiments.pipeline import objective as objective_lib
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import simulation as simulation_lib
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import told_cameras

FIELDS = (*posterior_lib.FIELDS, 'load_ratio')
# The mode an estimate is in, by the reading it was given (Config.check_reading).
MODE_OF_READING = {'none': 'video', 'wind_speed': 'known wind',
                   'area_weight': 'known area weight'}  # fmt: skip
LEVELS = (50, 90)
# The modes with a bending length read from an overhang (issue 39's protocol:
# the sheet with the strip, and with an anemometer too): by a depth camera
# (its t law, ``length_dof``), and by a ruler (Gaussian).
LENGTH_MODES = ('bending length', 'known wind, bending length',
                'bending length (ruler)', 'known wind, bending length (ruler)')  # fmt: skip
MODES = ('video', 'known wind', 'known area weight', 'joint pair',
         'joint pair, known winds', *LENGTH_MODES)  # fmt: skip
RESULT_FILE = 'calibration.json'


@dataclasses.dataclass(frozen=True)
class Config:
  """A calibration study.

  Attributes:
    material: the fabric (physsim.FABRICS).
    materials: several fabrics in one study (overrides ``material``): each
      gets ``pairs`` pairs drawn over its own search box, every recording is
      estimated in one lockstep (one device program for all), and the
      tables are fitted on all of them (ranks are in each posterior's own
      CDF, so fabrics pool); the coverage is also reported per fabric.
    size: 'demo' (the demo's cloth, clip, network and search, minutes on a
      CPU) or 'paper' (the estimate's defaults: 25x25 cloth, 3 s clips, 120
      simulations per estimate, recordings of the evaluation recipe at its
      own 33x33 mesh, 256x256 frames; a GPU's work; no network: the study
      trains demo-size networks only, so it needs ``--distance=shape``).
    pairs: pairs of held-out simulated recordings per fabric (each pair shares
      bending and area weight; every recording's parameters are a prior draw).
    folds: folds of pairs for the cross-fitted coverage (each fold is read
      with the sharpness and recalibration chosen on the others).
    sharpness_grid: candidate values of the likelihood's constant (the
      searches run with the estimate's sharpness).
    measured_sd: relative standard error of a measured wind or area weight.
    length_sd: relative standard error of a bending length read from an
      overhang (``LENGTH_MODES``), the median over recordings (0.025: the
      depth reader's median printed error on the overhang benchmark's seed-0
      set-ups at the protocol's three bending lengths, 2026-11-29; 0.035 at
      Peirce's two, 2026-11-28).
    length_sd_spread: how much that error varies between recordings, as a
      depth reading's does with the strip's length and pixels: recording
      ``seq``'s is ``length_sd`` x exp(spread x z), z standard normal clipped
      to +-``LENGTH_SD_CLIP`` (0.43: the reader's sd of log error on seed 0,
      1.1-5.7% there), so the tables hold for readings over that range
      (``length_sd_range``: 0.85-7.3%); 0: every recording's is
      ``length_sd``.
    length_dof: that reading's error law: Student's t of this many degrees
      of freedom (the depth reader's, ``physsim.overhang_depth.DOF``: 10 since
      2026-11-29, 4 before), or 0, Gaussian (a ruler's).
    sequences: training simulations of the network (the demo's recipe).
    batch_size: recordings simulated per batch when making them.
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
    seed: the study's seed (truths, recordings, searches).
    network_seed: seed of the first network's training simulations and
      training (0: the demo's own network).
    networks: networks trained with the recipe (seeds ``network_seed`` + 0,
      1, ...); pair ``p``'s recordings are estimated with network
      ``p % networks``.
    estimate: the estimate settings (material, cloth and clock follow the
      demo's).
    camera_sd_spread: where the estimates carry a camera error
      (``estimate``'s ``camera_sd_m`` / ``camera_sd_deg``), how far each
      recording's ranges about it: recording ``seq``'s shift and tilt are
      each that times exp(spread x u), u uniform in [-1, 1], drawn
      independently from (seed, seq) (``camera_sd_of``), so the tables hold
      for a carried error anywhere in that box, as an intake's varies from
      one recording to the next; 0: every recording carries the one error
      (its tables then hold from half to twice it).
    camera_errors: ``benchmarks.alignment_error``'s JSON files: each
      recording's estimate is told a camera off as one of their intakes
      actually erred (drawn per recording, put on its own camera in that
      camera's frame) and carries that intake's claim (``camera_errors_jitter``
      spreads the claims between the measured ones); the estimate's camera
      error and ``camera_sd_spread`` are then the claims' range
      (``with_intake_errors``) and its ``camera_sd_from`` 'intake', so the
      tables hold for the intake's own claims. (): cameras displaced by the
      full error each estimate carries.
    camera_errors_jitter: how far each claim is spread about the measured
      one: times exp(jitter x u), u uniform in [-1, 1].
    check_reading: for ``check``: 'wind_speed' (an anemometer) or
      'area_weight' (a scale) estimates every new recording with a simulated
      reading of it (``measured_sd``, drawn around the truth) as the search's
      prior, so the check measures the intervals an estimate given that
      reading prints, its search steered by the reading; 'none': the video
      alone.
    physics: the recordings' physics: 'own' (the estimator's simulator) or
      'mismatched' (``physsim.MISMATCHES``: a fan off the cloth's normal,
      another gust spectrum, drag, damped bending, stretchier edges; the
      estimates still simulate their own), to measure or fit the intervals
      on recordings unlike the estimator's simulator, as a real one is.
    centred_levels: the tables correct the intervals' width only, about the
      posterior's median (``bo.calibration.centred_levels``): for tables of
      another physics, whose bias in one direction a real recording need
      not share.
    rig_runs: windy-rig workdirs (comma-separated paths or globs;
      ``benchmarks.windy_rig --pairs``) whose recordings, made as a user's
      rig makes them and taken in through the intake, the tables are fitted
      on instead of the study's own (``calibration_rig``: nothing is
      simulated; the fabrics, pairs and carried camera errors are theirs).
  """

  material: str = 'gray_interlock'
  materials: tuple[str, ...] = ()
  size: str = cli.choice('demo', ('demo', 'paper'))
  pairs: int = 100
  folds: int = 5
  sharpness_grid: tuple[float, ...] = (0.05, 0.1, 0.15, 0.25, 0.35, 0.5, 0.7, 1.0, 1.4)
  measured_sd: float = 0.02
  length_sd: float = 0.025
  length_sd_spread: float = 0.43
  length_dof: float = 10.0
  sequences: int = 24
  batch_size: int = 64
  backend: str = cli.choice('auto', physsim.BACKENDS)
  seed: int = 0
  network_seed: int = 0
  networks: int = 5
  estimate: EstimateConfig = cli.nested(
    EstimateConfig().replace(distance=objective_lib.NETWORK_DISTANCE, q=8, n_init=16, max_iter=6,
                             posterior_grid=(12, 64, 24)),
    skip=('simulation.material', 'simulation.cloth_resolution', 'simulation.frames',
          'simulation.warmup', 'hardware.backend', 'seed', 'search.point', 'measured'),
  )  # fmt: skip
  camera_sd_spread: float = 0.0
  camera_errors: tuple[str, ...] = ()
  camera_errors_jitter: float = 0.25
  check_reading: str = cli.choice('none', ('none', 'wind_speed', 'area_weight'))
  physics: str = cli.choice('own', tuple(physsim.MISMATCHES))
  centred_levels: bool = False
  rig_runs: str = ''


PRESETS = {
  'default': Config(),
  # The estimate's own size for every fabric (issue 41): the shape distance,
  # the default paper-size search, recordings of the evaluation recipe; all
  # in one lockstep on a GPU. The likelihood's constant stays the estimate's
  # default (the tables recalibrate its intervals).
  'paper': Config(
    materials=tuple(physsim.FABRICS),
    size='paper',
    pairs=15,
    sharpness_grid=(0.5,),
    batch_size=32,
    estimate=EstimateConfig().replace(distance='shape'),
  ),
  # A few pairs on a CPU: checks the whole study end to end.
  'smoke': Config(
    pairs=3,
    networks=1,
    sequences=8,
    batch_size=6,
    sharpness_grid=(0.25, 0.5, 1.0),
    estimate=EstimateConfig().replace(
      distance=objective_lib.NETWORK_DISTANCE,
      q=4,
      n_init=8,
      max_iter=2,
      posterior_grid=(6, 16, 8),
    ),
  ),
}


def study_materials(config: Config) -> tuple[str, ...]:
  """The study's fabrics, in order (``materials``, else ``material``)."""
  return tuple(config.materials) or (config.material,)


def first_seq(config: Config, material: str) -> int:
  """The study-wide number of ``material``'s first recording: fabric ``k``'s
  recordings are ``k * 2 * pairs ...`` (pairs stay ``2j, 2j + 1``; a
  one-fabric study numbers them as before)."""
  return study_materials(config).index(material) * 2 * config.pairs


def truths(
  config: Config, group: int = 2, material: str | None = None
) -> physsim.Params:
  """(group * pairs,) parameter sets of ``material`` (default the study's
  first), group-major: the ``group`` recordings of each fabric (a pair by
  default) share bending and area weight and draw their own wind (one fan
  setting each); all uniform in the unit cube of the fabric's search box (the
  prior). ``group=2`` gives the calibration study's pairs."""
  if group < 2:
    raise ValueError(f'a group is two or more recordings, got {group}')
  material = material or study_materials(config)[0]
  k = study_materials(config).index(material)
  # the first fabric keeps the one-fabric study's stream
  rng = np.random.default_rng([config.seed, 7] + ([k] if k else []))
  u = rng.uniform(-1.0, 1.0, size=(config.pairs, group, 3))
  u[:, 1:, 0] = u[:, :1, 0]
  u[:, 1:, 2] = u[:, :1, 2]
  return physsim.from_unit(u.reshape(-1, 3), physsim.search_space(material))


def uses_networks(config: Config) -> bool:
  """Whether the study's estimates embed frames with trained networks (every
  distance but the shape's)."""
  return config.estimate.scoring.distance in objective_lib.EMBEDDING_DISTANCES


def network_seeds(config: Config) -> tuple[int, ...]:
  """The seeds of the study's networks, in order (none for a distance that
  embeds nothing)."""
  if not uses_networks(config):
    return ()
  return tuple(config.network_seed + k for k in range(config.networks))


def fold_of(seq: int, folds: int) -> int:
  """The cross-fitting fold of recording ``seq``: pairs take the folds in turn
  (a pair's recordings share bending and area weight, so they stay together)."""
  return (seq // 2) % folds


def network_of(config: Config, seq: int) -> int:
  """Which network (index into ``network_seeds``) estimates recording ``seq``:
  pairs take the networks in turn, as they take the folds, so with as many
  folds as networks each fold is one network's."""
  return fold_of(seq, config.networks)


def network_dirs(config: Config, workdir: str, k: int) -> tuple[str, str]:
  """(training set, training runs) folders of network ``k`` (one network:
  ``data`` and ``model``, as the demo lays them out)."""
  if config.networks == 1:
    return os.path.join(workdir, 'data'), os.path.join(workdir, 'model')
  base = os.path.join(workdir, 'networks', str(network_seeds(config)[k]))
  return os.path.join(base, 'data'), os.path.join(base, 'model')


NETWORKS_FILE = 'networks.json'


def study_configs(config: Config, point: str = 'median', network: int = 0):
  """(training set, recordings, training, estimate) configs; the first two
  and the estimate's are every network's, ``network`` picks the seeds of the
  training set and training. At the paper's size there is no network (the
  first and third are None) and the estimate keeps ``config.estimate``'s
  cloth and clock."""
  n = 2 * config.pairs
  mats = study_materials(config)
  if config.size == 'paper':
    rec = dataclasses.replace(
      gen.PRESETS['eval'], materials=mats, sequences=n,
      batch_size=min(config.batch_size, n * len(mats)), backend=config.backend,
      seed=5000 + config.seed, physics=config.physics,
    )  # fmt: skip
    est = config.estimate.replace(
      material=mats[0], backend=config.backend, seed=config.seed, point=point
    )
    return None, rec, None, est
  data, rec, training, est = demo_lib.configs(
    mats[0], config.sequences, config.seed, config.backend,
    config.network_seed + network,
  )  # fmt: skip
  rec = dataclasses.replace(
    rec, materials=mats, sequences=n, batch_size=min(config.batch_size, n),
    seed=5000 + config.seed, physics=config.physics,
  )  # fmt: skip
  est = config.estimate.replace(
    material=mats[0], cloth_resolution=est.simulation.cloth_resolution,
    frames=est.simulation.frames, warmup=est.simulation.warmup,
    backend=config.backend, seed=config.seed, point=point,
  )  # fmt: skip
  return data, rec, training, est


def check_config(config: Config) -> None:
  """Refuses a study that cannot run, naming the setting.

  Raises:
    ValueError: an unknown fabric, pairs below one, a reading's relative
      error outside (0, 0.5], or a paper-size study with a network distance
      (it trains demo-size networks only).
  """
  mats = study_materials(config)
  for m in mats:
    if m not in physsim.FABRICS:
      raise ValueError(
        f'--materials: no fabric {m!r}: one of {sorted(physsim.FABRICS)}'
      )
  if len(set(mats)) != len(mats):
    raise ValueError(f'--materials={",".join(mats)}: a fabric twice')
  if config.pairs < 1:
    raise ValueError(f'--pairs={config.pairs}: need at least one pair')
  for name in ('measured_sd', 'length_sd'):
    v = getattr(config, name)
    if not 0.0 < v <= 0.5:
      raise ValueError(f'--{name}={v}: a relative reading error in (0, 0.5]')
  if not 0.0 <= config.length_sd_spread <= 2.0:
    raise ValueError(
      f'--length_sd_spread={config.length_sd_spread}: a spread of log errors in [0, 2]'
    )
  measurements.check_dof(config.length_dof, 'length_dof')
  sc = config.estimate.scoring
  told_cameras.check_spread((sc.camera_sd_m, sc.camera_sd_deg), config.camera_sd_spread)
  if len(mats) > 1 and uses_networks(config):
    raise ValueError(
      f'--materials={",".join(config.materials)} with --distance='
      f'{config.estimate.scoring.distance}: a study with networks calibrates one '
      'fabric (its networks are trained on it); use --material'
    )
  if config.size == 'paper' and uses_networks(config):
    raise ValueError(
      f'--size=paper with --distance={config.estimate.scoring.distance}: the study '
      'trains demo-size networks only; use --distance=shape'
    )


@functools.lru_cache(maxsize=4)
def intake_errors(paths: tuple[str, ...]) -> tuple[told_cameras.IntakeError, ...]:
  """The measured intake errors of ``Config.camera_errors`` (read once)."""
  return told_cameras.read_intake_errors(paths)


def with_intake_errors(config: Config) -> Config:
  """``config`` with its estimates' camera error set from ``camera_errors``:
  the range of the intakes' claims (``told_cameras.intake_range``) as
  ``camera_sd_m`` / ``camera_sd_deg`` and ``camera_sd_spread``, and
  ``camera_sd_from`` 'intake'; ``config`` itself without them.

  Raises:
    ValueError: the files' errors (``told_cameras.read_intake_errors``), a
      jitter outside [0, 1], or a camera error given beside them.
  """
  if not config.camera_errors:
    return config
  if not 0.0 <= config.camera_errors_jitter <= 1.0:
    raise ValueError(
      f'--camera_errors_jitter={config.camera_errors_jitter}: a spread of log '
      'claims in [0, 1]'
    )
  sc = config.estimate.scoring
  m, deg, spread = told_cameras.intake_range(
    intake_errors(tuple(config.camera_errors)), config.camera_errors_jitter
  )
  given = (sc.camera_sd_m, sc.camera_sd_deg, config.camera_sd_spread)
  if any(given) and given != (m, deg, spread):
    raise ValueError(
      "--camera_errors sets the camera error from the intakes' claims; drop "
      '--camera_sd_m, --camera_sd_deg and --camera_sd_spread'
    )
  estimate = config.estimate.replace(
    camera_sd_m=m, camera_sd_deg=deg, camera_sd_from='intake'
  )
  return dataclasses.replace(config, estimate=estimate, camera_sd_spread=spread)


def camera_sd_of(config: Config, est: EstimateConfig, seq: int) -> tuple[float, float]:
  """(metres, degrees): the camera error recording ``seq``'s estimate
  carries, and its told camera is off by (``told_pose``): ``est``'s, each
  component times exp(``camera_sd_spread`` x u), u uniform in [-1, 1],
  drawn from (seed, seq) alone (``told_cameras.spread_sd``); with
  ``camera_errors``, the claim of the intake drawn for it
  (``told_cameras.intake_draw``)."""
  if config.camera_errors:
    return _intake_of(config, seq)[1]
  sd = (est.scoring.camera_sd_m, est.scoring.camera_sd_deg)
  return told_cameras.spread_sd(
    sd, config.camera_sd_spread, [config.seed, told_cameras.SD_STREAM, seq]
  )


def with_reading(config: Config, est: EstimateConfig, reading: str, truth: dict,
                 seq: int) -> EstimateConfig:  # fmt: skip
  """``est`` for recording ``seq``: unchanged for ``reading`` 'none', else with
  a simulated reading of that quantity as its prior, the one ``posteriors``
  applies to the same recording in its measured mode."""
  if reading == 'none':
    return est
  measured = measurements.simulated_reading(
    reading, truth, config.measured_sd, config.seed, seq
  )
  return est.replace(measured=measured)


def run_material(config: Config, run: dict) -> str:
  """A recording's fabric: its own (studies of several fabrics record it),
  else the study's only one."""
  return run.get('material') or study_materials(config)[0]


LENGTH_SD_CLIP = 2.5  # standard deviations of log error a simulated reading spans


def spread_length_sd(sd: float, spread: float, z: float) -> float:
  """A simulated reading's relative sd: ``sd`` x exp(``spread`` x z), z (a
  standard normal draw) clipped to +-``LENGTH_SD_CLIP``."""
  return sd * math.exp(spread * float(np.clip(z, -LENGTH_SD_CLIP, LENGTH_SD_CLIP)))


def spread_length_range(sd: float, spread: float) -> tuple[float, float]:
  """The relative sds ``spread_length_sd`` draws over (its extremes)."""
  return spread_length_sd(sd, spread, -LENGTH_SD_CLIP), spread_length_sd(
    sd, spread, LENGTH_SD_CLIP
  )


def length_sd_of(config: Config, seq: int) -> float:
  """Recording ``seq``'s simulated bending-length error (relative):
  ``spread_length_sd`` of ``length_sd`` and ``length_sd_spread``, z drawn
  from (seed, seq) alone."""
  z = np.random.default_rng([config.seed, 31, seq]).standard_normal()
  return spread_length_sd(config.length_sd, config.length_sd_spread, z)


def length_sd_range(config: Config) -> tuple[float, float]:
  """The relative bending-length errors the length modes' tables were
  fitted over (``length_sd_of``'s extremes)."""
  return spread_length_range(config.length_sd, config.length_sd_spread)


def estimate_record(config: Config, estimate: EstimateConfig) -> dict:
  """The study's settings as its files hold them: ``estimate``'s flat
  (``EstimateConfig.flat``), the form ``calibration_tables.calibration_note`` matches."""
  return {**dataclasses.asdict(config), 'estimate': estimate.flat()}


def told_pose(config: Config, est: EstimateConfig, pose: physsim.Pose,
              seq: int) -> physsim.Pose:  # fmt: skip
  """The camera pose recording ``seq``'s estimate is told, where ``est``
  carries a camera error (``camera_sd_m`` / ``camera_sd_deg``), as an
  estimate of a user's recording carries the intake's alignment error: the
  recording's true camera ``pose`` moved by a rigid error of that size about
  the estimate's pins (``told_cameras.moved_pose``), drawn from (seed, seq)
  alone, each recording its own; ``pose`` itself where both are 0 (a camera
  known exactly). With ``camera_errors``: moved as the intake drawn for it
  actually erred (``told_cameras.intake_pose``)."""
  pins = simulation_lib.pin_centre(est.simulation)
  if config.camera_errors:
    return told_cameras.intake_pose(pose, _intake_of(config, seq)[0], pins)
  key = jax.random.fold_in(jax.random.key(config.seed), told_cameras.POSE_STREAM)
  return told_cameras.moved_pose(
    jax.random.fold_in(key, seq), pose,
    (est.scoring.camera_sd_m, est.scoring.camera_sd_deg), pins,
  )  # fmt: skip


def _intake_of(config: Config, seq: int) -> tuple[told_cameras.IntakeError, tuple]:
  """Recording ``seq``'s drawn intake error and its claim (``intake_draw``),
  from (seed, seq) alone."""
  return told_cameras.intake_draw(
    intake_errors(tuple(config.camera_errors)), config.camera_errors_jitter,
    [config.seed, told_cameras.SD_STREAM, seq],
  )  # fmt: skip
