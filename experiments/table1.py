"""The paper's Table 1: PhySNet and SDN on depth and RGB, per material, plus similarity maps.

  python -m experiments.generate_dataset --rgb --out=data/sim
  python -m experiments.table1 --dataset=data/sim --workdir=out/table1
  # smoke (CPU, under a minute once the dataset exists):
  python -m experiments.generate_dataset --preset=smoke --rgb --sequences=4 --out=/tmp/ds
  python -m experiments.table1 --dataset=/tmp/ds --workdir=/tmp/t1 --preset=smoke

What each cell means: ``experiments.studies.table1``.
"""

from __future__ import annotations

import dataclasses

from absl import logging

from experiments.pipeline import cli
from experiments.studies import table1 as table1_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """Table 1 from the command line.

  Attributes:
    dataset: the dataset root (generate_dataset --rgb --out).
    workdir: run folders and the table go here.
    report_only: write the table of the runs as they stand (cut ones marked),
      training nothing.
    table: the experiment.
  """

  dataset: str = cli.required()
  workdir: str = 'out/table1'
  report_only: bool = False
  table: table1_lib.Config = table1_lib.Config()


PRESETS = {k: Args(table=v) for k, v in table1_lib.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  if args.report_only:
    table1_lib.report(args.table, args.dataset, args.workdir)
  else:
    table1_lib.run(args.table, args.dataset, args.workdir)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
