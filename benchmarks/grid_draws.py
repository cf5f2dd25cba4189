"""Posterior grid draws: the inverse CDF against the Gumbel trick, side by side.

Every step of a posterior search draws ``samples`` points from its grid
posterior, and every result draws the prior's as many (``bo.posterior.
sample_grid``). ``jax.random.categorical`` draws ``n`` cells by the Gumbel
trick, an (n, G) array: at the paper-size grid (12 x 64 x 24 = 18,432 cells)
and 4,096 draws, 75 million random numbers per draw. ``bo.posterior.
sample_cells`` inverts the cumulative mass instead (O(G + n log G)). This
script times both in float64 on this machine's default device, jitted, and one
whole search step (``bo.posterior.make_step``: GP fit, grid posterior, draws,
next batch) as ``bo.batched`` runs it for one search and for several, built
with each; and checks that both draw the same distribution.

  python -m benchmarks.grid_draws --out=$OUT/grid_draws.json
"""

from __future__ import annotations

import dataclasses
import functools
import time
from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np

import bo
from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The comparison.

  Attributes:
    grid: posterior grid cells per dimension (the estimate's default).
    samples: draws per call (the search's default).
    evaluations: points in the GP's data for the step (the initial design's).
    q: candidates per step.
    searches: how many searches step together (``bo.batched.ask_many``, as
      the estimate's lockstep runs them).
    repeats: timed calls of each (the table shows their median).
    out: JSON path.
  """

  grid: tuple[int, ...] = (12, 64, 24)
  samples: int = 4096
  evaluations: int = 48
  q: int = 24
  searches: tuple[int, ...] = (1, 8)
  repeats: int = 5
  out: str = 'out/benchmarks/grid_draws.json'


PRESETS = {
  'default': Args(),
  'smoke': Args(grid=(6, 16, 8), samples=512, searches=(1, 2), repeats=2),
}


def gumbel_cells(key, log_p, n: int) -> jax.Array:
  """The baseline: ``jax.random.categorical`` (the Gumbel trick)."""
  return jax.random.categorical(key, log_p, shape=(n,))


def _median_seconds(fn, repeats: int) -> tuple[float, float]:
  """(first call, median of ``repeats`` later calls), blocking on the result."""
  t = time.perf_counter()
  jax.block_until_ready(fn(0))
  first = time.perf_counter() - t
  times = []
  for i in range(repeats):
    t = time.perf_counter()
    jax.block_until_ready(fn(i + 1))
    times.append(time.perf_counter() - t)
  return first, float(np.median(times))


def _bowl(x: np.ndarray, seed: int) -> np.ndarray:
  """Noisy discrepancies of a bowl: what a search is told."""
  rng = np.random.default_rng(seed)
  return (np.sum((x - 0.2) ** 2, 1) + 0.05) * np.exp(0.1 * rng.standard_normal(len(x)))


def _searches(args: Args, n: int) -> list:
  """``n`` posterior searches after their initial design, as the estimate
  makes them (their GP step is one ``bo.batched`` row each)."""
  config = bo.posterior.PosteriorConfig(d=len(args.grid), grid=args.grid, q=args.q,
                                        samples=args.samples)  # fmt: skip
  out = []
  for i in range(n):
    search = bo.PosteriorSearch(config, n_init=args.evaluations, n_iter=3, seed=i)
    state = search.start()
    x, state = search.ask(state)  # the initial design: no GP
    out.append((search, search.tell(state, x, _bowl(x, i))))
  return out


def _ask(pairs, k: int):
  del k  # the same step each time: its own key
  return bo.batched.ask_many([p[0] for p in pairs], [p[1] for p in pairs])


def main(args: Args) -> None:
  g = int(np.prod(args.grid))
  rows = {}
  with jax.enable_x64(True):
    rng = np.random.default_rng(1)
    log_p = jnp.asarray(np.log(rng.random(g) ** 4 + 1e-12))
    for name, cells in (
      ('gumbel', gumbel_cells),
      ('inverse_cdf', bo.posterior.sample_cells),
    ):
      draw = jax.jit(lambda k, c=cells: c(jax.random.key(k), log_p, args.samples))
      first, med = _median_seconds(draw, args.repeats)
      freq = np.bincount(np.asarray(draw(99)), minlength=g) / args.samples
      rows[name] = {'draw_first_s': first, 'draw_s': med,
                    'total_variation': 0.5 * float(np.abs(freq - np.exp(log_p) /
                                                          np.exp(log_p).sum()).sum())}  # fmt: skip
      for fn in (bo.posterior.make_step, bo.posterior._step_row):
        fn.cache_clear()
      with mock.patch.object(bo.posterior, 'sample_cells', cells):
        for n in args.searches:
          first, med = _median_seconds(
            functools.partial(_ask, _searches(args, n)), args.repeats
          )
          rows[name][f'step_{n}_first_s'], rows[name][f'step_{n}_s'] = first, med
      for fn in (bo.posterior.make_step, bo.posterior._step_row):
        fn.cache_clear()
  base, new = rows['gumbel'], rows['inverse_cdf']
  print(f'grid {args.grid} ({g} cells), {args.samples} draws, device '
        f'{jax.devices()[0].platform}')  # fmt: skip
  print('| | Gumbel (categorical) | inverse CDF | ratio |')
  print('|---|---:|---:|---:|')
  steps = [(f'step_{n}_s', f'GP step of {n} search{"es" * (n > 1)} (bo.batched), s')
           for n in args.searches]  # fmt: skip
  for key, what in (('draw_s', 'draw, s'), *steps):
    print(
      f'| {what} | {base[key]:.4f} | {new[key]:.4f} | {base[key] / new[key]:.1f}x |'
    )
  print(f'| total variation from the masses | {base["total_variation"]:.3f} | '
        f'{new["total_variation"]:.3f} | |')  # fmt: skip
  files.write_json(args.out, {'args': dataclasses.asdict(args), 'rows': rows,
                              'device': jax.devices()[0].platform})  # fmt: skip
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
