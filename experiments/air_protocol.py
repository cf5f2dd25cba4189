r"""Does the protocol's video measure the fabric's air? (issue 76)

  python -m experiments.air_protocol --preset=smoke --out=/tmp/air.json   # CPU
  python -m experiments.air_protocol --sets=40 --out=$OUT/air_protocol.json  # GPU

Protocol sets of three fan settings with an anemometer, a scale and a strip,
each fabric with its own air coefficient, estimated with the air coefficient
free and held at ArcSim's: ``experiments.studies.air_protocol``.
"""

from __future__ import annotations

import dataclasses

from absl import logging

from experiments.pipeline import cli
from experiments.studies import air_protocol


@dataclasses.dataclass(frozen=True)
class Args:
  """The air protocol study from the command line.

  Attributes:
    study: the sets, their world and how they are estimated.
  """

  study: air_protocol.Study = air_protocol.Study()


PRESETS = {k: Args(study=v) for k, v in air_protocol.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  air_protocol.run(args.study)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
