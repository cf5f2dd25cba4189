"""One Bayesian-optimisation step: fit the GP, then propose a batch of points.

``make_propose(config)`` is a factory in the optax style: it closes over the
static configuration and returns a pure, jit-compiled function of the padded
data buffers. The buffers have a fixed capacity, so the function compiles once
per capacity rather than once per data-set size.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from bo import acquisition, gp, qmc


class ProposeConfig(NamedTuple):
  """Static settings of a proposal step (hashable, so usable as a cache key).

  Attributes:
    d: input dimension.
    q: batch size (Kriging believer for ``q > 1``).
    acquisition: ``'logei'`` or ``'ucb'``.
    beta: UCB exploration weight.
    kernel: ``'matern52'`` or ``'rbf'``.
    fit_restarts: L-BFGS-B starts for the hyperparameters.
    fit_maxiter: L-BFGS-B iterations per hyperparameter start.
    acq_restarts: L-BFGS-B starts for the acquisition.
    acq_maxiter: L-BFGS-B iterations per acquisition start.
    raw_samples: quasi-random raw candidates per acquisition optimisation.
    n_best: incumbents used as extra raw candidates (and perturbed).
  """

  d: int
  q: int = 1
  acquisition: str = 'logei'
  beta: float = 0.1
  kernel: str = 'matern52'
  fit_restarts: int = 4
  fit_maxiter: int = 50
  acq_restarts: int = 10
  acq_maxiter: int = 100
  raw_samples: int = 512
  n_best: int = 5


class Proposal(NamedTuple):
  """Result of one step.

  Attributes:
    x: proposed points in ``[-1, 1]^d``, ``(q, d)``.
    acq_value: acquisition value of each point when chosen ``(q,)``.
    params: fitted GP hyperparameters (warm start for the next step).
  """

  x: jnp.ndarray
  acq_value: jnp.ndarray
  params: gp.GPParams


def _acq_fn(config: ProposeConfig, state: gp.GPState, best_f):
  def acq(xq):
    mean, var = gp.posterior(state, xq, kernel=config.kernel)
    if config.acquisition == 'logei':
      return acquisition.log_ei(mean, var, best_f)
    return acquisition.ucb(mean, var, config.beta)

  return acq


def make_propose(config: ProposeConfig):
  """Builds the jitted proposal function for ``config``.

  Args:
    config: static settings.

  Returns:
    ``propose(x, y, mask, n_filled, key, init_params) -> Proposal`` where
    ``x`` is ``(cap, d)`` in ``[-1, 1]^d``, ``y`` is ``(cap,)`` raw values,
    ``mask`` marks valid rows, ``n_filled`` is the number of rows in use
    (valid or failed; the batch is fantasised into rows ``n_filled`` to
    ``n_filled + q - 1``, which must fit in the buffer), and ``init_params``
    warm-starts the hyperparameter fit.
  """
  if config.acquisition not in ('logei', 'ucb'):
    raise ValueError(f'Unknown acquisition {config.acquisition!r}.')
  raw_base = qmc.halton(config.raw_samples, config.d, seed=12345)

  def propose(x, y, mask, n_filled, key, init_params) -> Proposal:
    k_fit, k_acq = jax.random.split(key)
    state = gp.fit(
      x,
      y,
      mask,
      k_fit,
      kernel=config.kernel,
      n_restarts=config.fit_restarts,
      maxiter=config.fit_maxiter,
      init_params=init_params,
    )
    y_valid = jnp.where(mask, y, jnp.inf)
    best_f = jnp.min(y_valid)
    n_best = min(config.n_best, x.shape[0])
    _, best_idx = jax.lax.top_k(-y_valid, n_best)
    x_best = x[best_idx]
    base = jnp.asarray(raw_base, x.dtype)

    def body(carry, j):
      xb, yb, mb, st = carry
      acq = _acq_fn(config, st, best_f)
      xj, vj = acquisition.optimize(
        acq,
        jax.random.fold_in(k_acq, j),
        base,
        x_best,
        n_restarts=config.acq_restarts,
        maxiter=config.acq_maxiter,
      )
      # Kriging believer: pretend the posterior mean was observed at xj.
      mean, _ = gp.posterior(st, xj[None], kernel=config.kernel)
      i = n_filled + j
      xb = xb.at[i].set(xj)
      yb = yb.at[i].set(mean[0])
      mb = mb.at[i].set(True)
      st = gp.condition(st.params, xb, yb, mb, kernel=config.kernel)
      return (xb, yb, mb, st), (xj, vj)

    if config.q == 1:
      _, (xs, vs) = body((x, y, mask, state), 0)
      xs, vs = xs[None], vs[None]
    else:
      _, (xs, vs) = jax.lax.scan(body, (x, y, mask, state), jnp.arange(config.q))
    return Proposal(xs, vs, state.params)

  return jax.jit(propose)


@functools.lru_cache(maxsize=32)
def cached_propose(config: ProposeConfig):
  """``make_propose`` memoised per config, so repeated runs reuse compiles."""
  return make_propose(config)
