"""The optimisation loop: ``minimize``, its stopping rule and save/resume."""

import dataclasses
import functools
import json
import os
import tempfile
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from bo import batched, gp, propose, qmc

_MIN_CAPACITY = 16


class Result(NamedTuple):
  """Outcome of ``minimize``.

  Attributes:
    x_best: best point found, original units ``(d,)`` (NaN if all failed).
    y_best: its value ``()`` (``inf`` if every evaluation failed).
    X: every evaluated point in order ``(n_evals, d)``.
    Y: every value ``(n_evals,)``; failures are NaN.
    n_evals: number of evaluations.
    n_iter: number of BO iterations run (after the initial design).
    stopped_early: whether the stopping rule or the callback ended the run.
  """

  x_best: np.ndarray
  y_best: float
  X: np.ndarray
  Y: np.ndarray
  n_evals: int
  n_iter: int = 0
  stopped_early: bool = False


@dataclasses.dataclass(frozen=True)
class IterationInfo:
  """What the callback sees after each BO iteration.

  Attributes:
    iteration: index of the iteration just finished (0-based).
    X_new: points evaluated in it ``(q, d)``.
    Y_new: their values ``(q,)`` (NaN for failures).
    x_best: best point so far ``(d,)``.
    y_best: best value so far.
    seconds: wall time of the proposal step (excludes the objective).
  """

  iteration: int
  X_new: np.ndarray
  Y_new: np.ndarray
  x_best: np.ndarray
  y_best: float
  seconds: float


def _capacity(n: int) -> int:
  """Smallest power of two >= n (and >= _MIN_CAPACITY)."""
  return max(_MIN_CAPACITY, 1 << max(0, int(np.ceil(np.log2(max(n, 1))))))


def _best(X, Y):
  finite = np.isfinite(Y)
  if not finite.any():
    return np.full(X.shape[1], np.nan), float('inf')
  i = int(np.argmin(np.where(finite, Y, np.inf)))
  return X[i].copy(), float(Y[i])


def _evaluate(fun, x):
  y = np.asarray(fun(x), dtype=np.float64).reshape(-1)
  if y.shape[0] != x.shape[0]:
    raise ValueError(f'fun returned {y.shape[0]} values for {x.shape[0]} points.')
  return np.where(np.isfinite(y), y, np.nan)


def _stop_rule(history: list[np.ndarray], width: np.ndarray, rel: float, window: int):
  """Paper's rule: the incumbent moved < ``rel`` (per dimension, relative to
  the search-range width) between each of the last ``window`` iterations and
  the current one."""
  if len(history) <= window:
    return False
  cur = history[-1]
  if not np.all(np.isfinite(cur)):
    return False
  past = np.stack(history[-window - 1 : -1])
  return bool(np.all(np.abs(past - cur) / width < rel))


def _save(path: str, payload: dict[str, Any]):
  """Writes the state atomically: a temporary file, then ``os.replace``."""
  directory = os.path.dirname(os.path.abspath(path)) or '.'
  os.makedirs(directory, exist_ok=True)
  fd, tmp = tempfile.mkstemp(dir=directory, suffix='.tmp.npz')
  try:
    with os.fdopen(fd, 'wb') as f:
      np.savez(f, **payload)
    umask = os.umask(0)  # mkstemp's 0600 -> the user's usual mode
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, path)
  except BaseException:
    if os.path.exists(tmp):
      os.remove(tmp)
    raise


def _load(path: str) -> dict[str, Any]:
  with np.load(path, allow_pickle=False) as z:
    return {k: z[k] for k in z.files}


@functools.lru_cache(maxsize=32)
def _propose_row(config: propose.ProposeConfig):
  """One search's proposal as a ``bo.batched`` row function: the warm start
  and the fitted hyperparameters as flat arrays."""
  step = propose.cached_propose(config)

  def row(x, y, mask, n_filled, key, init):
    out = step(x, y, mask, n_filled, key, gp.params_from_array(init))
    return out._replace(params=gp.params_to_array(out.params))

  return row


class State(NamedTuple):
  """Where one search stands (host arrays; ``Minimizer`` reads and returns it).

  Attributes:
    X: evaluated points, original units ``(n, d)``.
    Y: their values ``(n,)``, NaN for failures.
    iteration: BO iterations finished (0 until the initial design is told).
    history: the incumbent after each iteration ``(iteration, d)``.
    params: last fitted GP hyperparameters (flat) or None (warm start).
    stopped: the stopping rule (or a callback, through ``stop``) ended it.
  """

  X: np.ndarray
  Y: np.ndarray
  iteration: int = 0
  history: np.ndarray | None = None
  params: np.ndarray | None = None
  stopped: bool = False


class Minimizer:
  """``minimize``'s loop one step at a time: ``ask`` for points, ``tell`` values.

  A driver that runs many searches at once (one per recording, say) asks each
  for its points, evaluates all of them in one batch and tells each its
  values; every search then goes exactly as ``minimize`` would have run it.
  The arguments are ``minimize``'s (see there) but for ``fun`` and
  ``callback``. ``device`` places the GP fit and proposal (default: JAX's
  default device); its float64 arithmetic runs under ``jax.enable_x64``
  inside ``ask`` only, so the caller's objective keeps its own precision.
  """

  def __init__(
    self,
    bounds,
    *,
    n_init: int,
    n_iter: int,
    q: int = 1,
    x0=None,
    seed: int = 0,
    acquisition: str = 'logei',
    beta: float = 0.1,
    kernel: str = 'matern52',
    stop_rel_change: float | None = None,
    stop_window: int = 3,
    stop_min_iter: int = 0,
    state_path: str | None = None,
    config_overrides: dict[str, Any] | None = None,
    device=None,
  ):
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.ndim != 2 or bounds.shape[1] != 2:
      raise ValueError(f'bounds must have shape (d, 2), got {bounds.shape}.')
    if not np.all(bounds[:, 1] > bounds[:, 0]):
      raise ValueError('bounds need lower < upper in every dimension.')
    if n_init < 1 or n_iter < 0 or q < 1:
      raise ValueError('Need n_init >= 1, n_iter >= 0 and q >= 1.')
    self.bounds = bounds
    self.d = bounds.shape[0]
    self.lo, self.hi = bounds[:, 0], bounds[:, 1]
    self.width = self.hi - self.lo
    self.n_init, self.n_iter, self.q = n_init, n_iter, q
    self.seed = seed
    self.stop_rel_change, self.stop_window = stop_rel_change, stop_window
    self.stop_min_iter = stop_min_iter
    self.state_path = state_path
    self.device = device
    self.x0 = None
    if x0 is not None:
      self.x0 = np.atleast_2d(np.asarray(x0, dtype=np.float64))
      if self.x0.shape[1] != self.d:
        raise ValueError(f'x0 must have {self.d} columns, got {self.x0.shape}.')
    config = propose.ProposeConfig(
      d=self.d, q=q, acquisition=acquisition, beta=beta, kernel=kernel,
      **(config_overrides or {}),
    )  # fmt: skip
    self.signature = json.dumps(
      dict(config._asdict(), bounds=bounds.tolist(), n_init=n_init, seed=seed)
    )
    self._key = jax.random.PRNGKey(seed)
    self._config = config
    propose.cached_propose(config)  # Validates before any eval.

  def _to_unit(self, x):
    return 2.0 * (x - self.lo) / self.width - 1.0

  def _from_unit(self, u):
    return self.lo + (np.clip(u, -1.0, 1.0) + 1.0) * 0.5 * self.width

  def start(self) -> State:
    """A fresh state, or the one saved at ``state_path`` (resume)."""
    empty = State(np.zeros((0, self.d)), np.zeros((0,)), 0, np.zeros((0, self.d)))
    if self.state_path is None or not os.path.exists(self.state_path):
      return empty
    s = _load(self.state_path)
    if str(s['signature']) != self.signature:
      raise ValueError(f'{self.state_path} was written by a run with other settings.')
    state = State(
      s['X'], s['Y'], int(s['iteration']), s['history'].reshape(-1, self.d),
      s['params'] if s['params'].size else None,
    )  # fmt: skip
    # A run saved after the iteration in which the rule fired has finished.
    return state._replace(stopped=self._rule(state))

  def done(self, state: State) -> bool:
    """The initial design is told and the budget or the stopping rule is spent."""
    return state.X.shape[0] > 0 and (state.stopped or state.iteration >= self.n_iter)

  def ask(self, state: State) -> tuple[np.ndarray, State]:
    """The next points to evaluate, original units: the initial design while
    nothing is told, then ``q`` proposals. Returns them and the state with the
    refitted GP hyperparameters (pass that state to ``tell``). The batch of
    one of ``bo.batched.ask_many``, which asks many searches at once."""
    return batched.ask_many([self], [state])[0]

  def ask_plan(self, state: State) -> batched.Ready | batched.Call:
    """``ask`` as a ``bo.batched`` step: the answer, or the GP row to run."""
    if self.done(state):
      raise ValueError('ask() after the search has finished.')
    n, d, q = state.X.shape[0], self.d, self.q
    if n == 0:
      starts = np.zeros((0, d)) if self.x0 is None else self.x0[: self.n_init]
      n_rand = self.n_init - starts.shape[0]
      design = self._from_unit(2.0 * qmc.halton(n_rand, d, seed=self.seed) - 1.0)
      return batched.Ready((np.concatenate([starts, design]), state))
    # Buffers grow in powers of two: O(log n) compiles in all, none while the
    # data fit the current buffer.
    cap = _capacity(n + q)
    mask = np.zeros(cap, bool)
    mask[:n] = np.isfinite(state.Y)
    if not mask.any():
      u = 2.0 * qmc.halton(q, d, seed=self.seed, skip=n) - 1.0
      return batched.Ready((self._from_unit(u), state))
    xb = np.zeros((cap, d))
    xb[:n] = self._to_unit(state.X)
    yb = np.zeros(cap)
    yb[:n] = np.where(mask[:n], state.Y, 0.0)
    with jax.enable_x64(True):
      if state.params is None:
        init = np.asarray(gp.params_to_array(gp.default_params(d, jnp.float64)))
      else:
        init = np.asarray(state.params, np.float64)
      key = np.asarray(jax.random.fold_in(self._key, state.iteration))

    def finish(out):
      return self._from_unit(np.asarray(out.x)), state._replace(
        params=np.asarray(out.params)
      )

    args = (xb, yb, mask, np.int32(n), key, init)
    return batched.Call(_propose_row(self._config), args, finish)

  def result_plan(self, state: State) -> batched.Ready:
    """``result`` as a ``bo.batched`` step (no GP: the answer)."""
    return batched.Ready(self.result(state))

  def tell(self, state: State, x, y) -> State:
    """Records the values ``y`` of the asked points ``x`` (non-finite: a
    failure), saves the state and applies the stopping rule."""
    x = np.asarray(x, dtype=np.float64).reshape(-1, self.d)
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    if y.shape[0] != x.shape[0]:
      raise ValueError(f'{y.shape[0]} values for {x.shape[0]} points.')
    y = np.where(np.isfinite(y), y, np.nan)
    first = state.X.shape[0] == 0
    state = state._replace(
      X=np.concatenate([state.X, x]), Y=np.concatenate([state.Y, y])
    )
    if not first:
      x_best, _ = _best(state.X, state.Y)
      state = state._replace(
        iteration=state.iteration + 1,
        history=np.concatenate([state.history, x_best[None]]),
      )
    self._save(state)
    return state._replace(stopped=state.stopped or (not first and self._rule(state)))

  def stop(self, state: State) -> State:
    """Ends the search (a callback asked to); not saved, as in ``minimize``."""
    return state._replace(stopped=True)

  def result(self, state: State) -> Result:
    x_best, y_best = _best(state.X, state.Y)
    return Result(
      x_best, y_best, state.X, state.Y, state.X.shape[0], state.iteration, state.stopped
    )

  def _rule(self, state: State) -> bool:
    return (
      self.stop_rel_change is not None
      and state.iteration >= self.stop_min_iter
      and _stop_rule(
        list(state.history), self.width, self.stop_rel_change, self.stop_window
      )
    )

  def _save(self, state: State):
    if self.state_path is None:
      return
    _save(
      self.state_path,
      dict(
        X=state.X, Y=state.Y, iteration=np.int64(state.iteration),
        signature=np.array(self.signature),
        history=np.asarray(state.history).reshape(-1, self.d),
        params=np.zeros(0) if state.params is None else np.asarray(state.params),
      ),
    )  # fmt: skip


def minimize(
  fun: Callable[[np.ndarray], Any],
  bounds,
  *,
  n_init: int,
  n_iter: int,
  q: int = 1,
  x0=None,
  seed: int = 0,
  acquisition: str = 'logei',
  callback: Callable[[IterationInfo], bool | None] | None = None,
  beta: float = 0.1,
  kernel: str = 'matern52',
  stop_rel_change: float | None = None,
  stop_window: int = 3,
  stop_min_iter: int = 0,
  state_path: str | None = None,
  config_overrides: dict[str, Any] | None = None,
  device=None,
) -> Result:
  """Minimises ``fun`` over a box with GP Bayesian optimisation.

  The box is mapped to ``[-1, 1]^d``; ``fun`` always sees original units.
  ``x0`` rows are evaluated first and count towards ``n_init``; the rest of
  the initial design is a scrambled Halton set. Each iteration fits the GP
  (float64) and proposes ``q`` points that ``fun`` evaluates in one call.
  Non-finite values are recorded as failures (NaN in ``Y``) and left out of
  the GP; if every value so far failed, the next batch is quasi-random.

  Args:
    fun: maps ``(n, d)`` points to ``(n,)`` values (NumPy or JAX).
    bounds: ``(d, 2)`` lower and upper bounds.
    n_init: size of the initial design (including ``x0``).
    n_iter: number of BO iterations, each evaluating ``q`` points.
    q: batch size per iteration.
    x0: optional ``(d,)`` or ``(m, d)`` points evaluated first.
    seed: seed for the design and all randomness (iteration ``t`` uses
      ``fold_in(key, t)``, so a resumed run draws the same keys).
    acquisition: ``'logei'`` (default) or ``'ucb'``.
    callback: called after each iteration with an ``IterationInfo``;
      returning True stops the run.
    beta: UCB weight (the paper's 0.1).
    kernel: ``'matern52'`` (default) or ``'rbf'``.
    stop_rel_change: if set, stop once the best point has moved less than
      this fraction of each dimension's range (``hi - lo``) over the last
      ``stop_window`` iterations (the paper: 0.1 over 3).
    stop_window: iterations in the stopping rule.
    stop_min_iter: the rule is not checked before this many iterations (a
      large initial design often holds the best point for a while).
    state_path: if set, the full state is written here (npz, atomically)
      after the initial design and after every iteration, and an existing
      file is resumed from; a resumed run ends as an uninterrupted one would.
    config_overrides: optional ``ProposeConfig`` fields (restarts, iterations).
    device: where the GP runs (default: JAX's default device).

  Returns:
    A ``Result``.
  """
  opt = Minimizer(
    bounds, n_init=n_init, n_iter=n_iter, q=q, x0=x0, seed=seed,
    acquisition=acquisition, beta=beta, kernel=kernel,
    stop_rel_change=stop_rel_change, stop_window=stop_window,
    stop_min_iter=stop_min_iter, state_path=state_path,
    config_overrides=config_overrides, device=device,
  )  # fmt: skip
  state = opt.start()
  while not opt.done(state):
    t0 = time.perf_counter()
    x_new, state = opt.ask(state)
    seconds = time.perf_counter() - t0
    initial = state.X.shape[0] == 0
    state = opt.tell(state, x_new, _evaluate(fun, x_new))
    if callback is not None and not initial:
      x_best, y_best = _best(state.X, state.Y)
      info = IterationInfo(
        state.iteration - 1, x_new, state.Y[-len(x_new) :], x_best, y_best, seconds
      )
      if callback(info):
        state = opt.stop(state)
  return opt.result(state)
