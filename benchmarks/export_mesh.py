"""An export for the user's mesh (``experiments.export --mesh=N``) against the elastica.

For each mesh of a strip (``--strip`` metres a side, N vertices a side), the
flex's bending is fitted as the export fits it (``physsim.mesh_fit.fit``: a
9-column cantilever at that spacing), once at three bending lengths (the
export's default for a sheet wider than 4.5 of them) and once at the strip's
own side (its default for this strip, ``fabric_files.fit_overhang``), and each
is then checked
on the strip as the export writes it: ``--strip`` metres over a table's edge,
as wide as the strip (at most ``--check_columns`` vertices: wider ones bend
alike), its tip's reach against the heavy elastica of the measured bending
length (``physsim.cantilever``); beside them the nominal scale (the fabric's
own rigidity, what the export wrote before). MuJoCo C, one strip at a time:

  python -m benchmarks.export_mesh --out=/tmp/export_mesh.json
  python -m benchmarks.export_mesh --preset=smoke --out=''
"""

from __future__ import annotations

import dataclasses
import time

import physsim
from experiments.pipeline import cli, files
from physsim import cantilever, mesh_fit


@dataclasses.dataclass(frozen=True)
class Args:
  """The strip, its meshes and the fabric.

  Attributes:
    material: the fabric.
    bending_scale: its rigidity over the material's reference.
    area_weight: kg/m^2.
    strip: the strip's side and overhang, m.
    resolutions: vertices a side of each mesh (comma-separated, 4-200).
    check_columns: the checked strip's width in vertices, at most.
    fps: the export's frame rate (its step divides the frame).
    out: the JSON written ('' none).
  """

  material: str = 'gray_interlock'
  bending_scale: float = 1.0
  area_weight: float = 0.185
  strip: float = 0.05
  resolutions: tuple[str, ...] = ('9', '17', '25', '41')
  check_columns: int = 17
  fps: float = 20.0
  out: str = 'out/benchmarks/export_mesh.json'


PRESETS = {
  'default': Args(),
  'smoke': Args(resolutions=('5', '7')),
}


def main(args: Args) -> None:
  resolutions = [int(r) for r in args.resolutions]
  if not (min(resolutions) >= 4 and max(resolutions) <= 200 and 0 < args.strip <= 1):
    raise ValueError('need --resolutions in 4-200 and 0 < --strip <= 1 m')
  d0 = physsim.reference_rigidity(args.material)
  rigidity = args.bending_scale * d0
  w = args.area_weight
  c = physsim.params.bending_length(args.bending_scale, w, d0)
  rows = []
  for n in resolutions:
    t0 = time.perf_counter()
    h = args.strip / (n - 1)
    config = physsim.config_for_mesh(physsim.square(n, args.strip), args.fps)
    strip = mesh_fit.strip(h, n - 1, columns=min(n, args.check_columns))
    elastica = float(cantilever.tip(args.strip / c)[0][0]) * args.strip
    row = {'resolution': n, 'spacing_mm': 1e3 * h, 'elastica_reach_mm': 1e3 * elastica}
    for name, overhang in (('default', 0.0), ('strip', args.strip)):
      t1 = time.perf_counter()
      fit = mesh_fit.fit(args.material, rigidity, w, h, config, overhang=overhang)
      x = mesh_fit.settle(strip, args.material, fit.flex_scale, w, config, c)
      row[name] = {'fit': fit.record(), 'strip_reach_error': float(x[-1, 1]) / elastica - 1,
                   'seconds': time.perf_counter() - t1}  # fmt: skip
    x = mesh_fit.settle(strip, args.material, args.bending_scale, w, config, c)
    row['strip_nominal_error'] = float(x[-1, 1]) / elastica - 1
    row['seconds'] = time.perf_counter() - t0
    rows.append(row)
    print(f'{n}x{n}: {row["seconds"]:.0f} s', flush=True)
  print(
    f'{args.material}, bending length {1e3 * c:.1f} mm (D {1e6 * rigidity:.3g} uN m, '
    f'{1e3 * w:.0f} g/m^2); a {100 * args.strip:g} cm strip, {args.strip / c:.2f} '
    "bending lengths over the edge; its reach against the elastica's"
  )
  print(
    '| mesh | spacing mm | nominal | fitted at 3 c: flex scale, reach | '
    f'fitted at {100 * args.strip:g} cm (the default here): flex scale, reach | '
    'fit s (3 c, strip) |'
  )
  print('|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    d, s = r['default'], r['strip']
    print(
      f'| {r["resolution"]}x{r["resolution"]} | {r["spacing_mm"]:.2f} | '
      f'{100 * r["strip_nominal_error"]:+.1f}% | '
      f'{d["fit"]["flex_bending_scale"]:.3f}, {100 * d["strip_reach_error"]:+.2f}% | '
      f'{s["fit"]["flex_bending_scale"]:.3f}, {100 * s["strip_reach_error"]:+.2f}% | '
      f'{d["seconds"]:.0f}, {s["seconds"]:.0f} |'
    )
  if args.out:
    files.write_json(args.out, {'rows': rows, 'args': dataclasses.asdict(args),
                                'hardware': 'CPU, MuJoCo C, one thread'})  # fmt: skip
    print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
