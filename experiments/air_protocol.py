r"""Does the protocol's video measure the fabric's air? (issue 76)

  python -m experiments.air_protocol --preset=smoke --out=/tmp/air.json   # CPU
  python -m experiments.air_protocol --sets=40 --out=$OUT/air_protocol.json  # GPU

Protocol sets of three fan settings with an anemometer, a scale and a strip,
each fabric with its own air coefficient, estimated with the air coefficient
free and held at ArcSim's: ``experiments.studies.air_protocol``.
"""

from __future__ import annotations

from experiments.pipeline import cli
from experiments.studies import air_protocol


def main(study: air_protocol.Study) -> None:
  air_protocol.run(study)


if __name__ == '__main__':
  cli.run(air_protocol.Study, air_protocol.PRESETS, main)
