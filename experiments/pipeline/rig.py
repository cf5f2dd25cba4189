"""A recording as a user's rig writes it, from a recipe that is not the estimator's.

Issue 40's confident failure came from a recording with the floor out of view,
a sheet blown back by a strong fan and a camera calibrated in the rig's own
z-up world. This makes such recordings on purpose, with a known truth, so the
intake's choice of "up" and the estimate's interval can be checked on them:

* the cloth: finer mesh, shorter timestep and gustier wind than the
  estimator's simulation (reality is never the estimator's model);
* the camera: a depth camera's own size and rate (640x480 at 30 fps, resampled
  by the intake), its noise set apart from the sensor model the estimator
  applies to its candidates, and only the cloth in view (no floor, no wall);
* the files: 16-bit PNGs in millimetres and an OpenCV camera JSON whose
  ``cam_to_world`` is in the rig's world (z up, turned and shifted from the
  simulator's), one without and one with an IMU's ``"gravity"`` (tilted by
  the accelerometer's error), and ``truth.json``.

``benchmarks/windy_rig.py`` estimates from them; ``tests/experiments/rig_test.py``
keeps them honest.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil

import jax
import numpy as np

import physsim
from physsim import camera, dataset, sensor


@dataclasses.dataclass(frozen=True)
class Recipe:
  """How the rig's recording is made.

  Attributes:
    material: the fabric (its ArcSim bending and density).
    bending_scale: the truth: bending stiffness over the fabric's.
    wind_speed: the truth: mean wind at the cloth, m/s.
    area_weight: the truth: kg/m^2.
    cloth_resolution: vertices per side of the sheet.
    cloth_size: its side, metres.
    timestep: the simulation step, seconds (shorter where the mesh needs it:
      ``physsim.stable_timestep``).
    gust_intensity: the gusts' relative strength.
    frames: frames written.
    fps: the camera's frame rate.
    warmup: seconds simulated before the first frame.
    width: image width, pixels.
    height: image height, pixels.
    focal: focal length, pixels.
    eye: the camera's position in the simulator's world, metres.
    target: the point it looks at, metres (the cloth hangs from z = 1.5 m).
    world_turn_deg: the rig's world turned about z from the simulator's.
    world_shift: and shifted, metres.
    noise: the camera's depth error (unlike the estimator's default model).
    imu_error_deg: the accelerometer's gravity direction error, degrees.
    seed: gusts, depth noise and the IMU's error.
    fan_yaw_deg: the fan's axis turned about the vertical from the cloth's
      normal, degrees (the estimator assumes 0).
    gust_modes: frozen-turbulence modes of the gusts (the estimator's: 8).
    air_drag: drag on the flow along the cloth (the estimator's: 0).
    bending_damping: Rayleigh damping of bending, seconds (the estimator's: 0).
    edge_solref: the edges' constraint time constant, seconds (the
      estimator's: 0.004; longer is a stretchier cloth).
  """

  material: str = 'gray_interlock'
  bending_scale: float = 1.0
  wind_speed: float = 3.52
  area_weight: float = 0.185
  cloth_resolution: int = 41
  cloth_size: float = 1.0
  timestep: float = 1 / 600
  gust_intensity: float = 0.3
  frames: int = 90
  fps: float = 30.0
  warmup: float = 1.0
  width: int = 640
  height: int = 480
  focal: float = 520.0
  eye: tuple[float, float, float] = (0.8, -2.3, 1.45)
  target: tuple[float, float, float] = (0.0, 0.25, 1.05)
  world_turn_deg: float = 30.0
  world_shift: tuple[float, float, float] = (2.0, -1.0, 0.3)
  noise: sensor.SensorNoise = sensor.SensorNoise(
    sigma_a=0.001, sigma_b=0.0025, quantization=0.001, edge_band=3.0,
    native_width=640, dropout_rate=0.01,
  )  # fmt: skip
  imu_error_deg: float = 0.5
  seed: int = 11
  fan_yaw_deg: float = 0.0
  gust_modes: int = 8
  air_drag: float = 0.0
  bending_damping: float = 0.0
  edge_solref: float = 0.004

  @property
  def truth(self) -> dict:
    return dict(
      bending_scale=self.bending_scale,
      wind_speed=self.wind_speed,
      area_weight=self.area_weight,
    )

  def intrinsics(self) -> camera.Intrinsics:
    return camera.Intrinsics.from_pinhole(
      self.width, self.height, self.focal, self.focal,
      (self.width - 1) / 2 - 1.5, (self.height - 1) / 2 + 1.5,
    )  # fmt: skip


def in_world(world: physsim.Mismatch) -> Recipe:
  """The rig's recipe with its simulator unlike the estimator's as ``world``
  is (a ``physsim.Mismatch``: the fan's turn and gusts, drag, damped bending,
  the edges' time constant)."""
  return Recipe(
    fan_yaw_deg=world.fan_yaw_deg, gust_modes=world.gust_modes,
    air_drag=world.air_drag, bending_damping=world.bending_damping,
    edge_solref=Recipe.edge_solref * world.edge_solref_scale,
  )  # fmt: skip


# Issue 39, item 6: the simulator itself unlike the estimator's, as the world
# is (``physsim.mismatch.WORLD``, the dataset sweeps' ``physics='mismatched'``);
# 'mismatched_b' a second such world (``physsim.mismatch.WORLD_B``), for
# checks held out in the physics too.
MISMATCHED = in_world(physsim.mismatch.WORLD)
RECIPES = {
  'default': Recipe(),
  'mismatched': MISMATCHED,
  'mismatched_b': in_world(physsim.mismatch.WORLD_B),
}

# The smallest that the intake still fits (a 12-vertex cloth's far corner is
# lost to the sensor's edge band and its pins come out 0.78 m apart).
SMOKE = Recipe(
  cloth_resolution=17, frames=16, fps=20.0, warmup=0.5,
  width=320, height=240, focal=260.0,
)  # fmt: skip


def with_fields(recipe: Recipe, text: str) -> Recipe:
  """``recipe`` with ``text``'s comma-separated ``field=value`` pairs: a number
  parsed as its field's type, a point (``eye``, ``target``, ``world_shift``)
  written ``x:y:z`` in metres, a number of the depth noise written
  ``noise.<field>`` (e.g. ``noise.sigma_b=0.0015``, the estimator's own), so
  that a study moves the camera or changes the physics or the sensor without
  a recipe of its own.

  Raises:
    ValueError: naming ``--recipe_fields``, the item and the fields it may
      change.
  """
  fields = _numbers(recipe)
  points = sorted(
    f.name for f in dataclasses.fields(recipe)
    if isinstance(getattr(recipe, f.name), tuple) and len(getattr(recipe, f.name)) == 3
  )  # fmt: skip
  noise = {f'noise.{n}': t for n, t in _numbers(recipe.noise).items()}
  kinds = {**fields, **noise, **dict.fromkeys(points, float)}
  out, sensed = {}, {}
  for item in (x for x in text.split(',') if x):
    name, _, value = item.partition('=')
    kind = kinds.get(name)
    if kind is None or not value:
      raise ValueError(
        f'--recipe_fields={text}: {item!r} is not field=number of '
        f'{sorted(fields) + sorted(noise)} or field=x:y:z of {points}'
      )
    parts = value.split(':') if name in points else [value]
    try:
      got = tuple(kind(v) for v in parts)
    except ValueError:
      raise ValueError(
        f'--recipe_fields={text}: {value!r} is not a {kind.__name__}'
      ) from None
    if not np.all(np.isfinite(got)) or len(got) != (3 if name in points else 1):
      shape = 'three finite numbers x:y:z' if name in points else 'a finite number'
      raise ValueError(f'--recipe_fields={text}: {value!r} is not {shape}')
    if name in noise:
      sensed[name.removeprefix('noise.')] = got[0]
    else:
      out[name] = got if name in points else got[0]
  if sensed:
    try:
      out['noise'] = dataclasses.replace(recipe.noise, **sensed)
    except ValueError as e:  # the sensor's own range checks
      raise ValueError(f'--recipe_fields={text}: {e}') from None
  return dataclasses.replace(recipe, **out)


def _numbers(obj) -> dict[str, type]:
  """A dataclass's int and float fields, each with its type."""
  return {
    f.name: type(getattr(obj, f.name))
    for f in dataclasses.fields(obj)
    if type(getattr(obj, f.name)) in (int, float)
  }


def drawn_fabric(recipe: Recipe, rng: np.random.Generator) -> Recipe:
  """``recipe`` with its bending scale and area weight drawn uniform in the
  unit cube of its material's search box (the estimate's prior), as the
  calibration tables draw their recordings' (``calibration_config.truths``):
  their coverage is an average over that prior, not a promise at its centre
  (the recipe's own fabric)."""
  p = physsim.from_unit(
    rng.uniform(-1.0, 1.0, 3), physsim.search_space(recipe.material)
  )
  return dataclasses.replace(
    recipe, bending_scale=float(p.bending_scale), area_weight=float(p.area_weight)
  )


def rig_from_sim(recipe: Recipe) -> np.ndarray:
  """(4, 4) the rig's world from the simulator's: a turn about z, a shift."""
  a = np.deg2rad(recipe.world_turn_deg)
  m = np.eye(4)
  m[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
  m[:3, 3] = recipe.world_shift
  return m


def _tilted(v: np.ndarray, deg: float, rng: np.random.Generator) -> np.ndarray:
  """``v`` turned by ``deg`` about a random axis normal to it."""
  axis = np.cross(v, rng.standard_normal(3))
  axis /= np.linalg.norm(axis)
  a = np.deg2rad(deg)
  return (
    v * np.cos(a) + np.cross(axis, v) * np.sin(a) + axis * (axis @ v) * (1 - np.cos(a))
  )


def depth(recipe: Recipe, backend: str = 'c') -> np.ndarray:
  """(T, H, W) the camera's noisy depth in metres (0: no return)."""
  if recipe.wind_speed <= 0 or recipe.area_weight <= 0 or recipe.bending_scale <= 0:
    raise ValueError(f'the truth must be positive, got {recipe.truth}')
  mesh = physsim.square(recipe.cloth_resolution, recipe.cloth_size)
  physics = physsim.Mismatch(
    fan_yaw_deg=recipe.fan_yaw_deg, gust_modes=recipe.gust_modes,
    air_drag=recipe.air_drag, bending_damping=recipe.bending_damping,
    edge_solref_scale=recipe.edge_solref / Recipe.edge_solref,
  )  # fmt: skip
  sim_config = physsim.config_for_mesh(
    mesh, recipe.fps, recipe.timestep, **physics.sim_fields()
  )
  model = physsim.build(mesh, recipe.material, sim_config)
  wind = physics.wind(recipe.gust_intensity)
  out = physsim.simulate(
    model, physsim.params.make(**recipe.truth), frames=recipe.frames,
    fps=recipe.fps, warmup=recipe.warmup, wind=wind,
    key=jax.random.key(recipe.seed)[None], backend=backend, workers=1,
  )  # fmt: skip
  intr = recipe.intrinsics()
  pose = camera.look_at(recipe.eye, recipe.target)
  render = physsim.make_depth_renderer(mesh.faces, intr)
  poses = jax.tree.map(lambda a: np.asarray(a)[None, None], pose)
  clean = np.asarray(render(np.asarray(out.positions), poses))[0, 0]
  key = jax.random.fold_in(jax.random.key(recipe.seed), 1)
  return np.asarray(sensor.apply_noise_frames(key, clean, intr, recipe.noise))


def camera_files(recipe: Recipe) -> tuple[dict, dict]:
  """The OpenCV camera JSON without and with the IMU's gravity."""
  pose = camera.look_at(recipe.eye, recipe.target)
  r_sim = np.asarray(pose.rotation, np.float64)
  cam_to_sim = np.eye(4)
  cam_to_sim[:3, :3] = r_sim
  cam_to_sim[:3, 3] = np.asarray(pose.position, np.float64)
  intr = recipe.intrinsics()
  cam = {
    'width': recipe.width, 'height': recipe.height, 'fx': intr.fx, 'fy': intr.fy,
    'cx': intr.cx, 'cy': intr.cy, 'fps': recipe.fps,
    'cam_to_world': (rig_from_sim(recipe) @ cam_to_sim).tolist(),
  }  # fmt: skip
  down = r_sim.T @ np.array([0.0, 0.0, -9.81])  # what the accelerometer reads
  rng = np.random.default_rng([recipe.seed, 40])
  gravity = _tilted(down, recipe.imu_error_deg, rng)
  return cam, dict(cam, gravity=gravity.tolist())


def write(recipe: Recipe, out: str, backend: str = 'c') -> dict:
  """Writes the recording under ``out``: ``depth/NNNN.png`` (16-bit mm),
  ``camera.json``, ``camera_imu.json``, ``truth.json`` and ``recipe.json``.

  Made in ``out.tmp`` and renamed, so ``out`` is whole or absent; an ``out``
  that holds this recipe's recording is kept (a rerun is free), one that holds
  another is refused.

  Returns:
    The paths written, by name.
  """
  paths = {
    'depth': os.path.join(out, 'depth'),
    'camera': os.path.join(out, 'camera.json'),
    'camera_imu': os.path.join(out, 'camera_imu.json'),
    'truth': os.path.join(out, 'truth.json'),
  }
  described = json.loads(json.dumps(dataclasses.asdict(recipe)))
  recipe_path = os.path.join(out, 'recipe.json')
  if os.path.exists(out):
    # a field the recipe gained since is at its default in an older recording
    defaults = json.loads(json.dumps(dataclasses.asdict(Recipe())))
    if os.path.isfile(recipe_path):
      if {**defaults, **dataset.read_json(recipe_path)} == described:
        return paths
    raise ValueError(f'{out}: exists and holds no recording of this recipe')
  frames = depth(recipe, backend)
  tmp = f'{out}.tmp'
  shutil.rmtree(tmp, ignore_errors=True)
  os.makedirs(os.path.join(tmp, 'depth'))
  for t, f in enumerate(dataset.depth_to_mm(frames)):
    dataset.imwrite(os.path.join(tmp, 'depth', f'{t:04d}.png'), f)
  cam, cam_imu = camera_files(recipe)
  for name, obj in [
    ('camera', cam), ('camera_imu', cam_imu), ('truth', recipe.truth),
    ('recipe', described),
  ]:  # fmt: skip
    with open(os.path.join(tmp, f'{name}.json'), 'w') as f:
      json.dump(obj, f, indent=1)
  os.rename(tmp, out)
  return paths
