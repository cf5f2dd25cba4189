"""Benchmark: the JAX GP optimiser (``bo.minimize``) against BoTorch.

Runs both optimisers side by side in one process on the same initial designs
and reports the final simple regret (median and interquartile range over
seeds) and the median wall time per iteration, excluding the objective.

  python -m benchmarks.bo_vs_botorch --seeds=10 --out=/tmp/bo_vs_botorch.json

BoTorch (and torch) are benchmark-only dependencies; without them only the
JAX optimiser runs. Both libraries are limited to one CPU thread so that the
comparison is per core and does not depend on how busy the machine is.
"""

import os

os.environ.setdefault(
  'XLA_FLAGS',
  '--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1',
)

import dataclasses  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import bo  # noqa: E402
from experiments.pipeline import cli, files  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Args:
  """The JAX optimiser against BoTorch.

  Attributes:
    seeds: number of seeds per problem.
    problems: problems to run (branin, hartmann6, fabric3).
    out: JSON output path (rewritten after each problem).
    skip_botorch: run only the JAX side.
    acquisition: JAX acquisition ('logei' or 'ucb').
    kernel: JAX kernel ('matern52' or 'rbf').
  """

  seeds: int = 10
  problems: tuple[str, ...] = ('branin', 'hartmann6', 'fabric3')
  out: str = 'out/benchmarks/bo_vs_botorch.json'
  skip_botorch: bool = False
  acquisition: str = cli.choice('logei', ['logei', 'ucb'])
  kernel: str = cli.choice('matern52', ['matern52', 'rbf'])


PRESETS = {
  'default': Args(),
  'smoke': Args(seeds=1, problems=('branin',), skip_botorch=True),
}

# ---- problems ----


def branin(x):
  x1, x2 = x[:, 0], x[:, 1]
  b, c, t = 5.1 / (4 * np.pi**2), 5 / np.pi, 1 / (8 * np.pi)
  return (x2 - b * x1**2 + c * x1 - 6) ** 2 + 10 * (1 - t) * np.cos(x1) + 10


_H_A = np.array(
  [
    [10, 3, 17, 3.5, 1.7, 8],
    [0.05, 10, 17, 0.1, 8, 14],
    [3, 3.5, 1.7, 10, 17, 8],
    [17, 8, 0.05, 10, 0.1, 14],
  ]
)
_H_P = 1e-4 * np.array(
  [
    [1312, 1696, 5569, 124, 8283, 5886],
    [2329, 4135, 8307, 3736, 1004, 9991],
    [2348, 1451, 3522, 2883, 3047, 6650],
    [4047, 8828, 8732, 5743, 1091, 381],
  ]
)
_H_ALPHA = np.array([1.0, 1.2, 3.0, 3.2])


def hartmann6(x):
  inner = np.sum(_H_A[None] * (x[:, None, :] - _H_P[None]) ** 2, axis=-1)
  return -np.sum(_H_ALPHA * np.exp(-inner), axis=-1)


# Fabric-like 3-D search: log10 bending stiffness, log10 area weight (both
# relative to a nominal fabric) and wind speed (m/s). Drape depends mostly on
# the stiffness-to-weight ratio, so the loss has a long, narrow valley along
# stiffness = weight, a weaker weight term, and a mildly rippled wind term,
# like an embedding distance between simulated and real depth videos.
_FABRIC_OPT = np.array([0.6, -0.35, 2.2])


def fabric3(x):
  d = x - _FABRIC_OPT
  ratio = d[:, 0] - d[:, 1]
  q = 4.0 * ratio**2 + 0.3 * d[:, 1] ** 2 + 0.5 * d[:, 2] ** 2
  ripple = 0.05 * np.sin(2.5 * d[:, 2]) ** 2
  return np.sqrt(q + 1e-3) - np.sqrt(1e-3) + ripple


PROBLEMS = {
  # name: (fun, bounds, optimum, n_init, n_iter, x0)
  'branin': (branin, [[-5.0, 10.0], [0.0, 15.0]], 0.397887357729739, 5, 25, None),
  'hartmann6': (hartmann6, [[0.0, 1.0]] * 6, -3.32236801141551, 10, 50, None),
  # Like the paper: the first point is the centre (all zeros in normalised
  # coordinates).
  'fabric3': (fabric3, [[-2.0, 2.0], [-1.0, 1.0], [0.0, 4.0]], 0.0, 5, 25, 'centre'),
}


def _initial_design(bounds, n_init, x0, seed):
  """The design ``bo.minimize`` uses, rebuilt so BoTorch starts identically."""
  lo, hi = bounds[:, 0], bounds[:, 1]
  starts = np.zeros((0, bounds.shape[0])) if x0 is None else np.atleast_2d(x0)
  u = bo.qmc.halton(n_init - starts.shape[0], bounds.shape[0], seed=seed)
  return np.concatenate([starts, lo + u * (hi - lo)])


# ---- runners ----


def run_jax(args: Args, fun, bounds, n_init, n_iter, x0, seed):
  secs = []
  res = bo.minimize(
    fun,
    bounds,
    n_init=n_init,
    n_iter=n_iter,
    x0=x0,
    seed=seed,
    acquisition=args.acquisition,
    kernel=args.kernel,
    callback=lambda info: secs.append(info.seconds),
  )
  return res.y_best, secs


def run_botorch(fun, bounds, n_init, n_iter, x0, seed):
  import torch
  from botorch.acquisition import LogExpectedImprovement
  from botorch.fit import fit_gpytorch_mll
  from botorch.models import SingleTaskGP
  from botorch.models.transforms import Normalize, Standardize
  from botorch.optim import optimize_acqf
  from gpytorch.mlls import ExactMarginalLogLikelihood

  torch.manual_seed(seed)
  dt = torch.float64
  d = bounds.shape[0]
  tb = torch.tensor(bounds.T, dtype=dt)
  X = torch.tensor(_initial_design(bounds, n_init, x0, seed), dtype=dt)
  Y = -torch.tensor(fun(X.numpy()), dtype=dt)[:, None]  # BoTorch maximises.
  secs = []
  for _ in range(n_iter):
    t0 = time.perf_counter()
    model = SingleTaskGP(
      X,
      Y,
      input_transform=Normalize(d=d, bounds=tb),
      outcome_transform=Standardize(m=1),
    )
    fit_gpytorch_mll(ExactMarginalLogLikelihood(model.likelihood, model))
    acq = LogExpectedImprovement(model, best_f=Y.max())
    cand, _ = optimize_acqf(acq, bounds=tb, q=1, num_restarts=10, raw_samples=512)
    secs.append(time.perf_counter() - t0)
    y = -torch.tensor(fun(cand.detach().numpy()), dtype=dt)[:, None]
    X, Y = torch.cat([X, cand.detach()]), torch.cat([Y, y])
  return float(-Y.max()), secs


def _summary(regrets, secs):
  r = np.asarray(regrets)
  return dict(
    regret_median=float(np.median(r)),
    regret_q25=float(np.percentile(r, 25)),
    regret_q75=float(np.percentile(r, 75)),
    sec_per_iter_median=float(np.median(secs)) if secs else float('nan'),
    regrets=r.tolist(),
  )


def main(args: Args) -> None:
  unknown = sorted(set(args.problems) - set(PROBLEMS))
  if unknown or not args.problems:
    raise ValueError(f'unknown --problems {unknown}; known: {list(PROBLEMS)}')
  have_botorch = not args.skip_botorch
  if have_botorch:
    try:
      import botorch  # noqa: F401
      import torch

      torch.set_num_threads(1)
    except ImportError:
      print('BoTorch not installed: running the JAX optimiser only.')
      print('  pip install torch==2.13.0 botorch   # benchmark-only')
      have_botorch = False
  out = {'machine': os.uname().nodename, 'cpu_threads': 1, 'problems': {}}
  rows = []
  for name in args.problems:
    fun, bounds, opt, n_init, n_iter, x0 = PROBLEMS[name]
    bounds = np.asarray(bounds)
    if isinstance(x0, str):
      x0 = bounds.mean(axis=1)
    entry = {'n_init': n_init, 'n_iter': n_iter}
    jr, js, compile_s = [], [], None
    br, bs = [], []
    for seed in range(args.seeds):
      y, secs = run_jax(args, fun, bounds, n_init, n_iter, x0, seed)
      if compile_s is None:
        compile_s, secs = secs[0], secs[1:]
      jr.append(y - opt)
      js.extend(secs)
      line = f'{name} seed {seed}: jax regret {y - opt:.3g}'
      if have_botorch:
        y, secs = run_botorch(fun, bounds, n_init, n_iter, x0, seed)
        br.append(y - opt)
        bs.extend(secs)
        line += f', botorch regret {y - opt:.3g}'
      print(line, flush=True)
    entry['jax'] = _summary(jr, js)
    entry['jax']['first_iter_compile_s'] = compile_s
    if have_botorch:
      entry['botorch'] = _summary(br, bs)
    out['problems'][name] = entry
    for lib in ('jax', 'botorch') if have_botorch else ('jax',):
      e = entry[lib]
      rows.append(
        f'| {name} ({n_init}+{n_iter}) | {lib} | {e["regret_median"]:.3g} | '
        f'[{e["regret_q25"]:.3g}, {e["regret_q75"]:.3g}] | '
        f'{e["sec_per_iter_median"]:.3f} |'
      )
    files.write_json(args.out, out)  # after each problem: a partial run is kept
  print(f'\n{args.seeds} seeds each; regret = best observed - optimum.\n')
  print('| problem (init+iters) | optimiser | median regret | IQR | s/iter |')
  print('|---|---|---|---|---|')
  print('\n'.join(rows))
  for name, e in out['problems'].items():
    print(
      f'{name}: JAX first-iteration compile {e["jax"]["first_iter_compile_s"]:.1f} s'
    )
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
