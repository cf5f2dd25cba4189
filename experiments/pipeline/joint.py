"""One fabric in several recordings: the searches of a joint estimate and their joint posterior.

Each recording has its own search (``joint_jobs``); once they have finished
(``estimation.estimate_many``), their likelihoods on the shared grid are
multiplied over bending and area weight, each recording's wind integrated
out (``combine_joint``, with ``posterior.joint``).
"""

from __future__ import annotations

import functools
import os

import jax
import numpy as np

import physsim
from experiments.pipeline import embedding, files, layout, measurements, units
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import results as results_lib
from experiments.pipeline import setup as setup_lib
from experiments.pipeline.objective import EstimateConfig
from experiments.pipeline.recording import Recording
from experiments.pipeline.searcher import Job, resolve_jobs

# The settings a joint estimate's recordings may each have their own of; the
# rest (material, likelihood, grid, search) they share.
PER_RECORDING = (
  'cloth_size',
  'cloth_resolution',
  'hem_mass',
  'camera_sd_m',
  'camera_sd_deg',
)


def joint_jobs(
  config: EstimateConfig,
  recordings: list[Recording],
  model_dir: str,
  workdir: str,
  winds: list[tuple[float, float]] | None = None,
  allow_other_material: bool = False,
  overrides: list[dict] | None = None,
  nets: dict[str, embedding.EmbeddingNet] | None = None,
  fans: list[str] | None = None,
) -> list[Job]:
  """The searches of one fabric's joint estimate (``estimate_joint``'s
  arguments and checks), one per recording under ``<workdir>/recording_<k>``,
  each with its setup resolved (``resolve_jobs``; ``nets``: networks restored
  already, by folder).

  Raises:
    ValueError: ``estimate_joint``'s, or a recording whose setup is refused
      (named).
  """
  if len(recordings) < 2:
    raise ValueError(
      f'a joint estimate needs two or more recordings, got {len(recordings)}'
    )
  if not config.posterior:
    raise ValueError(
      "a joint estimate combines posteriors: use point='median' or 'bayes'"
    )
  if config.measured.wind_speed_sd > 0:
    raise ValueError(
      "a measured wind is one recording's: estimate that recording alone, or "
      'give one reading per recording (--wind_speeds, --wind_speed_sds)'
    )
  if winds is not None and len(winds) != len(recordings):
    raise ValueError(f'{len(winds)} wind readings for {len(recordings)} recordings')
  read = winds is not None and all(sd > 0 for _, sd in winds)
  if config.measured.air_coefficient == 'auto':  # the protocol's fabric: its own
    config = config.replace(air_coefficient='free' if read else 'fixed')
  if config.measured.air_free and not read:
    raise ValueError(
      "--air_coefficient=free: a joint estimate reads the fabric's air from each "
      "recording's wind reading (--wind_speeds, --wind_speed_sds); without "
      'them the video sees the wind and the air as one'
    )
  check_fans(fans, winds, len(recordings))
  configs = [config] * len(recordings)
  if winds is not None:
    configs = [config.replace(wind_speed=v, wind_speed_sd=sd) for v, sd in winds]
    for c in configs:
      c.check()
  if overrides is not None:
    if len(overrides) != len(recordings):
      raise ValueError(
        f'{len(overrides)} sets of settings for {len(recordings)} recordings'
      )
    for o in overrides:
      if set(o) - set(PER_RECORDING):
        raise ValueError(
          f'settings {sorted(set(o) - set(PER_RECORDING))} are shared by a joint '
          f"estimate's recordings; a recording's own are {PER_RECORDING}"
        )
    configs = [c.replace(**o) for c, o in zip(configs, overrides, strict=True)]
    for c in configs:
      c.check()
  configs = _one_box(configs)
  jobs = [
    Job(c, r, model_dir, layout.recording_dir(workdir, k), allow_other_material)
    for k, (c, r) in enumerate(zip(configs, recordings, strict=True))
  ]
  resolved = resolve_jobs(jobs, nets)
  for job, r in zip(jobs, resolved, strict=True):
    if isinstance(r, Exception):
      raise ValueError(f'{job.recording.source}: {r}') from r
  return resolved


def check_fans(fans, winds, n: int) -> None:
  """Raises ValueError for fan labels (``estimate_joint``'s ``fans``) of
  another number of recordings than ``n``, or recordings of one fan setting
  with different wind readings (``winds``: (m/s, sd) each, (0, 0) none)."""
  if fans is None:
    return
  if len(fans) != n:
    raise ValueError(f'{len(fans)} fan settings for {n} recordings')
  for f in dict.fromkeys(fans):
    read = {tuple(winds[k]) for k, g in enumerate(fans) if g == f} if winds else set()
    if len(read) > 1:
      raise ValueError(
        f'fan setting {f!r}: its recordings were read {sorted(read)}; one wind, '
        'one reading (give it to each of them, or to none)'
      )


def joint_posterior(jobs: list[Job], key, shared_bias: float | None = None,
                    fans: list[str] | None = None, air=None) -> tuple[dict, list]:  # fmt: skip
  """``posterior.joint`` of finished searches (``joint_jobs``'s, or any
  subset of them) from their saved posteriors, drawing as many samples as
  each kept, with a shared discrepancy of ``shared_bias`` (None: the
  config's) and the recordings' fan settings (``fans``: one wind each
  label; ``air``: ``posterior.joint``'s, the air coefficient shared); returns
  it and the loaded ``posterior.npz`` files."""
  npz = [np.load(os.path.join(j.workdir, layout.POSTERIOR_FILE)) for j in jobs]
  grid = tuple(int(g) for g in npz[0]['grid'])
  config = jobs[0].config
  if shared_bias is None:
    shared_bias = config.scoring.shared_bias
  combined = posterior_lib.joint(
    [z['log_lik'] for z in npz], grid, [z['log_prior'] for z in npz], key,
    n=len(npz[0]['samples']), shared_bias_sd=shared_bias,
    area_weight_range=jobs[0].setup.space.area_weight
    if jobs[0].setup is not None
    else physsim.search_space(config.simulation.material).area_weight,
    fans=fans, air=air,
  )  # fmt: skip
  return combined, npz


def combine_joint(jobs: list[Job], results: list, workdir: str,
                  fans: list[str] | None = None) -> dict:  # fmt: skip
  """The joint posterior of one fabric's finished searches (``joint_jobs``,
  then ``estimate_many``: ``results`` in the jobs' order; ``fans``: their
  fan settings, ``estimate_joint``'s); writes and returns
  ``estimate_joint``'s ``joint.json``.

  Raises:
    ValueError: a recording whose estimate failed (named).
  """
  first = _finished_setup(jobs, results)
  configs = [job.config for job in jobs]
  # The settings the recordings share.
  config = configs[0].replace(wind_speed=0.0, wind_speed_sd=0.0)
  key = jax.random.fold_in(jax.random.key(config.seed), 11)
  note = joint_note(configs, first.setup.network, fans)
  # A joint the shipped tables cover was calibrated, and checked on another
  # physics, without a shared discrepancy; elsewhere (and in the protocol
  # check's sets) the discrepancy keeps its recordings from averaging away
  # the simulator's error.
  without = note and note.get('matches') and not note.get('shared_discrepancy')
  shared_sd = 0.0 if without else config.scoring.shared_bias
  space = first.setup.space
  air = _air_of(configs, space, first.setup.config.search.posterior_grid)
  combined, npz = joint_posterior(jobs, key, shared_sd, fans, air)
  grid = tuple(int(g) for g in npz[0]['grid'])
  combined['samples'] = [  # a bending length places (b, w) within their cells
    posterior_lib.refine_draws(x, grid, space, c.measured, config.seed + k)
    for k, (x, c) in enumerate(zip(combined['samples'], configs, strict=True))
  ]
  summary = functools.partial(_summary, combined, npz, space, note, air is not None)
  winds = _wind_readings(configs)
  per = []
  for k, job in enumerate(jobs):
    s = summary(k, job.config.measured)
    per.append(_recording_entry(job, results[k]['estimate'], s, winds, fans, k))
    posterior_lib.plot(
      combined['samples'][k], npz[k]['prior_samples'], space, job.recording.truth,
      os.path.join(workdir, f'joint_recording_{k}.png'),
      title=f'{config.simulation.material}: joint posterior, recording {k}',
      units=units.in_units(config.simulation.material),
    )  # fmt: skip
  shared = summary(0, configs[0].measured)
  _write_joint_samples(workdir, combined, space, air_samples=bool(air))
  out = {
    'material': config.simulation.material,
    'recordings': per,
    'bending_scale': shared['bending_scale'],
    'area_weight': shared['area_weight'],
    **({'air_coefficient': shared['air_coefficient']} if air else {}),
    'shared_bias': float(shared_sd),
    'calibration': note,
    'config': config.flat(),
  }
  files.write_json(os.path.join(workdir, layout.JOINT_FILE), out)
  return out


def _finished_setup(jobs: list[Job], results: list) -> Job:
  """The first job with its setup (``joint_jobs``' own, kept), once every
  recording's estimate has finished; raises ValueError naming one that
  failed (its exception in ``results``) or whose setup is refused."""
  for job, r in zip(jobs, results, strict=True):
    if isinstance(r, Exception):
      raise ValueError(f'{job.recording.source}: {r}') from r
  (first,) = resolve_jobs(jobs[:1])  # the joint_jobs' own setup, kept
  if isinstance(first, Exception):
    raise ValueError(f'{jobs[0].recording.source}: {first}') from first
  return first


def joint_note(configs: list, network: setup_lib.Network,
                fans: list[str] | None) -> dict | None:  # fmt: skip
  """The calibration note of a joint of recordings with ``configs``
  (``setup.calibration``: each recording's camera error covered), naming
  what no calibration measured: recordings sharing a fan setting, a known
  hem mass the first recording lacks."""
  uncalibrated = []
  if fans is not None and len(set(fans)) < len(fans):
    uncalibrated.append('recordings sharing one fan setting')
  hem_masses = [c.simulation.hem_mass for c in configs]
  if any(hem_masses[1:]) and not hem_masses[0]:
    uncalibrated.append('hem_mass (a recording with a known mass at its hem)')
  cameras = [(c.scoring.camera_sd_m, c.scoring.camera_sd_deg) for c in configs]
  return setup_lib.calibration(
    configs[0], network, joint=True, recordings=len(configs),
    uncalibrated=tuple(uncalibrated),
    every_wind_read=all(c.measured.wind_speed_sd > 0 for c in configs),
    cameras=tuple(cameras) if len(set(cameras)) > 1 else (),
  )  # fmt: skip


def _wind_readings(configs: list) -> list[tuple[float, float]] | None:
  """Each recording's wind reading (m/s, sd; (0, 0) where it has none), or
  None where no recording was read."""
  if not any(c.measured.wind_speed_sd > 0 for c in configs):
    return None
  return [(c.measured.wind_speed, c.measured.wind_speed_sd) for c in configs]


def _summary(combined: dict, npz: list, space: physsim.SearchSpace, note,
             air: bool, k: int, measured) -> dict:  # fmt: skip
  """Recording ``k``'s joint draws summarised (``posterior.summarise``) at the
  calibration ``note``'s levels and weights, with the shared air
  coefficient's draws beside its prior's where the air was free (``air``)."""
  return posterior_lib.summarise(
    combined['samples'][k], space, npz[k]['prior_samples'],
    results_lib.levels_of(note), results_lib.weights_of(note), measured,
    air=(combined['air'], npz[k]['air_prior_samples']) if air else None,
    air_simulated=combined.get('air_simulated'),
  )  # fmt: skip


def _recording_entry(job: Job, alone: dict, s: dict, winds, fans, k: int) -> dict:
  """Recording ``k``'s part of ``joint.json``: its estimate alone (``alone``),
  its own wind and load ratio in the joint (``s``, its summary), and what
  was known of it (wind reading, fan setting, hem mass, truth)."""
  hem_mass = job.config.simulation.hem_mass
  return {
    'recording': job.recording.source,
    'alone': alone,
    'wind_speed': s['wind_speed'],
    'load_ratio': s['load_ratio'],
    **({'measured_wind': list(winds[k])} if winds and winds[k][1] > 0 else {}),
    **({'fan': fans[k]} if fans is not None else {}),
    **({'hem_mass': hem_mass} if hem_mass else {}),
    **({'truth': job.recording.truth} if job.recording.truth else {}),
  }


def _write_joint_samples(workdir: str, combined: dict, space: physsim.SearchSpace,
                         air_samples: bool) -> None:  # fmt: skip
  """Writes the shared draws (``joint_posterior.npz``: bending and area weight
  with the first recording's wind, and the air coefficient's where free)."""
  files.write_atomic(
    os.path.join(workdir, layout.JOINT_POSTERIOR_FILE),
    lambda p: np.savez(
      p,
      samples=combined['samples'][0],
      bounds=space.bounds(),
      **({'air_samples': combined['air']} if air_samples else {}),
    ),  # fmt: skip
  )


def _air_of(configs, space: physsim.SearchSpace, grid) -> tuple | None:
  """``posterior.joint``'s ``air`` for recordings with ``configs`` (None: the
  air coefficient held at ArcSim's 1): their wind readings and the effective
  wind at each of the grid's wind cells."""
  if not configs[0].measured.air_free:
    return None
  nv = int(grid[1])
  u = np.zeros((nv, 3))
  u[:, 1] = -1.0 + (2.0 * np.arange(nv) + 1.0) / nv
  winds = np.ravel(physsim.params.from_unit(u, space).wind_speed)
  readings = [(c.measured.wind_speed, c.measured.wind_speed_sd) for c in configs]
  return readings, winds


def _one_box(configs: list) -> list:
  """The recordings' configs on one search box (a joint's grids must match):
  where their readings widen the fabric's box differently, each gets the
  widest (``Search.box``)."""
  boxes = [
    measurements.search_box(
      c.simulation.material, c.measured, c.search.box
    )[0].bounds()
    for c in configs
  ]  # fmt: skip
  if all(np.array_equal(b, boxes[0]) for b in boxes):
    return configs
  lo, hi = np.min([b[:, 0] for b in boxes], 0), np.max([b[:, 1] for b in boxes], 0)
  box = tuple(float(v) for pair in zip(lo, hi, strict=True) for v in pair)
  return [c.replace(box=box) for c in configs]
