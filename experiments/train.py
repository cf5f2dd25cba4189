r"""Train PhySNet (or SDN) per material on a generated dataset.

  python -m experiments.train --dataset=data/sim --workdir=out/train
  python -m experiments.train --dataset=/tmp/ds --workdir=/tmp/tr --preset=smoke
  python -m experiments.train --dataset=/tmp/ds --workdir=/tmp/tr_rgb \
    --preset=smoke --modality=rgb   # needs a dataset made with --rgb

Run folders, checkpoints and logs: ``experiments.pipeline.training``.
"""

from __future__ import annotations

import dataclasses

from absl import logging

from experiments.pipeline import cli
from experiments.pipeline import training as training_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """Training from the command line.

  Attributes:
    dataset: the dataset root (generate_dataset --out).
    workdir: run folders go here, one per material (or 'all').
    select_lr: instead of training, pick the learning rate per material among
      these by validation on the training simulations.
    train: what is trained and how.
  """

  dataset: str = cli.required()
  workdir: str = 'out/train'
  select_lr: tuple[float, ...] = ()
  train: training_lib.Config = training_lib.Config()


PRESETS = {k: Args(train=v) for k, v in training_lib.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  if args.select_lr:
    training_lib.choose_lr(args.train, args.dataset, args.workdir, args.select_lr)
  else:
    training_lib.run(args.train, args.dataset, args.workdir)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
