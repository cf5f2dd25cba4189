"""One recording's search: the job that asks for it, the ``bo`` search its settings make, and that search as it advances.

A ``Job`` names a recording, its settings, its network and its workdir;
``resolve_jobs`` gives each its ``setup.Setup`` (the network, the search box,
the matched calibration), reading each network once. ``make_searcher`` turns
the settings into a ``bo.PosteriorSearch`` (the default, ``point='median'``:
the posterior of bending, wind and area weight) or a ``bo.Minimizer``
(``point='argmin'``, the paper's protocol), each with its own state file and
stopping rule, searching the unit cube (``BOUNDS``). ``LiveSearch`` is one
such search as the lockstep (``search.run``) advances it.
"""

from __future__ import annotations

import dataclasses
import os
from typing import NamedTuple

import jax
import numpy as np

import bo
import physsim
from experiments.pipeline import embedding, layout, measurements
from experiments.pipeline import objective as obj_lib
from experiments.pipeline import setup as setup_lib
from experiments.pipeline.config import Scoring, Search
from experiments.pipeline.objective import EstimateConfig
from experiments.pipeline.recording import Recording

BOUNDS = np.array([[-1.0, 1.0]] * 3)  # the search runs in the unit cube


class Job(NamedTuple):
  """One recording to estimate.

  Attributes:
    config: its settings.
    recording: the video (``recording.load_recording``).
    model_dir: its material's trained network; '' for none (the shape
      distance alone: frames compared at the recording's loaded size).
    workdir: where its state, JSON and pictures go.
    allow_other_material: search with a network trained on other fabrics
      than ``config.simulation.material`` (else refused, ``setup.check_material``).
    setup: what the estimate is built from (``setup.Setup``: the network and
      its record, the search box, the matched calibration), resolved once by
      ``resolve_jobs``; None until then.
  """

  config: EstimateConfig
  recording: Recording
  model_dir: str
  workdir: str
  allow_other_material: bool = False
  setup: setup_lib.Setup | None = None


def resolve_jobs(
  jobs: list[Job], nets: dict[str, embedding.EmbeddingNet] | None = None
) -> list[Job | Exception]:
  """Each job with its ``setup.Setup`` (a job that has one keeps it), or the
  exception that refused it (a bad setting, no trained run at its folder, a
  network of another fabric). Each network is restored and its record read
  once for all the jobs (``nets``: networks the caller restored already, by
  folder); without one (the shape distance) the frames are compared at the
  recording's own size."""
  nets = nets or {}
  records: dict[str, setup_lib.Network] = {}
  out: list[Job | Exception] = []
  for job in jobs:
    if job.setup is not None:
      out.append(job)
      continue
    try:
      if job.model_dir:
        if job.model_dir not in records:
          records[job.model_dir] = setup_lib.record(
            job.model_dir, nets.get(job.model_dir)
          )
        net = records[job.model_dir]
      else:
        shape = job.recording.depth.shape[1:]
        net = setup_lib.Network('', embedding.no_network(shape), None, None, None)
      out.append(job._replace(setup=setup_lib.resolve(
        job.config, job.model_dir, allow_other_material=job.allow_other_material,
        network_record=net,
      )))  # fmt: skip
    except (ValueError, OSError) as e:
      out.append(e)
  return out


def gp_device(i: int = 0):
  """Where search ``i`` fits its GP when asked alone: a CPU device. The GP
  holds tens to hundreds of points, so on a GPU its L-BFGS loops only wait on
  kernel launches, while the GPU has the simulations to run. ``estimate_many``
  asks all its searches at once (``bo.batched``), spread over every CPU device
  (``cli.host_devices`` makes one per core but one)."""
  cpus = jax.local_devices(backend='cpu')  # this process's, under jax.distributed
  return cpus[i % len(cpus)]


def make_searcher(config: EstimateConfig, space: physsim.SearchSpace, workdir: str,
                  *, gp_on_cpu: bool = True, index: int = 0):  # fmt: skip
  """The search of an estimate: ``bo.PosteriorSearch`` or ``bo.Minimizer``
  (``index``: the search's number in a lockstep run, for its GP's device)."""
  device = gp_device(index) if gp_on_cpu else None
  s = config.search
  if s.point == 'argmin':
    return bo.Minimizer(
      BOUNDS, **minimizer_settings(s, config.seed, workdir), device=device
    )
  pc = posterior_config(s, config.scoring)
  points = bo.posterior.grid_points(pc.grid)
  return bo.PosteriorSearch(
    pc, n_init=s.n_init, n_iter=s.max_iter,
    log_prior=measurements.log_prior(points, space, config.measured, pc.grid),
    x0=np.zeros(3), seed=config.seed, stop_tol=2.0 * s.stop_rel_change,
    stop_window=s.stop_window, min_iter=s.min_iter,
    state_path=os.path.join(workdir, layout.POSTERIOR_STATE), device=device,
  )  # fmt: skip


def posterior_config(s: Search, sc: Scoring) -> bo.PosteriorConfig:
  """The ``bo.PosteriorConfig`` of an estimate's search and scoring sections
  (its grid, batch and likelihood)."""
  return bo.PosteriorConfig(
    d=3, grid=tuple(s.posterior_grid), q=s.q, replicates=s.replicates,
    likelihood=sc.likelihood, sharpness=sc.sharpness, model_error=sc.model_error,
    summaries=len(physsim.shape.SUMMARY) if sc.likelihood == 'synthetic' else 1,
  )  # fmt: skip


def minimizer_settings(s: Search, seed: int, workdir: str) -> dict:
  """``bo.Minimizer`` settings of an estimate's search section and seed, its
  state in ``workdir``."""
  return dict(
    n_init=s.n_init,
    n_iter=s.max_iter,
    q=s.q,
    x0=np.zeros(3),  # the paper starts from the range centre
    seed=seed,
    acquisition='logei',
    stop_rel_change=s.stop_rel_change,
    stop_window=s.stop_window,
    stop_min_iter=s.min_iter,
    state_path=os.path.join(workdir, layout.BO_STATE),
  )


def discrepancies(y) -> np.ndarray:
  """(n,) each evaluation's discrepancy from what its search was told: the
  discrepancy itself, or for the 'synthetic' likelihood's residuals ``(n, k)``
  their squared length (the shape distance; NaN: failed)."""
  y = np.asarray(y, np.float64)
  return np.sum(y**2, axis=1) if y.ndim == 2 else y


@dataclasses.dataclass
class LiveSearch:
  """One job's search as it advances (``state`` and ``best`` change)."""

  index: int  # into ``jobs``
  problem: obj_lib.Problem
  opt: bo.Minimizer | bo.PosteriorSearch
  state: bo.State | bo.posterior.State
  best: obj_lib.BestSeen

  def done(self) -> bool:
    return self.opt.done(self.state)

  def argmin(self) -> tuple[np.ndarray, float]:
    """The lowest-PSD candidate so far and its PSD (inf: none finite)."""
    y = discrepancies(self.state.Y)
    y = np.where(np.isfinite(y), y, np.inf)
    if not len(y) or not np.isfinite(y).any():
      return np.full(3, np.nan), float('inf')
    i = int(np.argmin(y))
    return self.state.X[i], float(y[i])

  def describe(self) -> str:
    """Where the search stands, in one line."""
    space = self.problem.space
    if isinstance(self.opt, bo.Minimizer):
      return describe_best(*self.argmin(), space)
    h = self.state.history
    if h is None or not len(h):
      return 'initial design scored'
    q = measurements.physical(h[-1], space)  # (3, 3): 5/50/95% x fields
    return (
      'posterior so far (uncalibrated; the table gives the estimate): median [90%] '
      + ', '.join(
        f'{measurements.SHORT[f]} {q[1, i]:.3g} [{q[0, i]:.3g}, {q[2, i]:.3g}]'
        for i, f in enumerate(measurements.FIELDS)
      )
    )


def describe_best(x_best, y_best, space) -> str:
  """A minimiser's progress line's worth: the best PSD and its parameters."""
  if not np.isfinite(y_best):
    return 'every simulation so far blew up'
  p = physsim.from_unit(x_best, space)
  return (
    f'best PSD {y_best:.4g} at bending x{float(p.bending_scale):.3g}, wind '
    f'{float(p.wind_speed):.2f} m/s, area weight {float(p.area_weight):.3f} kg/m^2'
  )
