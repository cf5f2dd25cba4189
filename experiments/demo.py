"""The main job on a small built-in default: an end-to-end estimate in minutes on a CPU.

  python -m experiments.demo --workdir=out/demo

Simulates a small training set, trains a small PhySNet, makes one real-like
recording with known parameters and estimates them from it alone
(``experiments.pipeline.demo``). Every stage resumes from what ``--workdir``
holds.
"""

from __future__ import annotations

import dataclasses

from absl import logging

import physsim
from experiments.pipeline import cli
from experiments.pipeline import demo as demo_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """The demo from the command line.

  Attributes:
    workdir: data, model, recording and estimate go here.
    material: the fabric (physsim.FABRICS).
    sequences: training simulations.
    seed: seed of the recording (its ground truth) and of the search.
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
  """

  workdir: str = 'out/demo'
  material: str = 'gray_interlock'
  sequences: int = 24
  seed: int = 0
  backend: str = cli.choice('auto', physsim.BACKENDS)


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  demo_lib.run(args.workdir, args.material, args.sequences, args.seed, args.backend)


if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
