"""Can the motion tell wind from area weight (or show bending)? Bounds, no network.

  python -m experiments.separability --workdir=out/separability
  python -m experiments.separability --workdir=/tmp/separability --preset=smoke   # CPU, about a minute

What it measures and writes: ``experiments.studies.separability``.
"""

from __future__ import annotations

import dataclasses

from absl import logging

from experiments.pipeline import cli
from experiments.studies import separability as study_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """The study from the command line.

  Attributes:
    workdir: results and figures go here (resumed from what it holds).
    study: what is simulated.
  """

  workdir: str = 'out/separability'
  study: study_lib.Config = study_lib.Config()


PRESETS = {k: Args(study=v) for k, v in study_lib.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  study_lib.run(args.study, args.workdir)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
