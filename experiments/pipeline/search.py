"""Searches over the fused objective: one recording, or many in lockstep.

Each recording has its own search (``searcher``: a ``bo.PosteriorSearch`` or
a ``bo.Minimizer``, with its own state file and stopping rule; ``resume``:
a rerun continues only its own). Searches advance together (``run``): each
step asks every unfinished search for its candidates (their GP steps as one
program: ``bo.batched``), scores all candidates of recordings of one
``Problem.structure`` in one call of that structure's ``Objective``
(``evaluation.Evaluator``), and tells each search its values. A candidate's
score does not depend on which batch it was in (per-candidate keys), so each
search goes as it would alone.

  from experiments.pipeline import search
  out = search.run([search.Job(config, recording, model_dir, workdir)], write)

(``write``: what a finished search leaves, ``results.write_result``; the
library's entry is ``estimation.estimate_many``.)
"""

from __future__ import annotations

import dataclasses
import functools
import os
import threading
import time
from collections.abc import Callable

import jax
import numpy as np

import bo
import physsim
from experiments.pipeline import deadline, embedding, evaluation, resume
from experiments.pipeline import objective as obj_lib
from experiments.pipeline.searcher import Job, LiveSearch, make_searcher, resolve_jobs

# Simulations at each finished posterior's median, for the fit check: the
# gusts' scatter between them against their distance to the recording.
REPLICAS = 8


def _compile_in_background(threads: list, evaluate, problems, sizes) -> None:
  """``evaluate.compile`` of ``sizes`` candidates a problem, in a thread
  appended to ``threads`` (a lockstep's steps, compiled during its design)."""
  threads.append(_in_background(evaluate.compile, problems, sizes, frames=True))


def _in_background(fn, *args, **kw) -> threading.Thread:
  """``fn(*args, **kw)`` started in a daemon thread, for a warm-up: what it
  returns or raises is dropped (the real call that follows raises the same)."""

  def quiet():
    try:
      fn(*args, **kw)
    except Exception:  # noqa: BLE001 - see the docstring
      pass

  t = threading.Thread(target=quiet, daemon=True)
  t.start()
  return t


def _compile_part(meter: physsim.one_off.Meter) -> str:
  """', of which compile N s' where a step both compiled and set up."""
  compile_s, setup_s = meter.parts()
  return (
    f', of which compile {compile_s:.1f} s' if compile_s > 0 and setup_s > 0 else ''
  )


def step_forecast(
  last_s: float,
  asked: int,
  simulated: int,
  one_off_s: float = 0.0,
  same_program: bool = False,
) -> float:
  """Seconds a lockstep step is forecast to take from the last one, which
  took ``last_s`` for ``asked`` candidates in ``simulated`` simulations, of
  which ``one_off_s`` compiling and setting up (``physsim.one_off``).

  The rest is scaled by ``asked / simulated`` where searches shared worlds
  (a design: ``distinct_worlds``) and the next step will not; the one-off
  part is paid again unless the next step runs the last one's program
  (``same_program``: no sharing before, the same padded rows). Still an
  overestimate after a shared design (its rendering and scoring, already
  done for every candidate, are scaled too): a stop too early costs a
  resume, one too late the step."""
  one_off_s = min(max(one_off_s, 0.0), last_s)
  rest = (last_s - one_off_s) * max(1.0, asked / max(simulated, 1))
  return rest + (0.0 if same_program else one_off_s)


def run(
  jobs: list[Job],
  write: Callable[..., dict],
  *,
  progress: bool = True,
  gp_on_cpu: bool = True,
  nets: dict[str, embedding.EmbeddingNet] | None = None,
  evaluator: evaluation.Evaluator | None = None,
) -> list[dict | Exception]:
  """Runs (or resumes) every job's search in lockstep, scoring their
  candidates together; hands each finished search to ``write``.

  Args:
    jobs: the recordings.
    write: ``write(job, search, result, best_frames, replicas=..., **timing)
      -> dict``, what a finished search leaves (``results.write_result``: the
      stages after the search, which this one does not import); ``replicas``:
      ``objective.Scores`` of simulations at its posterior's median that differ
      only in their gusts (``REPLICAS``; None: not a posterior of a shape
      distance), the fit check's.
    progress: print one line per step.
    gp_on_cpu: fit the GPs and propose on the CPU.
    nets: networks the caller has loaded already, by ``model_dir``.
    evaluator: an ``Evaluator`` to reuse across calls (default a new one).

  Returns:
    Per job, what ``write`` returned (or its ``estimate.json`` from a run
    that had finished before), or the exception that stopped it (a bad
    recording or model, another run in its workdir, every candidate blown
    up): one job's failure does not stop the others. Each search's files are
    written at the end of the step in which it stopped.

  Raises:
    deadline.Reached: the next step would end after the process's
      ``--time_limit`` (``deadline``); every search's state is saved, so the
      same call resumes.
  """
  lock = _Lockstep(
    jobs, write, progress, gp_on_cpu, evaluator or evaluation.Evaluator()
  )
  lock.start(nets)
  # Searches that finished before: their result stands (run.json matched),
  # read again where the calibration it quoted has changed since.
  ended = [s for s in lock.live if s.done()]
  for s in ended:
    lock.out[s.index] = resume.earlier_result(lock.jobs[s.index])
  lock.finish([s for s in ended if lock.out[s.index] is None])
  while active := [s for s in lock.live if not s.done()]:
    lock.step(active)
  return lock.out


@dataclasses.dataclass
class _Lockstep:
  """``run``'s searches as they advance together, and what they have cost.

  The searches' GP steps run as one program per setting (bo.batched), their
  rows stacked over the recordings and spread over the host's CPU devices
  (one per core but one: cli.host_devices) or the local GPUs. The batch keeps its
  first size (on CPUs the rows of searches that finished are skipped), so
  the program compiles once.
  """

  jobs: list[Job]
  write: Callable[..., dict]
  progress: bool
  gp_on_cpu: bool
  evaluate: evaluation.Evaluator
  out: list = dataclasses.field(default_factory=list)
  live: list[LiveSearch] = dataclasses.field(default_factory=list)
  t_start: float = dataclasses.field(default_factory=time.perf_counter)
  gp_seconds: float = 0.0
  steps: int = 0
  last_step_s: float = 0.0
  last_asked: int = 0
  last_run: int = 0
  last_rows: int = 0
  last_one_off: float = 0.0
  one_off: physsim.one_off.Meter = dataclasses.field(
    default_factory=physsim.one_off.Meter
  )  # compiles and set-ups of each step

  def __post_init__(self):
    self.out = [None] * len(self.jobs)
    self.seconds_before = self.evaluate.seconds
    self.gp_devices = (
      jax.local_devices(backend='cpu') if self.gp_on_cpu else jax.local_devices()
    )

  def start(self, nets) -> None:
    """Each job's setup, problem and search (or the exception refusing it)."""
    resolved = resolve_jobs(self.jobs, nets)
    self.jobs = [
      j if isinstance(j, Job) else job
      for j, job in zip(resolved, self.jobs, strict=True)
    ]
    for i, job in enumerate(self.jobs):
      if isinstance(resolved[i], Exception):
        self.out[i] = resolved[i]
        continue
      st = job.setup
      try:
        problem = obj_lib.make_problem(st.config, st.network.embedding, job.recording)
        opt = make_searcher(
          st.config, st.space, job.workdir, gp_on_cpu=self.gp_on_cpu, index=i
        )
        os.makedirs(job.workdir, exist_ok=True)
        resume.check_run(job, problem)
        self.live.append(LiveSearch(i, problem, opt, opt.start(), obj_lib.BestSeen()))
      except (ValueError, OSError) as e:
        self.out[i] = e

  def finish(self, finished: list[LiveSearch]) -> None:
    """Writes the results of searches that just ended. Their best candidates'
    frames were kept while scoring; one batch re-simulates those found before
    a resume."""
    ok = []
    for s in finished:
      if np.isfinite(s.argmin()[1]):
        ok.append(s)
      else:
        self.out[s.index] = ValueError(
          f'{self.jobs[s.index].recording.source}: every candidate simulation blew up'
        )
    frames = {s.index: s.best.frames_of(s.argmin()[0]) for s in ok}
    redo = [s for s in ok if frames[s.index] is None]
    if redo:
      scores = self.evaluate(
        [s.problem for s in redo], [s.argmin()[0][None] for s in redo],
        [len(s.state.Y) for s in redo], frames=True,
      )  # fmt: skip
      frames.update({s.index: sc.frames for s, sc in zip(redo, scores, strict=True)})
    t0 = time.perf_counter()
    results = bo.batched.result_many(
      [s.opt for s in ok], [s.state for s in ok], devices=self.gp_devices,
      min_rows=len(self.live),
    )  # fmt: skip
    t_result = time.perf_counter() - t0
    replicas = self._replicas(ok, results)
    for s, res in zip(ok, results, strict=True):
      job = self.jobs[s.index]
      timing = dict(
        seconds=time.perf_counter() - self.t_start,
        seconds_in_objective=self.evaluate.seconds - self.seconds_before,
        seconds_in_search=self.gp_seconds + t_result,
        recordings_in_batch=len(self.jobs),
      )
      with physsim.devices.on_host():  # the read-out's small eager work
        self.out[s.index] = self.write(
          job, s, res, frames[s.index], replicas=replicas.get(s.index), **timing
        )
      if self.progress:
        print(f'{job.recording.source}: {s.describe()}', flush=True)

  def _replicas(self, ok: list[LiveSearch], results) -> dict:
    """Per finished posterior search of a shape distance, ``REPLICAS``
    simulations at its posterior's median that differ only in their gusts
    and sensor noise (keys past its own evaluations), all in one call: what
    the fit check (``fit_check.predictive``) reads."""
    mine = [
      (s, np.tile(np.median(np.asarray(r.samples), axis=0), (REPLICAS, 1)))
      for s, r in zip(ok, results, strict=True)
      if hasattr(r, 'samples')
      and s.problem.config.scoring.distance in obj_lib.SHAPE_DISTANCES
    ]
    if not mine:
      return {}
    scores = self.evaluate(
      [s.problem for s, _ in mine], [u for _, u in mine],
      [len(s.state.Y) for s, _ in mine],
    )  # fmt: skip
    return {s.index: sc for (s, _), sc in zip(mine, scores, strict=True)}

  def step(self, active: list[LiveSearch]) -> None:
    """One step of every unfinished search: ask, score together, tell."""
    # --time_limit: not a step that would end after it (the first is
    # forecast as free: it compiles, and nothing says how long it takes)
    deadline.check(
      step_forecast(
        self.last_step_s, self.last_asked, self.last_run,
        one_off_s=self.last_one_off,
        same_program=self.last_run >= self.last_asked
        and evaluation.padded_rows(len(active)) == self.last_rows,
      ),
      f'step {self.steps} of {len(active)} searches',
    )  # fmt: skip
    t0 = time.perf_counter()
    self.one_off.mark()
    got = bo.batched.ask_many(
      [s.opt for s in active], [s.state for s in active], devices=self.gp_devices,
      min_rows=len(self.live),
    )  # fmt: skip
    asked = []
    for s, (x, state) in zip(active, got, strict=True):
      s.state = state
      asked.append(x)
    t1 = time.perf_counter()
    self.gp_seconds += t1 - t0
    warm, compiled = self._warm_up(active, asked)
    run_before = self.evaluate.simulated
    scores = self.evaluate(
      [s.problem for s in active], asked, [len(s.state.Y) for s in active],
      frames=True, compiled=compiled,
    )  # fmt: skip
    self.last_asked = sum(map(len, asked))
    self.last_run = self.evaluate.simulated - run_before
    for t in warm:
      t.join()
    t2 = time.perf_counter()
    for s, x, sc in zip(active, asked, scores, strict=True):
      s.best.update(x, sc.psd, sc.frames)
      synthetic = self.jobs[s.index].config.scoring.likelihood == 'synthetic'
      s.state = s.opt.tell(s.state, x, sc.residual if synthetic else sc.psd)
    ended = [s for s in active if s.done()]
    if self.progress:
      self._say(active, ended, t2 - t1, t1 - t0)
    self.finish(ended)
    self.steps += 1
    self.last_step_s = time.perf_counter() - t0
    self.last_one_off = self.one_off.seconds()
    self.last_rows = evaluation.padded_rows(len(active))

  def _warm_up(self, active, asked) -> tuple[list, Callable | None]:
    """On the first step off MuJoCo C: while the design's simulations run, the
    next step's GP program is traced and, in a lockstep, its fused program
    compiled (searches that share their design simulate it as a program of
    its own: distinct_worlds). The latter starts once the design's own
    program is compiled: two traces at once share Python's lock, and the
    design's is waited for. Returns the threads and the compile hook."""
    warm, compiled = [], None
    if self.steps == 0 and not evaluation.on_mujoco_c(
      [s.problem.config for s in active]
    ):
      warm.append(_in_background(
        bo.batched.warm_ask, [s.opt for s in active], [s.state for s in active],
        asked, devices=self.gp_devices, min_rows=len(self.live),
      ))  # fmt: skip
      if len(active) > 1:
        compiled = functools.partial(
          _compile_in_background, warm, self.evaluate, [s.problem for s in active],
          [s.problem.config.search.q for s in active],
        )  # fmt: skip
    return warm, compiled

  def _say(self, active, ended, sim_s: float, search_s: float) -> None:
    """The step's progress line."""
    if len(active) == 1:
      head, what = f'iteration {active[0].state.iteration:3d}', active[0].describe()
    else:
      head = f'step {self.steps:3d}'
      what = f'{len(active)} searches, {len(active) - len(ended)} still searching'
    shared = (
      f'; {self.last_asked} candidates' if self.last_run < self.last_asked else ''
    )
    print(
      f'{head}: {what} ({min(self.last_run, self.last_asked)} simulations '
      f'{sim_s:.1f} s, search {search_s:.1f} s{shared}; compile and set-up '
      f'{self.one_off.seconds():.1f} s{_compile_part(self.one_off)})',
      flush=True,
    )
