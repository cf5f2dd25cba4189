"""Searches over the fused objective: one recording, or many in lockstep.

Each recording has its own search: a ``bo.PosteriorSearch`` (the default,
``point='median'``: the posterior of bending, wind and area weight) or a
``bo.Minimizer`` (``point='argmin'``, the paper's protocol), with its own state
file, stopping rule and resume. Searches advance together: each step asks
every unfinished search for its candidates (their GP steps as one program:
``bo.batched``), scores all candidates of
recordings of one ``Problem.structure`` in one call of that structure's
``Objective`` (MJX costs about the same per step for 4 worlds as for ~64), and
tells each search its values. A candidate's score does not depend on which
batch it was in (per-candidate keys), so each search goes as it would alone.

  from experiments.pipeline import search
  result = search.estimate(config, recording, model_dir, workdir)
  results = search.estimate_many([search.Job(config, recording, model_dir, workdir)])
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import threading
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import numpy as np

import bo
import physsim
from experiments.pipeline import deadline, embedding, files, layout, measurements
from experiments.pipeline import objective as obj_lib
from experiments.pipeline import setup as setup_lib
from experiments.pipeline.objective import EstimateConfig
from experiments.pipeline.recording import Recording, read_json

BOUNDS = np.array([[-1.0, 1.0]] * 3)  # the search runs in the unit cube
# Config fields that do not change what an estimate searches (the shared
# discrepancy: only how the joint reads the searches).
_RESUMABLE_FIELDS = ('workers', 'calibration', 'shared_bias')  # fmt: skip


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
  (``cli.host_devices`` makes one per core)."""
  cpus = jax.local_devices(backend='cpu')  # this process's, under jax.distributed
  return cpus[i % len(cpus)]


def make_searcher(config: EstimateConfig, space: physsim.SearchSpace, workdir: str,
                  *, gp_on_cpu: bool = True, index: int = 0):  # fmt: skip
  """The search of an estimate: ``bo.PosteriorSearch`` or ``bo.Minimizer``
  (``index``: the search's number in a lockstep run, for its GP's device)."""
  device = gp_device(index) if gp_on_cpu else None
  s = config.search
  if s.point == 'argmin':
    return bo.Minimizer(BOUNDS, **minimizer_settings(config, workdir), device=device)
  pc = posterior_config(config)
  points = bo.posterior.grid_points(pc.grid)
  return bo.PosteriorSearch(
    pc, n_init=s.n_init, n_iter=s.max_iter,
    log_prior=measurements.log_prior(points, space, config.measured, pc.grid),
    x0=np.zeros(3), seed=config.seed, stop_tol=2.0 * s.stop_rel_change,
    stop_window=s.stop_window, min_iter=s.min_iter,
    state_path=os.path.join(workdir, layout.POSTERIOR_STATE), device=device,
  )  # fmt: skip


def posterior_config(config: EstimateConfig) -> bo.PosteriorConfig:
  """The ``bo.PosteriorConfig`` of an estimate."""
  s, sc = config.search, config.scoring
  return bo.PosteriorConfig(
    d=3, grid=tuple(s.posterior_grid), q=s.q, replicates=s.replicates,
    likelihood=sc.likelihood, sharpness=sc.sharpness, model_error=sc.model_error,
    summaries=len(physsim.shape.SUMMARY) if sc.likelihood == 'synthetic' else 1,
  )  # fmt: skip


def minimizer_settings(config: EstimateConfig, workdir: str) -> dict:
  """``bo.Minimizer`` settings of an estimate."""
  s = config.search
  return dict(
    n_init=s.n_init,
    n_iter=s.max_iter,
    q=s.q,
    x0=np.zeros(3),  # the paper starts from the range centre
    seed=config.seed,
    acquisition='logei',
    stop_rel_change=s.stop_rel_change,
    stop_window=s.stop_window,
    stop_min_iter=s.min_iter,
    state_path=os.path.join(workdir, layout.BO_STATE),
  )


def _digest(a) -> str:
  return hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()


def check_run(job: Job, problem) -> None:
  """Writes what defines the run; refuses a workdir holding another run.

  ``bo_state.npz`` alone only knows the optimiser's settings, so without this
  a rerun with another recording, camera, model or material would silently
  continue the old search.
  """
  workdir, config, recording = job.workdir, job.config, job.recording
  d = problem.data
  runs = embedding.members(job.model_dir) if job.model_dir else []  # none: shape
  run = {
    'config': {k: v for k, v in config.flat().items() if k not in _RESUMABLE_FIELDS},
    'recording_sha1': _digest(np.asarray(recording.depth, np.float32)),
    'camera': {
      'intrinsics': problem.intr.to_dict(),
      'poses_sha1': _digest(np.asarray(d.poses.rotation, np.float32))
      + _digest(np.asarray(d.poses.position, np.float32)),
    },
    'model_dir': ','.join(os.path.abspath(d) for d in runs),
  }
  if recording.rgb is not None and problem.net.modality == 'rgb':
    run['recording_rgb_sha1'] = _digest(recording.rgb)
  run = json.loads(json.dumps(run))  # tuples -> lists, as read back
  path = os.path.join(workdir, layout.RUN_FILE)
  if os.path.exists(path):
    old = read_json(path)
    diff = sorted(
      k for k in set(run) | set(old) if k != 'config' and run.get(k) != old.get(k)
    )
    diff += sorted(
      f'config.{k}'
      for k in set(run['config']) | set(old.get('config', {}))
      if run['config'].get(k) != old.get('config', {}).get(k)
    )
    if diff:
      raise ValueError(
        f'{path}: the workdir holds an estimate with different {diff}; use a '
        'new workdir'
      )
    return
  files.write_json(path, run)


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


def _pad(n: int) -> int:
  """Rows for ``n`` problems: up to 16 the next power of two, beyond it ``n``
  rounded up to three significant binary digits (at most 1/8 more), so that
  a shrinking set of searches compiles a few program shapes per doubling.
  A power of two wasted up to half of a large call: 210 searches ran as 256
  rows, 22% more worlds simulated, rendered and scored in every step, where
  this gives 224."""
  n = max(n, 1)
  if n <= 16:
    return 1 << (n - 1).bit_length()
  step = 1 << (n.bit_length() - 4)
  return -(-n // step) * step


# Simulations at each finished posterior's median, for the fit check: the
# gusts' scatter between them against their distance to the recording.
REPLICAS = 8

# On a GPU a fused call of up to this many worlds (rows x candidates) costs
# what one of 24 does: the simulation's steps wait on kernel launches, not on
# arithmetic (physsim.devices; such a call also runs on one device).
FLAT_WORLDS = physsim.devices.FLAT_WORLDS


def _compile_in_background(threads: list, evaluate, problems, sizes) -> None:
  """``evaluate.compile`` of ``sizes`` candidates a problem, in a thread
  appended to ``threads`` (a lockstep's steps, compiled during its design)."""
  threads.append(_in_background(evaluate.compile, problems, sizes, frames=True))


def _on_mujoco_c(configs) -> bool:
  return all(physsim.resolve_backend(c.hardware.backend) == 'c' for c in configs)


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


def _call_size(configs, n: int, rows: int = 1) -> int:
  """Candidates per fused call for ``n`` candidates of ``rows`` searches with
  ``configs`` (``Evaluator``): their ``q`` on MuJoCo C; elsewhere all ``n``,
  padded up to the searches' initial design where that keeps the call within
  ``FLAT_WORLDS`` worlds, so that a single estimate compiles one program
  shape for its design and its steps."""
  if _on_mujoco_c(configs):
    return min(n, max(c.search.q for c in configs))
  padded = max(n, *(c.search.n_init for c in configs))
  return padded if rows * padded <= FLAT_WORLDS else n


class Evaluator:
  """Scores candidates of many problems, one fused call per structure (on
  MuJoCo C, per batch of at most the search's ``q`` candidates).

  Holds one ``Objective`` per structure it has seen (built on first use). On
  the C backend, whose time grows with the worlds and where every program
  shape compiles for seconds, an initial design larger than ``q`` is scored
  in calls of ``q`` (the last one padded): a search compiles one program
  shape, not one for its design and another for its steps. On a GPU a call of
  48 candidates costs what one of 24 does, so the design stays one call
  (BENCHMARKS.md: two calls were slower there) and a small call is padded to
  the design's size instead (``FLAT_WORLDS``): one program shape there too.
  Each candidate keeps its own keys (its evaluation number), so the scores are
  those of one call; worlds that repeat across rows (searches sharing a
  design, padding rows) are simulated once (``objective.distinct_worlds``).
  """

  def __init__(self):
    self.objectives: dict[tuple, obj_lib.Objective] = {}
    self.seconds = 0.0  # wall time inside the fused calls
    self._lock = threading.Lock()  # one Objective per structure (``compile``)

  @property
  def simulated(self) -> int:
    """Simulations run so far (worlds that simulate alike run once:
    ``objective.distinct_worlds``)."""
    return sum(o.simulated for o in self.objectives.values())

  def objective(self, problem: obj_lib.Problem) -> obj_lib.Objective:
    k = problem.structure()
    with self._lock:
      if k not in self.objectives:
        self.objectives[k] = obj_lib.Objective(problem)
      return self.objectives[k]

  def __call__(self, problems, us, firsts, *, frames: bool = False,
               positions: bool = False,
               compiled: Callable[[], object] | None = None,
               ) -> list[obj_lib.Scores]:  # fmt: skip
    """Per problem, the ``Scores`` of its candidates ``us[i] (q_i, 3)`` (its
    evaluations ``firsts[i] ..`` for the keys); ``compiled()`` once the
    first fused call is compiled, before it runs (``Objective``)."""
    out: list = [None] * len(problems)
    for members, rows, n_max, q in self._groups(problems, us):
      chunks = []
      for lo in range(0, n_max, q):
        chunks.append(self._call(
          problems, us, firsts, rows, lo, q, frames, positions, compiled=compiled
        ))  # fmt: skip
        compiled = None  # the first fused call's alone
      for r, i in enumerate(members):
        n = len(us[i])
        psd, valid, pos, res = (
          self._joined(chunks, name, r, n)
          for name in ('psd', 'valid', 'positions', 'residual')
        )
        out[i] = obj_lib.Scores(
          psd, valid, self._best_frames(chunks, r, psd, q), pos, res
        )
    return out

  def compile(self, problems, sizes, *, frames: bool = False,
              positions: bool = False) -> None:  # fmt: skip
    """Compiles the programs that scoring ``sizes[i]`` candidates of each
    problem runs, without running them (``Objective.compile``): the
    candidates are taken distinct, as a search's proposals are, so a call
    whose worlds repeat (searches sharing an initial design) compiles another
    program. A lockstep driver calls it in a thread while the design runs;
    its steps then find their program compiled."""
    rng = np.random.default_rng(0)
    us = [rng.uniform(-1.0, 1.0, (n, 3)) for n in sizes]
    for _, rows, _, q in self._groups(problems, us):
      self._call(problems, us, [0] * len(problems), rows, 0, q, frames, positions,
                 compile_only=True)  # fmt: skip

  def _groups(self, problems, us):
    """The fused calls' groups: per structure, its members, their rows
    (padded), the most candidates of a member and the candidates a call."""
    groups: dict[tuple, list[int]] = {}
    for i, p in enumerate(problems):
      if len(us[i]):
        groups.setdefault(p.structure(), []).append(i)
    for members in groups.values():
      rows = members + [members[0]] * (_pad(len(members)) - len(members))
      n_max = max(len(us[i]) for i in members)
      q = _call_size([problems[i].config for i in members], n_max, len(rows))
      yield members, rows, n_max, q

  def _call(self, problems, us, firsts, rows, lo, q, frames, positions,
            compile_only=False, compiled=None):  # fmt: skip
    """One fused call: candidates ``lo .. lo + q - 1`` of each row's problem
    (a row with fewer repeats its first); ``compile_only``: compiled, not run."""
    part = []
    for i in rows:
      u = us[i][lo : lo + q]
      if not len(u):
        u = us[i][:1]
      part.append(np.concatenate([u, np.repeat(u[:1], q - len(u), 0)]))
    with physsim.devices.on_host():  # small: the call places them
      keys = [
        obj_lib.candidate_keys(problems[i].config, firsts[i] + lo, q) for i in rows
      ]
      gust = jax.numpy.stack([k[0] for k in keys])
      noise = jax.numpy.stack([k[1] for k in keys])
      data = obj_lib.stack([problems[i].data for i in rows])
    objective = self.objective(problems[rows[0]])
    if compile_only:
      objective.compile(
        data, np.stack(part), gust, noise, frames=frames, positions=positions
      )
      return None
    t0 = time.perf_counter()
    s = objective(
      data, np.stack(part), gust, noise, frames=frames, positions=positions,
      compiled=compiled,
    )  # fmt: skip
    self.seconds += time.perf_counter() - t0
    return s

  @staticmethod
  def _joined(chunks, name: str, r: int, n: int):
    """Row ``r``'s ``name`` over the calls, its first ``n`` candidates."""
    if getattr(chunks[0], name) is None:
      return None
    return np.concatenate([getattr(c, name)[r] for c in chunks])[:n]

  @staticmethod
  def _best_frames(chunks, r: int, psd: np.ndarray, q: int):
    """Row ``r``'s lowest-PSD candidate's frames: those of the call it was in."""
    if chunks[0].frames is None:
      return None
    if len(chunks) == 1 or not np.isfinite(psd).any():
      return chunks[0].frames[r]
    return chunks[int(np.nanargmin(psd)) // q].frames[r]


def score(problem: obj_lib.Problem, u, *, evaluator: Evaluator | None = None,
          first: int = 0, **outputs) -> obj_lib.Scores:  # fmt: skip
  """Scores unit-cube points ``u (n, 3)`` of one problem in one fused call
  (on MuJoCo C, calls of its search's ``q``: ``Evaluator``; evaluations
  ``first ..`` for the keys); pass one ``evaluator`` to calls of
  one structure so that they share its compile. ``outputs``: ``frames`` or
  ``positions`` (see ``Objective``)."""
  evaluator = evaluator or Evaluator()
  return evaluator([problem], [np.asarray(u, np.float64)], [first], **outputs)[0]


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
  evaluator: Evaluator | None = None,
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
  lock = _Lockstep(jobs, write, progress, gp_on_cpu, evaluator or Evaluator())
  lock.start(nets)
  # Searches that finished before: their result stands (run.json matched).
  ended = [s for s in lock.live if s.done()]
  for s in ended:
    path = os.path.join(lock.jobs[s.index].workdir, layout.ESTIMATE_FILE)
    if os.path.isfile(path):
      lock.out[s.index] = read_json(path)
  lock.finish([s for s in ended if lock.out[s.index] is None])
  while active := [s for s in lock.live if not s.done()]:
    lock.step(active)
  return lock.out


@dataclasses.dataclass
class _Lockstep:
  """``run``'s searches as they advance together, and what they have cost.

  The searches' GP steps run as one program per setting (bo.batched), their
  rows stacked over the recordings and spread over the host's CPU devices
  (one per core: cli.host_devices) or the local GPUs. The batch keeps its
  first size (on CPUs the rows of searches that finished are skipped), so
  the program compiles once.
  """

  jobs: list[Job]
  write: Callable[..., dict]
  progress: bool
  gp_on_cpu: bool
  evaluate: Evaluator
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
        check_run(job, problem)
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
        and _pad(len(active)) == self.last_rows,
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
    self.last_rows = _pad(len(active))

  def _warm_up(self, active, asked) -> tuple[list, Callable | None]:
    """On the first step off MuJoCo C: while the design's simulations run, the
    next step's GP program is traced and, in a lockstep, its fused program
    compiled (searches that share their design simulate it as a program of
    its own: distinct_worlds). The latter starts once the design's own
    program is compiled: two traces at once share Python's lock, and the
    design's is waited for. Returns the threads and the compile hook."""
    warm, compiled = [], None
    if self.steps == 0 and not _on_mujoco_c([s.problem.config for s in active]):
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


def describe_best(x_best, y_best, space) -> str:
  """A minimiser's progress line's worth: the best PSD and its parameters."""
  if not np.isfinite(y_best):
    return 'every simulation so far blew up'
  p = physsim.from_unit(x_best, space)
  return (
    f'best PSD {y_best:.4g} at bending x{float(p.bending_scale):.3g}, wind '
    f'{float(p.wind_speed):.2f} m/s, area weight {float(p.area_weight):.3f} kg/m^2'
  )
