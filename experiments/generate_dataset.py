"""Simulate and render the fabric dataset sweep (``experiments.pipeline.datasets``).

  python -m experiments.generate_dataset --out=data/sim                 # the paper's
  python -m experiments.generate_dataset --preset=smoke --out=/tmp/ds   # CPU, seconds

A rerun resumes: finished sequences are kept as they are.
"""

from __future__ import annotations

import dataclasses

from absl import logging

from experiments.pipeline import cli
from experiments.pipeline import datasets as datasets_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """A dataset sweep from the command line.

  Attributes:
    out: the dataset folder (created, or resumed).
    sweep: what is simulated and rendered.
  """

  out: str = 'data/sim'
  sweep: datasets_lib.Config = datasets_lib.Config()


PRESETS = {k: Args(sweep=v) for k, v in datasets_lib.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  s = datasets_lib.run(args.sweep, args.out)
  print(datasets_lib.describe(s, args.out))


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
