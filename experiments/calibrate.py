"""Simulation-based calibration of the estimate's credible intervals.

  python -m experiments.calibrate --workdir=out/calibration            # GPU: 200 recordings
  python -m experiments.calibrate --workdir=/tmp/cal --preset=smoke    # CPU, minutes
  python -m experiments.calibrate --workdir=out/calibration --install  # ship its coverage
  python -m experiments.calibrate --workdir=out/calibration --analyse_only  # no simulation

What it measures: ``experiments.studies.calibration``. With ``--install`` the
held-out coverage is copied into the package (``experiments/pipeline/
calibration.json``), where every estimate's report quotes it.
"""

from __future__ import annotations

import dataclasses
import shutil

from absl import logging

from experiments.pipeline import cli, distributed, report
from experiments.studies import calibration


@dataclasses.dataclass(frozen=True)
class Args:
  """The calibration study from the command line.

  Attributes:
    workdir: network, recordings, estimates and results (resumed).
    install: copy the held-out coverage into the package, where estimates
      quote it.
    analyse_only: analyse the estimates the workdir holds, simulating
      nothing (e.g. searches run on a GPU machine, analysis elsewhere).
    study: what is simulated and estimated.
  """

  workdir: str = 'out/calibration'
  install: bool = False
  analyse_only: bool = False
  study: calibration.Config = calibration.Config()


PRESETS = {k: Args(study=v) for k, v in calibration.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  calibration.run(args.study, args.workdir, analyse_only=args.analyse_only)
  if args.install and distributed.is_main():
    shutil.copyfile(
      f'{args.workdir}/{calibration.RESULT_FILE}', report.CALIBRATION_FILE
    )
    print(f'installed as {report.CALIBRATION_FILE}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
