"""Is the intake's own alignment error honest? Its claim against its actual error.

The intake places a user's camera in the simulator's world and says how far
off that placement may be (``intake_alignment.alignment_error``: the pins'
spacing shortfall and their scatter's standard error as a shift, at least two
pixels at their depth, and its turn with the tilt by where up came from); the
estimate then renders its candidates from cameras moved by
that much (``physsim.shape.misplaced_pose``: a rotation of ``sd_deg`` per axis
about the pins' centre, then a shift of ``sd_m`` per axis). On windy-rig recordings
(``experiments.pipeline.rig``: floor out of view, up from ``--world_up`` or
the IMU) the true camera is known, so the placement's actual error is split
the same way, a rotation about the pins' centre and the shift left, and each
is compared with its claim: for a per-axis Gaussian error, the length of the
error vector lies within 2.50 sd (chi with 3 degrees of freedom) 90% of the
time. Recordings are kept in ``--workdir`` (a rerun reads them). Prints a table
and writes JSON.

  python -m benchmarks.alignment_error --workdir=out/alignment_error \
      --out=$OUT/alignment_error.json
"""

from __future__ import annotations

import dataclasses
import os
import re
import time

import numpy as np

from experiments.pipeline import cli, files, intake, objective, rig, simulation
from physsim import camera

CHI3_90 = 2.5003  # the 90% quantile of a chi distribution of 3 degrees of freedom


@dataclasses.dataclass(frozen=True)
class Args:
  """The recordings and the intakes.

  Attributes:
    winds: the rig's fan, m/s.
    seeds: each wind's recordings (gusts, noise, IMU error).
    recipe: 'default' or 'mismatched' (``rig.RECIPES``).
    recipe_fields: comma-separated ``field=value`` changes to the recipe
      (``rig.with_fields``), e.g. another rig's camera:
      ``eye=-0.9:-2.0:1.7,target=0:0.2:1.1``.
    modes: 'world_up' (``--world_up=z``) and/or 'imu' (the camera file's gravity).
    workdir: where the recordings are kept.
    out: JSON path ('' for none).
  """

  winds: tuple[float, ...] = (3.0, 3.52, 4.0, 4.5)
  seeds: tuple[int, ...] = (11, 12, 13)
  recipe: str = cli.choice('default', tuple(rig.RECIPES))
  recipe_fields: str = ''
  modes: tuple[str, ...] = ('world_up', 'imu')
  workdir: str = 'out/alignment_error'
  out: str = ''


PRESETS = {
  'default': Args(),
  # one small recording through both modes: the path in a minute on a CPU
  'smoke': Args(winds=(3.0,), seeds=(11,), workdir='/tmp/alignment_error_smoke'),
}


def _rotation_vector(r: np.ndarray) -> np.ndarray:
  """(3,) axis times angle (radians) of the rotation matrix ``r``."""
  angle = np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))
  if angle < 1e-12:
    return np.zeros(3)
  axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
  return angle * axis / (2.0 * np.sin(angle))


def placement_vectors(placed, true, centre) -> tuple[np.ndarray, np.ndarray]:
  """(shift (3,) m, rotation (3,) axis-angle radians): ``placed`` against
  ``true`` as ``misplaced_pose`` draws an error, a rotation about ``centre``
  then a shift, both in ``true``'s camera frame (its x right, y down, z
  forward), so that the error can be put on another camera
  (``told_cameras.intake_pose``)."""
  t = np.asarray(true.rotation, np.float64)
  r = np.asarray(placed.rotation, np.float64) @ t.T
  c = np.asarray(centre, np.float64)
  rotated = r @ (np.asarray(true.position, np.float64) - c) + c
  shift = np.asarray(placed.position, np.float64) - rotated
  return t.T @ shift, t.T @ _rotation_vector(r)


def sizes(shift: np.ndarray, rotation: np.ndarray) -> tuple[float, float]:
  """(m, deg): the lengths of a shift and of an axis-angle rotation (radians)."""
  return float(np.linalg.norm(shift)), float(np.degrees(np.linalg.norm(rotation)))


def main(args: Args) -> None:
  unknown = [m for m in args.modes if m not in ('world_up', 'imu')]
  if unknown:
    raise ValueError(f'--modes: no {unknown}; world_up and/or imu')
  base = rig.with_fields(rig.RECIPES[args.recipe], args.recipe_fields)
  tag = '_'.join([args.recipe] + re.findall(r'[A-Za-z0-9.-]+', args.recipe_fields))
  sim = objective.EstimateConfig().simulation
  centre = simulation.pin_centre(sim)  # what the estimate rotates its cameras about
  rows, t0 = [], time.perf_counter()
  for wind in args.winds:
    for seed in args.seeds:
      recipe = dataclasses.replace(base, wind_speed=wind, seed=seed)
      paths = rig.write(recipe, os.path.join(args.workdir, f'{tag}_{wind:g}_{seed}'))
      true = camera.look_at(recipe.eye, recipe.target)
      for mode in args.modes:
        ik_config = intake.IntakeConfig(world_up='z' if mode == 'world_up' else '')
        cam = paths['camera'] if mode == 'world_up' else paths['camera_imu']
        try:
          ik = intake.take_in(paths['depth'], ik_config, cam, sim)
        except ValueError as e:  # a refusal is a result: counted, not a crash
          rows.append({'wind': wind, 'seed': seed, 'mode': mode, 'refused': str(e)})
          print(f'{wind:g} m/s seed {seed} {mode}: refused: {e}', flush=True)
          continue
        shift_cam, rot_cam = placement_vectors(ik.pose, true, centre)
        shift, deg = sizes(shift_cam, rot_cam)  # a rotation keeps lengths
        sd_m, sd_deg = ik.alignment_sd
        rows.append({
          'wind': wind, 'seed': seed, 'mode': mode, 'up_from': ik.up_from,
          'shift_m': shift, 'rotation_deg': deg, 'sd_m': sd_m, 'sd_deg': sd_deg,
          'shift_in_sd': shift / sd_m, 'rotation_in_sd': deg / sd_deg,
          'shift_camera_m': shift_cam.tolist(), 'rotation_camera_rad': rot_cam.tolist(),
        })  # fmt: skip
        print(
          f'{wind:g} m/s seed {seed} {mode}: shift {100 * shift:.1f} cm (claimed '
          f'{100 * sd_m:.1f} a axis), rotation {deg:.2f} deg (claimed {sd_deg:.2f})',
          flush=True,
        )
  summary = {}
  for mode in args.modes:
    mine = [r for r in rows if r['mode'] == mode and 'refused' not in r]
    refused = sum(1 for r in rows if r['mode'] == mode and 'refused' in r)
    if not mine:
      summary[mode] = {'recordings': 0, 'refused': refused}
      continue
    s = np.array([r['shift_in_sd'] for r in mine])
    d = np.array([r['rotation_in_sd'] for r in mine])
    summary[mode] = {
      'recordings': len(mine),
      'refused': refused,
      'shift_within_90': float(np.mean(s <= CHI3_90)),
      'rotation_within_90': float(np.mean(d <= CHI3_90)),
      'median_shift_in_sd': float(np.median(s)),
      'median_rotation_in_sd': float(np.median(d)),
      'median_shift_cm': float(100 * np.median([r['shift_m'] for r in mine])),
      'median_rotation_deg': float(np.median([r['rotation_deg'] for r in mine])),
      'median_claim_cm_deg': [
        float(100 * np.median([r['sd_m'] for r in mine])),
        float(np.median([r['sd_deg'] for r in mine])),
      ],
    }
  print('| mode | placed (refused) | shift: median (cm), in claimed sd, within 90% | '
        'rotation: median (deg), in claimed sd, within 90% |\n|---|---:|---|---|')  # fmt: skip
  for mode, c in summary.items():
    if not c['recordings']:
      print(f'| {mode} | 0 ({c["refused"]}) | - | - |')
      continue
    print(
      f'| {mode} | {c["recordings"]} ({c["refused"]}) | {c["median_shift_cm"]:.1f}, '
      f'{c["median_shift_in_sd"]:.2f}, {100 * c["shift_within_90"]:.0f}% | '
      f'{c["median_rotation_deg"]:.2f}, {c["median_rotation_in_sd"]:.2f}, '
      f'{100 * c["rotation_within_90"]:.0f}% |'
    )
  print(f'(a per-axis Gaussian error of the claimed sd: median about 1.54 sd, 90% within '
        f'{CHI3_90:.2f}; {time.perf_counter() - t0:.0f} s)')  # fmt: skip
  if args.out:
    files.write_json(args.out, {'args': dataclasses.asdict(args), 'rows': rows,
                                'summary': summary, 'hardware': 'CPU, MuJoCo C'})  # fmt: skip


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
