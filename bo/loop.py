"""The optimisation loop: ``minimize``, its stopping rule and save/resume."""

import dataclasses
import json
import os
import tempfile
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from bo import gp, propose, qmc

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
    os.replace(tmp, path)
  except BaseException:
    if os.path.exists(tmp):
      os.remove(tmp)
    raise


def _load(path: str) -> dict[str, Any]:
  with np.load(path, allow_pickle=False) as z:
    return {k: z[k] for k in z.files}


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

  Returns:
    A ``Result``.
  """
  bounds = np.asarray(bounds, dtype=np.float64)
  if bounds.ndim != 2 or bounds.shape[1] != 2:
    raise ValueError(f'bounds must have shape (d, 2), got {bounds.shape}.')
  if not np.all(bounds[:, 1] > bounds[:, 0]):
    raise ValueError('bounds need lower < upper in every dimension.')
  if n_init < 1 or n_iter < 0 or q < 1:
    raise ValueError('Need n_init >= 1, n_iter >= 0 and q >= 1.')
  d = bounds.shape[0]
  lo, hi = bounds[:, 0], bounds[:, 1]
  width = hi - lo
  to_unit = lambda x: 2.0 * (x - lo) / width - 1.0
  from_unit = lambda u: lo + (np.clip(u, -1.0, 1.0) + 1.0) * 0.5 * width

  config = propose.ProposeConfig(
    d=d, q=q, acquisition=acquisition, beta=beta, kernel=kernel,
    **(config_overrides or {}),
  )  # fmt: skip
  signature = json.dumps(
    dict(config._asdict(), bounds=bounds.tolist(), n_init=n_init, seed=seed)
  )
  key = jax.random.PRNGKey(seed)
  step = propose.cached_propose(config)  # Validates the settings before any eval.

  # ---- state: resume or initial design ----
  X = np.zeros((0, d))
  Y = np.zeros((0,))
  it0 = 0
  history: list[np.ndarray] = []
  params_flat = None
  if state_path is not None and os.path.exists(state_path):
    s = _load(state_path)
    if str(s['signature']) != signature:
      raise ValueError(f'{state_path} was written by a run with other settings.')
    X, Y, it0 = s['X'], s['Y'], int(s['iteration'])
    history = list(s['history'])
    params_flat = s['params'] if s['params'].size else None

  def save(it):
    if state_path is None:
      return
    _save(
      state_path,
      dict(
        X=X, Y=Y, iteration=np.int64(it), signature=np.array(signature),
        history=np.array(history).reshape(-1, d),
        params=np.zeros(0) if params_flat is None else np.asarray(params_flat),
      ),
    )  # fmt: skip

  if X.shape[0] == 0:
    starts = np.zeros((0, d))
    if x0 is not None:
      starts = np.atleast_2d(np.asarray(x0, dtype=np.float64))
      if starts.shape[1] != d:
        raise ValueError(f'x0 must have {d} columns, got {starts.shape}.')
      starts = starts[:n_init]
    n_rand = n_init - starts.shape[0]
    design = from_unit(2.0 * qmc.halton(n_rand, d, seed=seed) - 1.0)
    X = np.concatenate([starts, design])
    Y = _evaluate(fun, X)
    save(0)

  # ---- BO iterations ----
  it = it0
  # A run saved after the iteration in which the rule fired has finished.
  stopped = (
    stop_rel_change is not None
    and it >= stop_min_iter
    and _stop_rule(history, width, stop_rel_change, stop_window)
  )
  with jax.enable_x64(True):
    while it < n_iter and not stopped:
      t0 = time.perf_counter()
      n = X.shape[0]
      # Buffers grow in powers of two: O(log n) compiles in all, none while
      # the data fit the current buffer.
      cap = _capacity(n + q)
      mask = np.zeros(cap, bool)
      mask[:n] = np.isfinite(Y)
      if not mask.any():
        u = 2.0 * qmc.halton(q, d, seed=seed, skip=n) - 1.0
      else:
        xb = np.zeros((cap, d))
        xb[:n] = to_unit(X)
        yb = np.zeros(cap)
        yb[:n] = np.where(mask[:n], Y, 0.0)
        if params_flat is None:
          init = gp.default_params(d, jnp.float64)
        else:
          init = gp.params_from_array(jnp.asarray(params_flat))
        out = step(
          jnp.asarray(xb), jnp.asarray(yb), jnp.asarray(mask), jnp.int32(n),
          jax.random.fold_in(key, it), init,
        )  # fmt: skip
        u = np.asarray(out.x)
        params_flat = np.asarray(gp.params_to_array(out.params))
      seconds = time.perf_counter() - t0
      x_new = from_unit(u)
      with jax.enable_x64(False):  # the objective runs in its own precision
        y_new = _evaluate(fun, x_new)
      X = np.concatenate([X, x_new])
      Y = np.concatenate([Y, y_new])
      x_best, y_best = _best(X, Y)
      history.append(x_best)
      it += 1
      save(it)
      if callback is not None:
        info = IterationInfo(it - 1, x_new, y_new, x_best, y_best, seconds)
        if callback(info):
          stopped = True
      if (
        stop_rel_change is not None
        and it >= stop_min_iter
        and _stop_rule(history, width, stop_rel_change, stop_window)
      ):
        stopped = True
  x_best, y_best = _best(X, Y)
  return Result(x_best, y_best, X, Y, X.shape[0], it, stopped)
