"""The protocol study's slopes and noise of one candidate at one truth, with
MuJoCo C on the CPU, cached as JSON.

The slopes J of the statistics (``protocol_camera.STATS``) with respect to
(log bending, log area weight, log wind) are central finite differences in
steady wind (``simulate_candidate``; a recording without wind has no wind
parameter); their noise covariance R is the spread over a few gust histories,
pulled half-way to its diagonal (``bo.design.shrink``: a 6 x 6 covariance
from a few draws), plus the depth sensor's and the set-up's
(``protocol_camera.sensor_sd``). ``candidate_slopes`` caches them under a
name carrying every setting they depend on; ``world_residual`` is what
another physics shows beside them (``protocol_bound.set_bias``).
"""

from __future__ import annotations

import hashlib
import json
import os
import time

import numpy as np

import physsim
from bo import design
from experiments.pipeline import files
from experiments.studies import protocol_camera, protocol_candidates, protocol_config
from experiments.studies.protocol_candidates import Candidate
from experiments.studies.protocol_config import Config

CHAOS_NUDGE = 1e-3  # log bending
CACHE_VERSION = 3  # bump when what a cached slope file means changes
WORLD_VERSION = 1  # bump when what a cached world file means changes
PARAMS = ('log_bending', 'log_area_weight', 'log_wind')


def sim_config(
  c: Candidate, config: Config, physics: physsim.Mismatch = physsim.mismatch.OWN
) -> physsim.SimConfig:
  """The simulator's settings for the candidate: at most
  ``protocol_candidates.timestep(c)``, the step and edges
  ``physsim.config_for_mesh`` gives its mesh; ``physics``'s
  edges, drag and damping (``physsim.Mismatch``; default the estimator's)."""
  fields = physics.sim_fields()
  return physsim.config_for_mesh(
    protocol_candidates.mesh(c), config.fps, protocol_candidates.timestep(c),
    fields.pop('edge_solref'), scaled_edges=config.scaled_edges, **fields,
  )  # fmt: skip


def _model(c: Candidate, config: Config,
           physics: physsim.Mismatch = physsim.mismatch.OWN) -> physsim.ClothModel:  # fmt: skip
  """The candidate's compiled cloth under ``physics``, its hem attached."""
  m = protocol_candidates.mesh(c)
  hem = physsim.hem_mass(m, c.resolution, c.hem / 1000) if c.hem > 0 else None
  return physsim.build(
    m, config.material, sim_config(c, config, physics), extra_mass=hem
  )


def _steady_kwargs(config: Config) -> dict:
  """``physsim.simulate``'s clip and backend settings of the study."""
  return dict(frames=round(config.clip * config.fps), fps=config.fps,
              warmup=config.warmup, backend='c', workers=config.workers,
              space=protocol_config.SPACE)  # fmt: skip


def robust_slope(near, far, scramble=0.0) -> np.ndarray:
  """Central-difference slopes at a step and at twice it, combined: the wider
  one, shrunk towards 0 by its error, estimated as the larger of how much the
  two disagree and ``scramble`` (the slope a nudge far below the step makes
  look like, divided by the step): ``far * max(0, 1 - err^2 / far^2)``. A
  smooth statistic keeps its slope; one whose clip mean the flapping
  scrambles (a flag in steady wind) loses it, instead of reporting the
  scramble divided by the step as information."""
  near, far = np.asarray(near, np.float64), np.asarray(far, np.float64)
  err = np.maximum(np.abs(near - far), np.asarray(scramble, np.float64))
  with np.errstate(divide='ignore', invalid='ignore'):
    keep = np.clip(1 - err**2 / far**2, 0, 1)
  return np.where(far == 0, 0.0, far * np.nan_to_num(keep))


def _probes(
  c: Candidate, bending: float, area_weight: float, steps: list[float]
) -> np.ndarray:
  """(4 p + 2, 3) (bending, area weight, wind) of the steady simulations:
  -2, -1, +1 and +2 ``steps`` of each of the candidate's p parameters in log
  space, then -+``CHAOS_NUDGE`` of log bending."""
  p = 3 if c.wind > 0 else 2
  base = np.log([bending, area_weight, max(c.wind, 1e-9)])
  points = []
  for i in range(p):
    for sign in (-2, -1, 1, 2):
      x = base.copy()
      x[i] += sign * steps[i]
      points.append(np.exp(x))
  for sign in (-1, 1):  # the chaos probe: a nudge of 1e-3 in log bending
    points.append(np.exp(base + sign * np.array([CHAOS_NUDGE, 0, 0])))
  return np.array(points)


def _differences(out: np.ndarray, steps: list[float], overhang: bool):
  """The slopes from the ``_probes``' statistics ``out`` (4 p + 2, m): the
  central differences at one step and at two (``near``, ``far``: (m, p)),
  the chaos probe's ``scramble`` (m,) and the ``robust_slope`` of them."""
  p = (len(out) - 2) // 4
  s, nudged = out[:-2].reshape(p, 4, -1), out[-2:]
  h = np.array(steps[:p])[:, None]
  near = ((s[:, 2] - s[:, 1]) / (2 * h)).T  # (m, p)
  far = ((s[:, 3] - s[:, 0]) / (4 * h)).T
  # what a nudge far below any step does: smooth statistics move by ~0, ones
  # the flapping scrambles by their whole scatter, whatever the step
  scramble = np.abs(nudged[1] - nudged[0])  # (m,)
  jac = robust_slope(near, far, (scramble[None] / (4 * h)).T)
  if overhang:
    # A resting overhang's shape solves D (laplacian^2) u = w g: it depends on
    # D / w alone, so its slope in log area weight is minus its slope in log
    # bending. The simulated strip, released from flat, still swings through
    # the clip, and the air's drag on the swing (which does not scale with w)
    # would show area weight that a resting strip cannot.
    jac[:, 1] = -jac[:, 0]
  return near, far, scramble, jac


def _gust_noise(c: Candidate, model: physsim.ClothModel, bending: float,
                area_weight: float, config: Config, key):  # fmt: skip
  """The statistics' covariance (m, m) over ``config.draws`` gust histories
  at the truth, shrunk to its diagonal by ``config.shrink``, and their
  standard deviations (m,); zeros for a candidate without wind."""
  n = len(protocol_camera.STATS)
  if not (c.wind > 0 and config.draws > 0):
    return np.zeros((n, n)), np.zeros(n)
  gusty = physsim.simulate(
    model,
    physsim.params.make(bending, np.full(config.draws, c.wind), area_weight),
    wind=physsim.Wind(gust_intensity=config.gusts),
    key=key,
    **_steady_kwargs(config),
  )
  if not np.all(gusty.valid):
    raise RuntimeError(f'{c.name}: a gusty simulation blew up')
  rest = protocol_candidates.mesh(c).vertices
  g = protocol_camera.summaries(gusty.positions, rest, c.resolution, c.size)
  return design.shrink(np.cov(g, rowvar=False), config.shrink), g.std(axis=0, ddof=1)


def simulate_candidate(c: Candidate, bending: float, area_weight: float,
                       config: Config, key) -> dict:  # fmt: skip
  """Slopes (m, p) and noise covariance (m, m) of one candidate at one truth;
  p = 3 with wind, 2 without (no wind parameter). Steady wind at +-1 and +-2
  steps of each parameter and at +-``CHAOS_NUDGE`` of log bending
  (``robust_slope``), ``draws`` gusty histories at the truth."""
  m = protocol_candidates.mesh(c)
  model = _model(c, config)
  sim = model.config
  steps = [config.step_bending, config.step_area_weight, config.step_wind]
  p = 3 if c.wind > 0 else 2
  points = _probes(c, bending, area_weight, steps)
  winds = points[:, 2] if c.wind > 0 else np.zeros(len(points))
  steady = physsim.simulate(
    model,
    physsim.params.make(points[:, 0], winds, points[:, 1]),
    **_steady_kwargs(config),
  )
  if not np.all(steady.valid):
    raise RuntimeError(f'{c.name}: a steady simulation blew up at bending {bending}')
  out = protocol_camera.summaries(steady.positions, m.vertices, c.resolution, c.size)
  near, far, scramble, jac = _differences(out, steps, c.overhang)
  gust_cov, gust_sd = _gust_noise(c, model, bending, area_weight, config, key)
  sensor = protocol_camera.sensor_sd(c, config.clip, config.camera_fps,
                                     config.setup_mm, config.curvature_floor)  # fmt: skip
  cov = gust_cov + np.diag(sensor**2)
  return {
    'candidate': c.name, 'bending': bending, 'area_weight': area_weight,
    'wind': c.wind, 'timestep': sim.timestep, 'edge_solref': sim.edge_solref,
    'params': list(PARAMS[:p]), 'slopes': jac.tolist(),
    'noise_cov': cov.tolist(), 'gust_sd': gust_sd.tolist(),
    'sensor_sd': sensor.tolist(),
    'camera_distance_m': protocol_camera.camera_distance(c.size),
    'summary': out.mean(axis=0).tolist(),
    'slope_near': near.tolist(), 'slope_far': far.tolist(),
    'scramble': scramble.tolist(),
  }  # fmt: skip


# Config fields a cached slope file depends on besides its name's own.
_SLOPE_FIELDS = ('gusts', 'draws', 'clip', 'warmup', 'fps', 'camera_fps',
                 'step_bending', 'step_area_weight', 'step_wind', 'setup_mm',
                 'curvature_floor', 'shrink', 'seed')  # fmt: skip


def _slope_digest(config: Config) -> str:
  """'' at the default settings, else '_' and a short digest of those of
  ``_SLOPE_FIELDS`` that differ from them."""
  default = Config()
  changed = {
    f: getattr(config, f)
    for f in _SLOPE_FIELDS
    if getattr(config, f) != getattr(default, f)
  }
  if not changed:
    return ''
  return (
    '_' + hashlib.sha1(json.dumps(changed, sort_keys=True).encode()).hexdigest()[:8]
  )


def _stem(c: Candidate, bending: float, area_weight: float, config: Config) -> str:
  """A cached file's name for the candidate at a truth, under ``config``."""
  return (
    f'{config.material}_{c.name}_b{bending:.4g}_w{area_weight:.4g}'
    f'{"" if config.scaled_edges else "_fixed_edges"}{_slope_digest(config)}'
  )


def slope_path(c: Candidate, bending: float, area_weight: float, config: Config,
               cache_dir: str) -> str:  # fmt: skip
  """Where ``candidate_slopes`` caches the candidate's slopes at a truth."""
  return os.path.join(
    cache_dir, f'{_stem(c, bending, area_weight, config)}_v{CACHE_VERSION}.json'
  )


def _cached_slopes(path: str) -> dict:
  """A cached slope file, checked: a damaged one (its writes are atomic, so
  damaged after) is refused naming it rather than ranked as garbage.

  Raises:
    ValueError: naming the file and how to recompute it.
  """
  why = ''
  try:
    out = physsim.dataset.read_json(path)
  except ValueError as e:
    out, why = None, str(e).removeprefix(f'{path}: ')[:100]
  if out is not None:
    try:
      slopes = np.asarray(out['slopes'], np.float64)
      cov = np.asarray(out['noise_cov'], np.float64)
      float(out['wind'])
    except (KeyError, TypeError, ValueError):
      why = 'no slopes, noise_cov and wind'
    else:
      m = slopes.shape[0] if slopes.ndim == 2 else -1
      if cov.shape != (m, m) or not (
        np.isfinite(slopes).all() and np.isfinite(cov).all()
      ):
        why = f'slopes {slopes.shape} and noise_cov {cov.shape} do not fit or are not finite'
  if why:
    raise ValueError(
      f'{path}: a damaged cached slope file ({why}); delete it to recompute'
    )
  return out


def candidate_slopes(c: Candidate, bending: float, area_weight: float,
                     config: Config, cache_dir: str, key) -> dict:  # fmt: skip
  """``simulate_candidate``, cached as JSON under ``cache_dir`` (a rerun, or
  ``experiments.plan``, reuses it). The file's name carries every setting that
  changes what is simulated or how its noise is read (``_SLOPE_FIELDS``; a
  short digest of those that differ from the defaults), so that a study of
  other clips never reads another's slopes."""
  path = slope_path(c, bending, area_weight, config, cache_dir)
  if os.path.exists(path):
    return _cached_slopes(path)
  t0 = time.time()
  out = simulate_candidate(c, bending, area_weight, config, key)
  out['seconds'] = time.time() - t0
  files.write_json(path, out)
  return out


def world_residual(c: Candidate, bending: float, area_weight: float, config: Config,
                   cache_dir: str, physics: physsim.Mismatch = physsim.mismatch.WORLD
                   ) -> list[float]:  # fmt: skip
  """(len(STATS),) what ``physics`` (a world unlike the estimator's simulator,
  ``physsim.mismatch``) shows minus what the estimator's own simulator shows,
  in steady wind at the truth: the statistics' misfit that a fit with the
  estimator's simulator turns into bias (``protocol_bound.set_bias``). Cached
  as JSON beside the slopes."""
  name = (
    f'{_stem(c, bending, area_weight, config)}_world{physics.fan_yaw_deg:g}_'
    f'{physics.air_drag:g}_{physics.bending_damping:g}_{physics.edge_solref_scale:g}'
    f'_v{WORLD_VERSION}.json'
  )
  path = os.path.join(cache_dir, name)
  if os.path.exists(path):
    with open(path) as f:
      return json.load(f)['residual']
  m = protocol_candidates.mesh(c)
  params = physsim.params.make(bending, c.wind, area_weight)
  stats = []
  for phys in (physsim.mismatch.OWN, physics):
    out = physsim.simulate(
      _model(c, config, phys), params, wind=phys.wind(0.0), **_steady_kwargs(config)
    )
    if not np.all(out.valid):
      raise RuntimeError(f'{c.name}: a steady simulation blew up at bending {bending}')
    stats.append(
      protocol_camera.summaries(out.positions, m.vertices, c.resolution, c.size)[0]
    )
  residual = (stats[1] - stats[0]).tolist()
  files.write_json(path, {'candidate': c.name, 'bending': bending,
                          'area_weight': area_weight, 'residual': residual})  # fmt: skip
  return residual
