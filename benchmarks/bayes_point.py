"""The least-expected-error point: prefix sums against the candidates x draws
matrix, side by side.

Every estimate's results take ``bo.calibration.bayes_point`` of the
posterior's and the prior's draws per quantity, and the calibration's
analysis takes it for every recording, mode and quantity. The matrix form
(199 candidates x 4,096 draws of exp/log/abs) was what it computed until
2026-11-28; ``bayes_point`` now sums over the sorted draws. This script times
both on the same draws in this process and checks they pick the same
candidate.

  python -m benchmarks.bayes_point --out=$OUT/bayes_point.json
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from bo import calibration
from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The comparison.

  Attributes:
    samples: draws per call (a posterior keeps 4,096; its summaries and the
      prior's own point draw 16,384).
    repeats: timed calls of each (the table shows their median).
    out: JSON path.
  """

  samples: tuple[int, ...] = (4096, 16384)
  repeats: int = 20
  out: str = 'out/benchmarks/bayes_point.json'


PRESETS = {'default': Args(), 'smoke': Args(samples=(512,), repeats=3)}


def matrix_costs(x, loss: str, n_candidates: int = 199, weights=None):
  """The matrix form, as ``bayes_point`` computed it before: (the candidates,
  each one's expected error over every draw); the tests' reference too."""
  w = np.ones_like(x) if weights is None else np.asarray(weights, np.float64)
  order = np.argsort(x)
  cw = np.cumsum(w[order]) / w.sum()
  probs = (np.arange(n_candidates) + 0.5) / n_candidates
  c = x[order][np.minimum(np.searchsorted(cw, probs), x.size - 1)][:, None]
  if loss == 'relative':
    cost = np.abs(c - x) / x @ w
  elif loss == 'log':
    cost = np.abs(np.log(c) - np.log(x)) @ w
  else:
    cost = np.exp(np.abs(np.log(c) - np.log(x))) @ w
  return c[:, 0], cost


def matrix_point(x, loss: str) -> float:
  """The matrix form's point: its least expected error's candidate."""
  c, cost = matrix_costs(x, loss)
  return float(c[np.argmin(cost)])


def _median_seconds(fn, repeats: int) -> float:
  times = []
  for _ in range(repeats):
    t0 = time.perf_counter()
    fn()
    times.append(time.perf_counter() - t0)
  return float(np.median(times))


def main(args: Args) -> None:
  if min(args.samples, default=0) < 2 or args.repeats < 1:
    raise ValueError(
      f'need samples >= 2 and repeats >= 1, got {args.samples}, {args.repeats}'
    )
  rows = []
  for n in args.samples:
    x = np.random.default_rng(0).lognormal(0.0, 0.8, n)
    for loss in calibration.LOSSES:
      same = calibration.bayes_point(x, loss) == matrix_point(x, loss)
      before = _median_seconds(
        lambda x=x, loss=loss: matrix_point(x, loss), args.repeats
      )
      after = _median_seconds(
        lambda x=x, loss=loss: calibration.bayes_point(x, loss), args.repeats
      )
      rows.append({
        'loss': loss, 'samples': n, 'matrix_ms': 1e3 * before,
        'prefix_sums_ms': 1e3 * after, 'speedup': before / after, 'same_point': same,
      })  # fmt: skip
  print('| loss | draws | matrix | prefix sums | speed-up | same point |')
  print('|---|---:|---:|---:|---:|---|')
  for r in rows:
    print(
      f'| {r["loss"]} | {r["samples"]} | {r["matrix_ms"]:.2f} ms | '
      f'{r["prefix_sums_ms"]:.3f} ms | {r["speedup"]:.0f}x | {r["same_point"]} |'
    )
  files.write_json(args.out, {'rows': rows, 'repeats': args.repeats})
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
