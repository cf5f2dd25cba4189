"""Make the real-like evaluation set: seven fabrics and three garments with ground truth.

  python -m experiments.make_eval_set --out=data/eval
  python -m experiments.make_eval_set --out=/tmp/eval --preset=smoke
  python -m experiments.make_eval_set --out=data/eval_mm --physics=mismatched

How it differs from the training data: ``experiments.pipeline.eval_set``.
"""

from __future__ import annotations

import dataclasses

from absl import logging

import physsim
from experiments.pipeline import cli, eval_set


@dataclasses.dataclass(frozen=True)
class Args:
  """The evaluation set from the command line.

  Attributes:
    out: the set's root (fabrics/ and one folder per garment).
    smoke: tiny: 2 fabrics, 1 garment, small images (CPU).
    sequences: recordings per fabric and garment (0: 3).
    resolution: image width = height, pixels (0: 256).
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
    physics: 'own' (the estimator's simulator) or 'mismatched' (another
      physics, ``physsim.MISMATCHES``: what a real rig is like).
  """

  out: str = 'data/eval'
  smoke: bool = False
  sequences: int = 0
  resolution: int = 0
  backend: str = cli.choice('auto', physsim.BACKENDS)
  physics: str = cli.choice('own', tuple(physsim.MISMATCHES))


PRESETS = {'default': Args(), 'smoke': Args(smoke=True, backend='c')}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  eval_set.run(
    args.out, args.smoke, sequences=args.sequences, resolution=args.resolution,
    backend=args.backend if args.backend != 'auto' else '',
    physics=args.physics if args.physics != 'own' else '',
  )  # fmt: skip


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
