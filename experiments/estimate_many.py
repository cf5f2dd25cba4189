"""Estimate many recordings at once: one simulation batch per iteration for all.

Every recording keeps its own search (a ``bo.Minimizer`` with the settings
``experiments.estimate`` uses, its own state file, stopping rule and resume),
but the searches advance in lockstep: each iteration asks every unfinished
search for its candidates, simulates all of them as one batch (one per mesh
and clock, ``estimate.evaluate_problems``), renders and scores each against its
own recording and network, and tells each search its values. A candidate's
score does not depend on which batch it was in (per-world gust and sensor keys,
one compiled cloth per mesh), so each search goes as ``estimate`` would have
run it alone, up to floating-point summation order in MJX.

Why: MJX on a GPU costs about the same per step for 4 worlds as for ~64
(BENCHMARKS.md), so a table of 20 recordings x 4 candidates costs about one
estimate's time instead of twenty.

  from experiments import estimate_many as em
  results = em.estimate_many([em.Job(config, recording, model_dir, workdir), ...])

``experiments.tables --batched`` runs its evaluation set this way.
"""

from __future__ import annotations

import dataclasses
import os
import time
from typing import NamedTuple

import numpy as np

import bo
from experiments import estimate as est


@dataclasses.dataclass
class _Search:
  """One job's search as it advances (``state`` and ``best`` change)."""

  index: int  # into ``jobs``
  problem: est.Problem
  opt: bo.Minimizer
  state: bo.State
  best: est.BestSeen

  def done(self) -> bool:
    return self.opt.done(self.state)


class Job(NamedTuple):
  """One recording to estimate.

  Attributes:
    config: its settings (``estimate.EstimateConfig``).
    recording: the video (``estimate.load_recording``).
    model_dir: its material's trained network.
    workdir: where its state, JSON and pictures go.
  """

  config: est.EstimateConfig
  recording: est.Recording
  model_dir: str
  workdir: str


def estimate_many(
  jobs: list[Job],
  *,
  progress: bool = True,
  gp_on_cpu: bool = True,
  nets: dict[str, est.EmbeddingNet] | None = None,
) -> list[dict | Exception]:
  """Runs (or resumes) every job's estimate, batching their simulations.

  Args:
    jobs: the recordings.
    progress: print one line per iteration.
    gp_on_cpu: fit the GPs and propose on the CPU.
    nets: networks the caller has loaded already, by ``model_dir``.

  Returns:
    Per job, its ``estimate.json`` dict, or the exception that stopped it (a
    bad recording or model, another run in its workdir, every candidate blown
    up): one job's failure does not stop the others. Each search's files are
    written at the end of the step in which it stopped, not at the end of
    the run; its ``seconds`` are the batch's wall time until then.
  """
  t_start = time.time()
  out: list[dict | Exception | None] = [None] * len(jobs)
  nets = dict(nets or {})
  live: list[_Search] = []
  for i, job in enumerate(jobs):
    try:
      if job.model_dir not in nets:
        nets[job.model_dir] = est.load_embedding(job.model_dir)
      net = est._check_inputs(job.recording, job.model_dir, nets[job.model_dir])
      os.makedirs(job.workdir, exist_ok=True)
      problem = est.make_problem(
        job.config, net.network, net.params, net.input_mode, job.recording,
        modality=net.modality, clip_frames=net.clip_frames,
      )  # fmt: skip
      est._check_run(
        job.workdir, job.config, job.recording, job.model_dir, net.modality
      )
      opt = bo.Minimizer(
        est.BOUNDS,
        **est.minimizer_settings(job.config, job.workdir),
        device=est.gp_device() if gp_on_cpu else None,
      )
      live.append(_Search(i, problem, opt, opt.start(), est.BestSeen()))
    except (ValueError, OSError) as e:
      out[i] = e

  sim_seconds = 0.0

  def finish(finished):
    """Writes the results of searches that just ended, so each lands as soon
    as it can. Their best candidates' frames (for the montages) were kept while
    scoring; one batch re-simulates those found before a resume."""
    res = {s.index: s.opt.result(s.state) for s in finished}
    ok = []
    for s in finished:
      if np.isfinite(res[s.index].y_best):
        ok.append(s)
      else:
        out[s.index] = ValueError(
          f'{jobs[s.index].recording.source}: every candidate simulation blew up'
        )
    frames = {s.index: s.best.frames_of(res[s.index].x_best) for s in ok}
    redo = [s for s in ok if frames[s.index] is None]
    sims = _per_group(
      est.simulate_problems, redo, [res[s.index].x_best[None] for s in redo]
    )
    frames.update(
      {s.index: np.asarray(f[0, 0]) for s, f in zip(redo, sims, strict=True)}
    )
    wall = time.time() - t_start
    for s in ok:
      job, r = jobs[s.index], res[s.index]
      out[s.index] = est.finish(
        job.config, job.recording, s.problem.modality, job.workdir, r,
        frames[s.index], retrieval=est.network_retrieval(job.model_dir),
        seconds=wall, seconds_in_objective=sim_seconds,
        recordings_in_batch=len(jobs),
      )  # fmt: skip
      if progress:
        where = est.describe(r.x_best, r.y_best, s.problem.space)
        print(f'{job.recording.source}: {where}', flush=True)

  finish([s for s in live if s.done()])  # finished before a resume
  it = 0
  while active := [s for s in live if not s.done()]:
    t0 = time.time()
    asked = []
    for s in active:
      x, s.state = s.opt.ask(s.state)
      asked.append(x)
    t1 = time.time()
    values = _per_group(est.evaluate_problems, active, asked, keep_best=True)
    t2 = time.time()
    sim_seconds += t2 - t1
    for s, x, y in zip(active, asked, values, strict=True):
      s.state = s.opt.tell(s.state, x, y)
    ended = [s for s in active if s.done()]
    if progress:
      print(
        f'step {it:3d}: {len(active)} searches, {sum(map(len, asked))} candidates '
        f'simulated and scored in {t2 - t1:.1f} s, GP {t1 - t0:.1f} s; '
        f'{len(active) - len(ended)} still searching',
        flush=True,
      )
    finish(ended)
    it += 1
  return out


def _per_group(call, searches: list[_Search], xs, *, keep_best: bool = False) -> list:
  """``call`` (``estimate.evaluate_problems`` or ``simulate_problems``) once per
  simulation group (mesh and clock) of ``searches``; the first item of each
  search's result, in ``searches`` order. ``keep_best`` passes each search's
  ``BestSeen`` to ``evaluate_problems``."""
  groups: dict[tuple, list[int]] = {}
  for k, s in enumerate(searches):
    groups.setdefault(s.problem.sim_group(), []).append(k)
  out: list = [None] * len(searches)
  for members in groups.values():
    kw = dict(best=[searches[k].best for k in members]) if keep_best else {}
    res = call(
      [searches[k].problem for k in members], [xs[k] for k in members], pad=True, **kw
    )
    for k, r in zip(members, res, strict=True):
      out[k] = r[0]
  return out
