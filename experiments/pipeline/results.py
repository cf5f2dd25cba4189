"""What one finished search leaves: ``estimate.json``, ``posterior.npz`` and its pictures.

The stage after the posterior: a search's result
(``bo.Result`` or ``bo.posterior.Result``) read into the estimate a person
reads (the point, 50% and 90% intervals read at the calibration's levels,
errors against a known truth: ``summaries``) and written beside its trace,
montage (``search_figures``) and posterior figures.
"""

from __future__ import annotations

import functools
import os

import jax
import numpy as np

import bo
import physsim
from experiments.pipeline import (
  files,
  fit_check,
  layout,
  measurements,
  search_figures,
  summaries,
  units,
)
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import searcher as search_lib
from experiments.pipeline import setup as setup_lib
from experiments.pipeline.config import SHAPE_DISTANCES
from experiments.pipeline.measurements import Measured


def write_result(
  job: search_lib.Job,
  search: search_lib.LiveSearch,
  res,
  best_frames: np.ndarray,
  figures: bool = True,
  pictures: list | None = None,
  replicas=None,
  **timing,
) -> dict:
  """Writes ``estimate.json``, ``trace.png``, ``montage.png`` (and for a
  posterior ``posterior.png`` and ``posterior.npz``) of a finished search;
  returns the result dict.

  Args:
    job: the estimate, its ``setup`` resolved (``resolve_jobs``): its
      network's record (recipe, accuracy, retrieval; recorded beside the
      estimate: a parameter near 1 is not constrained by the video) and the
      calibration its intervals are read with.
    search: its finished search.
    res: ``search.opt.result(...)``: a ``bo.Result`` or ``bo.posterior.Result``.
    best_frames: the lowest-PSD candidate's camera-0 frames as its network saw
      them, ``(T, H, W)`` depth or ``(T, H, W, 3)`` colour.
    figures: draw the pictures (else only the JSON and ``posterior.npz``).
    pictures: where to put the pictures' drawing, as callables, instead of
      drawing them here (``estimate_many``).
    replicas: ``objective.Scores`` of simulations at the posterior's median
      that differ only in their gusts (``search.run``'s): the fit check's
      (``fit_check.predictive``); None: no check.
    **timing: seconds to record (``seconds``, ``seconds_in_objective``, ...).
  """
  st, recording, workdir = job.setup, job.recording, job.workdir
  config = st.config
  best = search.argmin()
  result = {
    'recording': recording.source,
    'material': config.simulation.material,
    'garment': config.simulation.garment,
    'point': config.search.point,
  }
  draws = []  # the pictures, each a callable
  if config.search.point == 'argmin':
    result.update(_argmin_summary(st, res, best[0]))
  else:
    result.update(_posterior_summary(
      st, res, workdir, recording.truth, draws if figures else None,
      recording.source,
    ))  # fmt: skip
  result.update(_search_record(st, res, best, result['point_unit'], timing))
  if config.posterior and config.scoring.distance in SHAPE_DISTANCES:
    result['fit_check'] = _fit_check(st, res, replicas)
  if recording.truth is not None:
    result.update(_against_truth(result, recording.truth, st.space))
  files.write_json(os.path.join(workdir, layout.ESTIMATE_FILE), result)
  if not figures:
    return result
  draws += _search_pictures(job, search, res, best_frames)
  if pictures is not None:
    pictures.extend(draws)
  else:
    for draw in draws:
      draw()
  return result


def _search_record(st: setup_lib.Setup, res, best: tuple, point, timing: dict) -> dict:
  """What the search did beside its estimate: the bending matrix at the point
  (``point``, unit cube), the best evaluation (``best``: its unit point and
  distance) in physical values, the box it searched, its evaluations,
  failures and iterations, the network's retrieval, the seconds and the
  settings."""
  config, space = st.config, st.space
  x_best, y_best = best
  retrieval = st.network.retrieval
  material = physsim.load_material(physsim.fabric(config.simulation.material).material)
  bending = float(np.ravel(physsim.from_unit(point, space).bending_scale)[0])
  return {
    'bending_matrix_Nm': (bending * material.bending).tolist(),
    'argmin': {
      f: float(np.ravel(v)[0])
      for f, v in zip(posterior_lib.FIELDS, physsim.from_unit(x_best, space), strict=True)
    },
    'search_box': space.bounds().tolist(),
    **({'search_box_widened': list(st.widened)} if st.widened else {}),
    'psd_best': float(y_best),
    'evaluations': int(len(res.Y)),
    'failed_evaluations': int(np.sum(~np.isfinite(search_lib.discrepancies(res.Y)))),
    'iterations': int(res.n_iter),
    'stopped_by_rule': bool(res.stopped_early),
    **({'network_retrieval_vs_chance': retrieval} if retrieval else {}),
    **{k: float(v) for k, v in timing.items()},
    'config': config.flat(),
  }  # fmt: skip


def _fit_check(st: setup_lib.Setup, res, replicas) -> dict:
  """Whether the simulations at the point reproduce the recording
  (``replicas``; None: not checked) and which readings the video alone
  disagrees with (``fit_check``)."""
  config = st.config
  return {
    'predictive': None if replicas is None else fit_check.predictive(replicas),
    'conflicts': fit_check.conflicts(
      res.log_lik, search_lib.posterior_config(config.search, config.scoring).grid,
      st.space, config.measured,
    ),
  }  # fmt: skip


def _against_truth(result: dict, truth: dict, space: physsim.SearchSpace) -> dict:
  """A known truth, the estimate's errors against it beside the range
  centre's, and whether each interval held it. With the air coefficient free
  the point is the estimate's true wind and its c; else the search's point."""
  est = result['estimate']
  air = 'air_coefficient' in est
  point = (
    physsim.params.make(*(est[f]['value'] for f in measurements.FIELDS))
    if air
    else physsim.from_unit(result['point_unit'], space)
  )
  return {
    'truth': truth,
    'errors': summaries.errors(
      point, truth, space, air=est['air_coefficient']['value'] if air else None
    ),
    'covered': summaries.covered(result, truth),
  }


def _search_pictures(job: search_lib.Job, search: search_lib.LiveSearch, res,
                     best_frames: np.ndarray) -> list:  # fmt: skip
  """The drawing of ``trace.png`` (in the fabric's units, as the table's) and
  ``montage.png`` (the recording beside the best simulation, in the modality
  its network saw), as callables."""
  st, recording, workdir = job.setup, job.recording, job.workdir
  config = st.config
  iteration = search_figures.iterations_of(
    len(res.Y), config.search.n_init, config.search.q
  )
  return [
    functools.partial(
      search_figures.plot_trace, res.X, search_lib.discrepancies(res.Y), iteration,
      st.space, recording.truth, os.path.join(workdir, layout.TRACE_PNG),
      distance=config.scoring.distance,
      units=units.in_units(config.simulation.material),
    ),
    functools.partial(
      search_figures.plot_montage,
      recording.rgb if search.problem.net.modality == 'rgb' else recording.depth,
      best_frames, recording.fps, os.path.join(workdir, layout.MONTAGE_PNG),
      sim_label='best simulation',
    ),
  ]  # fmt: skip


def _argmin_summary(st: setup_lib.Setup, res: bo.Result, x_best) -> dict:
  """The paper's point (the best evaluation) and where the GP puts the minimum."""
  config, space = st.config, st.space
  post = bo.minimizer_samples(
    res.X, res.Y, search_lib.BOUNDS, jax.random.key(config.seed)
  )
  samples = measurements.physical(post.samples, space)
  best = physsim.from_unit(x_best, space)
  return {
    'point_unit': np.asarray(x_best, np.float64).tolist(),
    'estimate': summaries.summary(samples, best),
    'load_ratio': summaries.load_ratio_summary(samples, best),
    'interval_meaning': 'where the GP puts the minimum of the PSD, not where '
    'the parameters are; not calibrated',
  }


def _name(source: str) -> str:
  """A recording's name for a title: its file or folder (a dataset sequence:
  material/sequence)."""
  parts = os.path.normpath(source).split(os.sep) if source else []
  return '/'.join(parts[-2:]) if parts and parts[-1].isdigit() else (parts or [''])[-1]


def _posterior_summary(st: setup_lib.Setup, res, workdir: str, truth,
                       draws: list | None = None, source: str = '') -> dict:  # fmt: skip
  """The posterior median as the point, credible intervals, the prior's width;
  writes ``posterior.npz`` and puts the drawing of ``posterior.png`` in
  ``draws`` (None: no picture). The intervals are read at the levels of
  ``st.calibration`` where it matched these settings, network and mode."""
  config, space, note = st.config, st.space, st.calibration
  pc = search_lib.posterior_config(config.search, config.scoring)
  points = bo.posterior.grid_points(pc.grid)
  lp = measurements.log_prior(points, space, config.measured, pc.grid)
  prior, samples = _refined_draws(
    config.measured, config.seed, space, pc.grid, lp, res.samples
  )
  summarise = functools.partial(
    posterior_lib.summarise, samples, space, prior, levels_of(note), weights_of(note),
    config.measured,
  )  # fmt: skip
  summary = summarise()
  # The point: each parameter's (recalibrated) median or Bayes point, in the
  # search's coordinates (with the air free, its wind is the effective one).
  which = 'bayes' if config.search.point == 'bayes' else 'median'
  point = physsim.params.make(*(summary[f][which] for f in posterior_lib.FIELDS))
  median = np.clip(physsim.to_unit(point, space), -1.0, 1.0)
  air = {}
  if config.measured.air_free:
    air = _air_draws(config.measured, config.seed, space, samples, prior)
  if air:  # what a person reads: the true wind, and c
    summary = summarise(air=(air['air_samples'], air['air_prior_samples']))
  estimate = {}
  for name in [*posterior_lib.FIELDS, *(['air_coefficient'] if air else [])]:
    s = summary[name]
    estimate[name] = {'value': s[which], **s}
  files.write_atomic(
    os.path.join(workdir, layout.POSTERIOR_FILE),
    lambda p: np.savez(
      p, samples=samples, prior_samples=prior, log_post=res.log_post,
      log_lik=res.log_lik, log_prior=lp, grid=np.asarray(pc.grid),
      bounds=space.bounds(), gp_mean=res.mean, gp_var=res.var,
      noise_sd=res.noise_sd, floor=res.floor, **air,
    ),
  )  # fmt: skip
  if draws is not None:
    draws.append(functools.partial(
      posterior_lib.plot, samples, prior, space, truth,
      os.path.join(workdir, layout.POSTERIOR_PNG),
      title=f'{config.simulation.material}: posterior given {_name(source) or os.path.basename(workdir)}',
      summary=summary, point=which,
      units=units.in_units(config.simulation.material),
    ))  # fmt: skip
  return {
    'point_unit': np.ravel(median).tolist(),
    'estimate': estimate,
    'load_ratio': {'value': summary['load_ratio'][which], **summary['load_ratio']},
    **_noise_record(config.scoring.likelihood, res),
    'interval_meaning': _interval_meaning(note),
    'calibration': note,
  }


def _refined_draws(measured: Measured, seed: int, space: physsim.SearchSpace,
                   grid, lp, samples) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
  """(prior, posterior) draws in the unit cube, each refined off the grid's
  points (``posterior.refine_draws``, with the ``measured`` readings and
  the estimate's ``seed``): the prior's as many as the posterior's, drawn
  from the log prior ``lp`` on ``grid``."""
  key = jax.random.key(seed)
  prior = posterior_lib.refine_draws(
    posterior_lib.prior_samples(
      jax.random.fold_in(key, 7), grid, lp, len(samples)
    ), grid, space, measured, seed + 1,
  )  # fmt: skip
  posterior = posterior_lib.refine_draws(samples, grid, space, measured, seed)
  return prior, posterior


def _air_draws(measured: Measured, seed: int, space: physsim.SearchSpace, samples,
               prior) -> dict:  # fmt: skip
  """The air coefficient's draws beside the posterior's and the prior's: the
  wind they hold is the effective one, c read from it and the ``measured``
  wind reading (``measurements.air_draws``, from the estimate's ``seed``), as
  ``posterior.npz`` keeps them."""
  return {
    'air_samples': measurements.air_draws(
      measurements.physical(samples, space)[:, 1], measured, seed
    ),
    'air_prior_samples': measurements.air_draws(
      measurements.physical(prior, space)[:, 1], measured, seed + 1
    ),
  }  # fmt: skip


def _noise_record(likelihood: str, res) -> dict:
  """The noise the ``likelihood`` read: the log PSD's spread, or for the
  'synthetic' likelihood (None there) the shape's spread per summary, m."""
  synthetic = likelihood == 'synthetic'
  return {
    'noise_sd_log_psd': None if synthetic else res.noise_sd,
    **({'noise_sd_shape_m': np.asarray(res.noise_sd).tolist()} if synthetic else {}),
  }


def _interval_meaning(note: dict | None) -> str:
  """What the intervals are, as ``estimate.json`` says it: recalibrated where
  the calibration ``note`` matched and was recalibrated."""
  recalibrated = bool(note and note.get('recalibrated') and note.get('matches'))
  return (
    'central credible intervals of the posterior given the video (and any '
    'measured wind or area weight)'
    + (
      ', read at levels recalibrated on simulated recordings so that they hold '
      'the truth as often as they say'
      if recalibrated
      else ''
    )
  )


def levels_of(note: dict | None) -> dict | None:
  """The recalibrated CDF levels a calibration note carries (it matched), else None."""
  return note.get('levels') if note and note.get('matches') else None


def weights_of(note: dict | None) -> dict | None:
  """The calibrated weights of the posterior's points (it matched), else None."""
  return note.get('weights') if note and note.get('matches') else None
