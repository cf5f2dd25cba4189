"""Simulate a light and a stiff fabric in a fan's gusty wind; save a filmstrip PNG.

python -m experiments.simulate_demo --workdir=out/filmstrip
"""

from __future__ import annotations

import dataclasses

from experiments.pipeline import cli
from experiments.studies import filmstrip


@dataclasses.dataclass(frozen=True)
class Args:
  """The filmstrip from the command line.

  Attributes:
    workdir: where filmstrip.png and motion.json go.
    film: what is simulated.
  """

  workdir: str = 'out/filmstrip'
  film: filmstrip.Config = filmstrip.Config()


def main(args: Args) -> None:
  filmstrip.run(args.film, args.workdir)


if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
