"""Which recordings measure bending and area weight: the protocol study (issue 39).

  python -m experiments.protocol --workdir=out/protocol --workers=16     # ~8 min on 16 cores
  python -m experiments.protocol --workdir=out/protocol --preset=full    # + the first study's swatches
  python -m experiments.protocol --workdir=/tmp/protocol --preset=smoke  # CPU, < 1 min
  python -m experiments.protocol --workdir=out/protocol \\
      --figure=docs/figures/protocol_gray_interlock.png                  # and a copy

What it measures: ``experiments.studies.protocol``. Writes ``protocol.json``
(narrowing factors per candidate set, truth and mode; the slopes and noise of
every candidate) and ``protocol.png`` to ``--workdir``; the simulations'
slopes are cached under ``<workdir>/slopes/``, so a rerun resumes, and
``experiments.plan`` can reuse them.
"""

from __future__ import annotations

import dataclasses
import os
import shutil

from experiments.pipeline import cli, files
from experiments.studies import protocol, protocol_config, protocol_report


@dataclasses.dataclass(frozen=True)
class Args:
  """The protocol study from the command line.

  Attributes:
    workdir: results and the cached slopes (resumed).
    figure: also copy the figure here (e.g. under docs/figures/; '' none).
    study: the candidates, truths and noise model.
  """

  workdir: str = cli.required()
  figure: str = ''
  study: protocol_config.Config = protocol_config.Config()


PRESETS = {k: Args(study=v) for k, v in protocol_config.PRESETS.items()}


def main(args: Args) -> None:
  result = protocol.run(args.study, args.workdir)
  print(protocol_report.markdown(result))
  for pair in result['convergence']:
    print('mesh convergence (first truth):', protocol_report.convergence_line(pair))
  print(f'{result["seconds"]:.0f} s ({result["simulation_seconds"]:.0f} s of simulation '
        f'from scratch); wrote {args.workdir}/{protocol_report.RESULT_FILE} '
        f'and {protocol_report.FIGURE_FILE}')  # fmt: skip
  if args.figure:
    os.makedirs(os.path.dirname(args.figure) or '.', exist_ok=True)
    src = os.path.join(args.workdir, protocol_report.FIGURE_FILE)
    files.write_atomic(args.figure, lambda tmp: shutil.copyfile(src, tmp))
    print(f'copied the figure to {args.figure}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
