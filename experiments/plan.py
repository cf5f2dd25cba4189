r"""What to record next, from an estimate's posterior (issue 39, item 4).

  python -m experiments.plan --workdir=out/estimate           # its posterior.npz
  python -m experiments.plan --workdir=out/joint   # a joint's joint_posterior.npz
  python -m experiments.plan --workdir=out/estimate --reading=0.02 \
      --candidates=sheet_100cm_2ms_r9,swatch_20cm_2ms_r9

Ranks candidate recordings
(``experiments.studies.protocol_candidates.Candidate`` names: a cloth size, a
fan setting) by the expected information gain about bending and area weight
from the estimate's posterior draws (``bo.design``, the Laplace gain with the
simulator's slopes and gust noise, MuJoCo C on the CPU, cached in
``<workdir>/plan_slopes/``; ``experiments.studies.protocol_plan``), prints a
table and one line of advice, and writes ``plan.json`` to the estimate's
workdir. Up to a minute a candidate and posterior node on two CPU cores the
first time (a 17 x 17 swatch), instant after.
"""

from __future__ import annotations

import dataclasses

from experiments.pipeline import cli
from experiments.studies import protocol_config, protocol_plan


@dataclasses.dataclass(frozen=True)
class Args:
  """The next recording for an estimate.

  Attributes:
    workdir: an estimate's workdir (its ``posterior.npz`` and ``estimate.json``,
      or a joint estimate's ``joint_posterior.npz`` and ``joint.json``).
    candidates: recordings to rank (``protocol_candidates.Candidate`` names, e.g.
      ``swatch_20cm_2ms_r9``: size, fan m/s or ``still``, mesh; comma-separated).
    nodes: posterior points where slopes are simulated (quantiles of bending;
      1 to 16).
    reading: relative standard error of an anemometer reading of the new
      recording's wind (0: none; at most 1).
    draws: gust histories per candidate for its noise (3 to 64).
    clip: seconds of the recording (0.25 to 10).
    seed: gust histories.
  """

  workdir: str = cli.required()
  candidates: tuple[str, ...] = protocol_plan.PLAN_CANDIDATES
  nodes: int = 1
  reading: float = 0.0
  draws: int = 6
  clip: float = 1.5
  seed: int = 0


PRESETS = {
  'default': Args(),
  # a tiny mesh and short clips: the path end to end in well under a minute
  'smoke': Args(
    candidates=('sheet_100cm_2ms_r5', 'swatch_20cm_still_r5'), draws=3, clip=0.5
  ),
}


def main(args: Args) -> None:
  warmup = 0.25 if args.clip < 1 else 1.0
  config = protocol_config.Config(draws=args.draws, clip=args.clip,
                                  warmup=warmup, seed=args.seed)  # fmt: skip
  result = protocol_plan.plan(
    args.workdir, list(args.candidates), args.nodes, args.reading, config
  )
  print(protocol_plan.plan_table(result))
  print(result['recommendation'])


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
