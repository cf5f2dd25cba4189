"""Export an estimate's fabric for another simulation at your mesh: MuJoCo, ArcSim, draws.

  python -m experiments.export --workdir=out/estimate            # the estimate's sheet
  python -m experiments.export --workdir=out/estimate --cloth_size=0.05 --mesh=17
  python -m experiments.export --workdir=out/joint --out=sim/fabric --cloth_size=0.5

Writes, into ``<workdir>/fabric_<n>x<n>`` (all of the files or none):
``fabric.xml`` (MuJoCo MJCF of a pinned sheet of that mesh whose flex bends
as the measured fabric does: its bending fitted by simulating a cantilever
strip of the mesh's spacing until it reaches as far as the elastica of the
measured bending length; ``physsim.export.load`` compiles it with the
estimator's edges), ``fabric_arcsim.json`` (the ArcSim material),
``fabric_draws.csv`` (posterior draws, to randomise over what the recordings
left open) and ``fabric.json`` (the fabric in uN m, mm and g/m^2, the mesh and
its fit): ``experiments.pipeline.fabric_files``. Check it against a recording
it was not estimated from: ``python -m experiments.validate``.
"""

from __future__ import annotations

import dataclasses

from experiments.pipeline import cli, fabric_files


@dataclasses.dataclass(frozen=True)
class Args:
  """The fabric of an estimate, as files for a mesh.

  Attributes:
    workdir: an estimate's workdir (``estimate.json``, or a joint's ``joint.json``).
    out: where the files go ('': ``<workdir>/fabric_<n>x<n>``).
    mesh: the exported sheet's vertices a side (0: the estimate's); its
      bending is fitted at that mesh's spacing (3-200).
    resolution: the same as --mesh (its older name; 0: --mesh).
    cloth_size: the exported sheet's side, m (0: the estimate's; 0.05-3).
    overhang: the fitted cantilever's overhang, m (0: the sheet's own side
      where it is 1-4.5 bending lengths, a swatch or strip; else three bending
      lengths, as a reading of the bending length is made).
    draws: posterior draws to write (0: none; at most 100000).
    seed: which saved draws are written when there are more.
  """

  workdir: str = cli.required()
  out: str = ''
  mesh: int = 0
  resolution: int = 0
  cloth_size: float = 0.0
  overhang: float = 0.0
  draws: int = 200
  seed: int = 0


def main(args: Args) -> None:
  cli.check_numbers(args)
  if args.mesh and args.resolution and args.mesh != args.resolution:
    raise ValueError(
      f'--mesh={args.mesh} and --resolution={args.resolution}: one mesh (the same flag)'
    )
  record = fabric_files.write(
    args.workdir, args.out, draws=args.draws, cloth_size=args.cloth_size,
    resolution=args.mesh or args.resolution, overhang=args.overhang, seed=args.seed,
    mesh_flag='mesh' if args.mesh or not args.resolution else 'resolution',
  )  # fmt: skip
  for line in fabric_files.summary(record):
    print(line)
  for kind, path in record['files'].items():
    print(f'{kind}: {path}')
  if 'draws' not in record['files'] and args.draws:
    print('no posterior draws in the estimate (the argmin keeps none): the point only')


if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
