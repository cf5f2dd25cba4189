"""Export an estimate's fabric for another simulation: MuJoCo, ArcSim, draws.

  python -m experiments.export --workdir=out/estimate          # into out/estimate/fabric
  python -m experiments.export --workdir=out/joint --out=sim/fabric --cloth_size=0.5

Writes ``fabric.xml`` (MuJoCo MJCF of a pinned sheet at the estimate's point;
``physsim.export.load`` compiles it with the estimator's edges),
``fabric_arcsim.json`` (the ArcSim material), ``fabric_draws.csv`` (posterior
draws, to randomise over what the recordings left open) and ``fabric.json``
(what, from where): ``experiments.pipeline.fabric_files``.
"""

from __future__ import annotations

import dataclasses
import os

from experiments.pipeline import cli, fabric_files


@dataclasses.dataclass(frozen=True)
class Args:
  """The fabric of an estimate, as files.

  Attributes:
    workdir: an estimate's workdir (``estimate.json``, or a joint's ``joint.json``).
    out: where the files go ('': ``<workdir>/fabric``).
    draws: posterior draws to write (0: none).
    cloth_size: the exported sheet's side, m (0: the estimate's).
    resolution: its vertices a side (0: the estimate's).
    seed: which saved draws are written when there are more.
  """

  workdir: str = cli.required()
  out: str = ''
  draws: int = 200
  cloth_size: float = 0.0
  resolution: int = 0
  seed: int = 0


def main(args: Args) -> None:
  cli.check_numbers(args)
  if args.draws < 0 or args.cloth_size < 0 or args.resolution < 0:
    raise ValueError(
      f'--draws={args.draws}, --cloth_size={args.cloth_size}, --resolution='
      f"{args.resolution}: need >= 0 (0: none, or the estimate's own)"
    )
  out = args.out or os.path.join(args.workdir, 'fabric')
  record = fabric_files.write(
    args.workdir, out, draws=args.draws, cloth_size=args.cloth_size,
    resolution=args.resolution, seed=args.seed,
  )  # fmt: skip
  p = record['point']
  print(
    f'{record["material"]}: bending scale {p["bending_scale"]:.4g} (rigidity '
    f'{record["bending_rigidity_Nm"]:.3g} N m, young {record["young_Pa"]:.4g} Pa at '
    f'1 mm), area weight {p["area_weight"]:.4g} kg/m^2'
  )
  for kind, path in record['files'].items():
    print(f'{kind}: {path}')
  if 'draws' not in record['files'] and args.draws:
    print('no posterior draws in the estimate (the argmin keeps none): the point only')


if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
