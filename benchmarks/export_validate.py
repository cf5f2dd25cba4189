"""An exported sheet in fan settings it was not made from: ``experiments.validate``'s numbers.

A rig's recordings (``experiments.pipeline.rig``: a 41-vertex sheet, gustier
wind, its own camera and noise; ``--recipe=mismatched``: another physics too)
of one fabric at each of ``--winds`` are each compared, through
``experiments.pipeline.validation`` (the recording's camera, its anemometer's
wind), with the fabric exported for the 1 m sheet at each of ``--resolutions``
vertices a side: the shape distance from the recording against the gusts'
noise floor (the same fabric, other gust seeds), and the library's default
fabric's. The export is of ``--estimate``'s workdir, or else of an estimate at
the recipe's truth (what a perfect estimate would export: this measures the
export and the check, not an estimate):

  python -m benchmarks.export_validate --workdir=/tmp/export_validate
  python -m benchmarks.export_validate --preset=smoke --workdir=/tmp/ev_smoke
"""

from __future__ import annotations

import dataclasses
import json
import os
import time

from experiments.pipeline import cli, fabric_files, files, intake, rig, validation


@dataclasses.dataclass(frozen=True)
class Args:
  """The recordings, the exports and the check.

  Attributes:
    workdir: where recordings, exports and the JSON go.
    estimate: an estimate's workdir to export ('': one at the recipe's truth).
    recipe: the rig's recipe (``rig.RECIPES``).
    winds: the fan settings recorded, m/s (comma-separated).
    resolutions: the exported sheet's vertices a side (comma-separated).
    smoke: the rig's small recording (``rig.SMOKE``'s camera, mesh and clip).
    settings: the check's simulations.
  """

  workdir: str = cli.required()
  estimate: str = ''
  recipe: str = 'default'
  winds: tuple[str, ...] = ('2.0', '3.0')
  resolutions: tuple[str, ...] = ('25', '41')
  smoke: bool = False
  settings: validation.Settings = validation.Settings(seeds=6)


PRESETS = {
  'default': Args(),
  'smoke': Args(
    winds=('3.0',),
    resolutions=('10',),
    smoke=True,
    settings=validation.Settings(frames=16, warmup=0.5, seeds=3, image_size=32),
  ),  # fmt: skip
}


def _truth_estimate(recipe: rig.Recipe, workdir: str, fps: float) -> str:
  """An estimate's workdir whose point is the recipe's truth."""
  path = os.path.join(workdir, 'truth_estimate')
  os.makedirs(path, exist_ok=True)
  entry = lambda v: {'value': v, 'median': v, 'interval_90': [v, v]}  # noqa: E731
  with open(os.path.join(path, 'estimate.json'), 'w') as f:
    json.dump({
      'material': recipe.material,
      'config': {'cloth_size': recipe.cloth_size, 'cloth_resolution': 25, 'fps': fps},
      'estimate': {'bending_scale': entry(recipe.bending_scale),
                   'area_weight': entry(recipe.area_weight)},
    }, f)  # fmt: skip
  return path


def main(args: Args) -> None:
  if args.recipe not in rig.RECIPES:
    raise ValueError(f'--recipe={args.recipe}: one of {sorted(rig.RECIPES)}')
  args.settings.check()
  base = rig.SMOKE if args.smoke else rig.RECIPES[args.recipe]
  if args.smoke and args.recipe != 'default':
    base = dataclasses.replace(rig.RECIPES[args.recipe], **{
      k: getattr(rig.SMOKE, k)
      for k in ('cloth_resolution', 'frames', 'fps', 'warmup', 'width', 'height', 'focal')
    })  # fmt: skip
  estimate = args.estimate or _truth_estimate(base, args.workdir, 20.0)
  path = os.path.join(args.workdir, 'export_validate.json')
  rows = []
  for n in (int(r) for r in args.resolutions):
    t0 = time.perf_counter()
    out = os.path.join(args.workdir, f'fabric_{n}x{n}')
    record = fabric_files.write(estimate, out, draws=0, cloth_size=base.cloth_size,
                                resolution=n)  # fmt: skip
    exported = validation.read_export(out)
    for wind in (float(v) for v in args.winds):
      recipe = dataclasses.replace(base, wind_speed=wind)
      paths = rig.write(
        recipe, os.path.join(args.workdir, f'rec_{args.recipe}_{wind:g}')
      )
      validation.check_set_up(exported, paths['depth'], paths['camera'],
                              recipe.cloth_size, wind)  # fmt: skip
      taken, rec = validation.take_in(
        exported, paths['depth'], paths['camera'], intake.IntakeConfig(world_up='z'),
        args.settings,
      )  # fmt: skip
      result = validation.predict(exported, rec, wind, args.settings)
      rows.append({'resolution': n, 'wind_speed': wind, **result.record(),
                   'alignment_sd': list(taken.alignment_sd),
                   'fit': record['simulator']['fit'],
                   'seconds': time.perf_counter() - t0})  # fmt: skip
      r = rows[-1]
      print(
        f'{n}x{n}, {wind:g} m/s: distance {r["distance_mm"]:.1f} mm, floor '
        f'{r["floor_mm"]:.1f} mm ({r["distance_over_floor"]:.2f}x; the library '
        f'{r["library_over_floor"]:.2f}x), {r["seconds"]:.0f} s', flush=True,
      )  # fmt: skip
      files.write_json(path, {'rows': rows, 'args': dataclasses.asdict(args),
                              'hardware': 'CPU, MuJoCo C'})  # fmt: skip
  print(
    f'{base.material} (bending x{base.bending_scale:g}, {1e3 * base.area_weight:.0f} '
    f'g/m^2), rig recipe {args.recipe!r}, exported from '
    f'{"the truth" if not args.estimate else args.estimate}; {args.settings.seeds} '
    'gust seeds'
  )
  print(
    '| mesh | wind m/s | distance mm | floor mm | distance / floor | library / floor |'
  )
  print('|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["resolution"]}x{r["resolution"]} | {r["wind_speed"]:g} | '
      f'{r["distance_mm"]:.1f} | {r["floor_mm"]:.1f} | {r["distance_over_floor"]:.2f} | '
      f'{r["library_over_floor"]:.2f} |'
    )
  print(f'wrote {path}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
