"""The simulated overhang against the heavy elastica, as the mesh is refined.

The protocol study (``experiments.studies.protocol``) reads bending from a
strip overhanging a table's edge. This measures whether the simulator's strip
hangs as the exact heavy elastica of its rigidity D = bending x D0 says
(``physsim.cantilever``), and whether a finer mesh closes the gap: for each
mesh and bending, one strip released flat in still air (the study's overhang
candidate: its first two rows held, ``--overhang`` metres free), its tip's
reach from the edge averaged over the clip, the elastica's reach, and the
rigidity whose elastica reaches as far (over D; 1: the simulator's strip is
the elastica). MuJoCo C, one world per mesh and bending:

  python -m benchmarks.overhang_mesh --out=/tmp/overhang_mesh.json
  python -m benchmarks.overhang_mesh --resolutions=9,13 --bendings=1 --out=/tmp/o.json
"""

from __future__ import annotations

import dataclasses
import time

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, files
from experiments.studies import (
  protocol_camera,
  protocol_candidates,
  protocol_config,
  protocol_elastica,
  protocol_slopes,
)


@dataclasses.dataclass(frozen=True)
class Args:
  """The overhang's mesh study.

  Attributes:
    material: the fabric.
    overhang: metres over the edge.
    resolutions: vertices a side of each mesh (comma-separated, >= 4).
    bendings: bending scales (comma-separated).
    area_weight: kg/m^2.
    warmup: seconds simulated before the clip.
    clip: seconds averaged.
    fps: frames per second averaged.
    workers: MuJoCo C processes.
    out: the JSON written ('' none).
  """

  material: str = 'gray_interlock'
  overhang: float = 0.03
  resolutions: tuple[str, ...] = ('9', '13', '17')
  bendings: tuple[str, ...] = ('0.3', '1', '3')
  area_weight: float = 0.185
  warmup: float = 1.0
  clip: float = 1.5
  fps: float = 20.0
  workers: int = 0
  out: str = 'out/benchmarks/overhang_mesh.json'


PRESETS = {
  'default': Args(),
  'smoke': Args(resolutions=('5', '7'), bendings=('3',), warmup=0.25, clip=0.25),
}


def main(args: Args) -> None:
  bendings = protocol_config.floats('bendings', args.bendings)
  resolutions = [int(r) for r in args.resolutions]
  if min(resolutions) < 4 or not args.overhang > 0:
    raise ValueError('need --resolutions >= 4 and --overhang > 0')
  d0 = physsim.reference_rigidity(physsim.fabric(args.material).material)
  config = protocol_config.Config(material=args.material, fps=args.fps)
  rows = []
  for n in resolutions:
    cand = protocol_candidates.Candidate(args.overhang, 0.0, 2, n, overhang=True)
    mesh = protocol_candidates.mesh(cand)
    sim = protocol_slopes.sim_config(cand, config)
    model = physsim.build(mesh, args.material, sim)
    t0 = time.time()
    out = physsim.simulate(
      model,
      physsim.params.make(
        np.array(bendings), np.zeros(len(bendings)), np.full(len(bendings), args.area_weight)
      ),
      frames=round(args.clip * args.fps), fps=args.fps, warmup=args.warmup,
      backend='c', workers=args.workers, space=protocol_config.SPACE,
      key=jax.random.key(0),
    )  # fmt: skip
    if not np.all(out.valid):
      raise RuntimeError(f'{cand.name}: a simulation blew up')
    stats = protocol_camera.summaries(out.positions, mesh.vertices, n, args.overhang)
    reach = stats[:, 2]
    for b, r in zip(bendings, reach, strict=True):
      rows.append({
        'resolution': n, 'spacing_mm': 1000 * args.overhang / (n - 2),
        'seconds': time.time() - t0,
        **protocol_elastica.elastica_check(args.overhang, b, args.area_weight,
                                           float(r), d0),
      })  # fmt: skip
    print(f'{cand.name}: {time.time() - t0:.0f} s', flush=True)
  print(f'{args.material}, {100 * args.overhang:g} cm over the edge, area weight '
        f'{args.area_weight:g} kg/m^2')  # fmt: skip
  print(
    '| mesh | spacing mm | bending | L/c | reach (sim) | reach (elastica) | D ratio |'
  )
  print('|---:|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    e, q = r['elastica_reach'], r['rigidity_ratio']
    print(f"| {r['resolution']} | {r['spacing_mm']:.1f} | {r['bending']:g} | "
          f"{r['overhang_over_c']:.2f} | {r['simulated_reach']:.3f} | "
          f"{'-' if e is None else f'{e:.3f}'} | {'-' if q is None else f'{q:.2f}'} |")  # fmt: skip
  if args.out:
    files.write_json(args.out, {'rows': rows, 'flags': dataclasses.asdict(args)})
    print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
