"""How closely an exported fabric (``physsim.export``) hangs where the estimator's does.

The exported MJCF, compiled by MuJoCo C (with ``export.load``'s edge weights,
and plainly), is stepped in the estimator's own air force (ArcSim's face force
on the steady wind, computed each step and applied to its bodies), and its
mean position over a clip (what the shape distance reads) is compared with the
estimator's MuJoCo C rollout of the same sheet; beside it, how far the
estimator's own sheet moves for a small change of each parameter, the scale
the comparison is read against, and for one of a ten-thousandth (a fluttering
sheet's mean over a clip moves with any rounding: the floor). Prints a table and writes JSON.

  python -m benchmarks.export_fidelity --out=$OUT/export_fidelity.json
"""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

import physsim
from experiments.pipeline import cli, files
from physsim import export


@dataclasses.dataclass(frozen=True)
class Args:
  """The sheet and its clip.

  Attributes:
    material: the fabric.
    bending_scale, area_weight, wind_speed: the sheet's parameters.
    resolution: vertices a side of the 1 m sheet (the estimate's 25).
    fps: frames a second averaged.
    warmup: seconds simulated before the clip.
    clip: seconds averaged.
    out: JSON path ('' for none).
  """

  material: str = 'gray_interlock'
  bending_scale: float = 1.0
  area_weight: float = 0.184
  wind_speed: float = 3.0
  resolution: int = 25
  fps: float = 20.0
  warmup: float = 1.0
  clip: float = 3.0
  out: str = ''


PRESETS = {
  'default': Args(),
  # the path end to end in seconds on a CPU
  'smoke': Args(resolution=8, warmup=0.25, clip=0.5),
}


def _estimator(model, args: Args, s: float, w: float, v: float) -> np.ndarray:
  """(V, 3) the estimator's mean position over the clip (MuJoCo C, steady)."""
  ro = physsim.simulate(
    model, physsim.params.make(s, v, w), frames=round(args.clip * args.fps),
    fps=args.fps, warmup=args.warmup, backend='c', workers=1,
  )  # fmt: skip
  return ro.check().positions[0].mean(axis=0)


def _exported(m: mujoco.MjModel, mesh, config, args: Args) -> np.ndarray:
  """(V, 3) an exported model's mean position over the clip, in the
  estimator's air force (``physsim.face_wind_forces``, jitted, each step)."""
  faces = jnp.asarray(mesh.faces)
  area = jnp.asarray(mesh.face_areas, jnp.float64)
  flow = args.wind_speed * jnp.array([0.0, 1.0, 0.0])
  rest = np.asarray(mesh.vertices, np.float64)
  moving = np.flatnonzero(~np.isin(np.arange(len(rest)), mesh.pinned))
  body = np.asarray(m.flex_vertbodyid)[moving]
  dofs = m.jnt_dofadr[m.body_jntadr[body]][:, None] + np.arange(3)

  @jax.jit
  def wind(x, v):
    return physsim.face_wind_forces(
      x, v, faces, area, flow, config.air_density, config.air_drag
    )

  d = mujoco.MjData(m)
  steps = round(1.0 / args.fps / m.opt.timestep)
  warm = round(args.warmup * args.fps)
  frames = warm + round(args.clip * args.fps)
  total = np.zeros_like(rest)
  x, v = rest.copy(), np.zeros_like(rest)
  for i in range(frames):
    for _ in range(steps):
      x[moving] = rest[moving] + d.qpos[dofs]  # slide joints: offsets from rest
      v[moving] = d.qvel[dofs]
      d.xfrc_applied[body, :3] = np.asarray(wind(x, v))[moving]
      mujoco.mj_step(m, d)
    if i >= warm:
      total[moving] += rest[moving] + d.qpos[dofs]
      total[mesh.pinned] += rest[mesh.pinned]
  return total / (frames - warm)


def main(args: Args) -> None:
  # the exported model's air force in float64, as the estimator's MuJoCo C
  # rollout computes its own (NumPy): a float32 force alone moves a fluttering
  # sheet by about a millimetre
  jax.config.update('jax_enable_x64', True)
  mesh = physsim.square(args.resolution, 1.0)
  config = physsim.config_for_mesh(mesh, args.fps)
  model = physsim.build(mesh, args.material, config)
  s, w, v = args.bending_scale, args.area_weight, args.wind_speed
  t0 = time.perf_counter()
  ours = _estimator(model, args, s, w, v)
  xml = export.mujoco_xml(mesh, args.material, s, w, config)
  rows = {
    'exported, export.load': _exported(export.load(xml), mesh, config, args),
    'exported, compiled plainly': _exported(
      mujoco.MjModel.from_xml_string(xml), mesh, config, args
    ),
    # a change that means nothing: the flutter's own spread of the mean
    'estimator, bending x1.0001 (the floor)': _estimator(model, args, 1.0001 * s, w, v),
    'estimator, bending x1.1': _estimator(model, args, 1.1 * s, w, v),
    'estimator, area weight x1.03': _estimator(model, args, s, 1.03 * w, v),
    'estimator, wind x1.02': _estimator(model, args, s, w, 1.02 * v),
  }
  table = {
    k: 1000 * float(np.linalg.norm(x - ours, axis=-1).mean()) for k, x in rows.items()
  }
  moved = 1000 * float(np.linalg.norm(ours - mesh.vertices, axis=-1).mean())
  print(
    f'{args.material}, {args.resolution}x{args.resolution}, {v} m/s steady, mean '
    f'position over {args.clip} s (the sheet moved {moved:.0f} mm from rest)'
  )
  print('| against the estimator | mean vertex distance (mm) |\n|---|---:|')
  for k, d in table.items():
    print(f'| {k} | {d:.2f} |')
  if args.out:
    files.write_json(args.out, {
      'args': dataclasses.asdict(args), 'moved_mm': moved, 'distance_mm': table,
      'seconds': time.perf_counter() - t0, 'hardware': 'CPU, MuJoCo C',
    })  # fmt: skip


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
