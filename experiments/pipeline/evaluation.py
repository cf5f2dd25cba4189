"""Scoring many searches' candidates together: one fused objective call per problem structure.

``Evaluator`` holds one ``objective.Objective`` per ``Problem.structure`` and
scores the candidates of every problem of one structure in one call (MJX
costs about the same per step for 4 worlds as for ~64); ``score`` is one
problem's candidates alone. A candidate's score does not depend on which
call it was in (per-candidate keys), so a search scored with others goes as
it would alone.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import jax
import numpy as np

import physsim
from experiments.pipeline import objective as obj_lib


def padded_rows(n: int) -> int:
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


# On a GPU a fused call of up to this many worlds (rows x candidates) costs
# what one of 24 does: the simulation's steps wait on kernel launches, not on
# arithmetic (physsim.devices; such a call also runs on one device).
FLAT_WORLDS = physsim.devices.FLAT_WORLDS


def on_mujoco_c(configs) -> bool:
  """Whether every one of ``configs`` simulates on MuJoCo C, where a call's
  time grows with its worlds: a design is scored in calls of ``q``
  (``_call_size``) and the lockstep compiles nothing ahead in a thread."""
  return all(physsim.resolve_backend(c.hardware.backend) == 'c' for c in configs)


def _call_size(configs, n: int, rows: int = 1) -> int:
  """Candidates per fused call for ``n`` candidates of ``rows`` searches with
  ``configs`` (``Evaluator``): their ``q`` on MuJoCo C; elsewhere all ``n``,
  padded up to the searches' initial design where that keeps the call within
  ``FLAT_WORLDS`` worlds, so that a single estimate compiles one program
  shape for its design and its steps."""
  if on_mujoco_c(configs):
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
      rows = members + [members[0]] * (padded_rows(len(members)) - len(members))
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
        obj_lib.candidate_keys(
          problems[i].config.seed, problems[i].config.search, firsts[i] + lo, q
        )
        for i in rows
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
