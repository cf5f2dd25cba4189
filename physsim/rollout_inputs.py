"""A rollout's inputs: the wind a batch shares, the per-world arrays
(``WorldInputs``: masses, wind, gusts, bending scale), the worlds' gust keys,
the frame plan (substeps a frame, warm-up frames) and when a world blew up
(``physsim.rollout`` runs them)."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from physsim import forces
from physsim.cloth import ClothModel

# A vertex further than this from its rest position, or faster than this, means
# the integration blew up (the cloth is 1 m; real flapping is a few m/s).
MAX_DISPLACEMENT = 5.0  # m
MAX_SPEED = 100.0  # m/s


@dataclasses.dataclass(frozen=True)
class Wind:
  """Wind settings shared by a batch (arrays may carry a leading batch axis).

  Attributes:
    direction: (3,) or (B, 3) flow direction; normalised. Default +y, normal to
      the resting cloth (the paper's tables quote this normal component).
    gust_intensity: RMS relative fluctuation; 0 for steady wind.
    gust_modes: number of frozen-turbulence modes.
  """

  direction: tuple[float, float, float] | np.ndarray = (0.0, 1.0, 0.0)
  gust_intensity: float = 0.0
  gust_modes: int = 8


class WorldInputs(NamedTuple):
  """Per-world arrays a rollout takes (leading axis B; a pytree of JAX arrays).

  Attributes:
    speed: (B,) mean wind speed, m/s.
    direction: (B, 3) unit flow direction.
    bending: (B,) bending scale relative to the model's reference rigidity.
    gusts: ``forces.Gusts`` with a leading B axis.
    body_mass: (B, nbody) MuJoCo body masses, kg.
  """

  speed: jax.Array
  direction: jax.Array
  bending: jax.Array
  gusts: forces.Gusts
  body_mass: jax.Array


def check_wind(wind: Wind) -> np.ndarray:
  """The wind's unit direction(s); raises ValueError on a bad direction or
  gust intensity (host-side, before anything is traced)."""
  direction = np.asarray(wind.direction, np.float64)
  norm = np.linalg.norm(direction, axis=-1, keepdims=True)
  if not np.all(np.isfinite(direction)) or np.any(norm < 1e-9):
    raise ValueError(
      f'wind direction must be finite and non-zero, got {wind.direction}'
    )
  if not (0.0 <= wind.gust_intensity <= 1.0):
    raise ValueError(f'gust_intensity must be in [0, 1], got {wind.gust_intensity}')
  return direction / norm


def world_inputs(
  model: ClothModel,
  bending_scale,
  wind_speed,
  area_weight,
  keys: jax.Array,
  wind: Wind,
  rigidity_ratio=1.0,
) -> WorldInputs:
  """Per-world rollout inputs, traceable (no host round trip).

  Args:
    model: the compiled cloth.
    bending_scale, wind_speed, area_weight: (B,) physical parameters (trusted:
      validate at the boundary, e.g. ``params.validate``).
    keys: (B,) gust keys, one per world.
    wind: shared wind settings (checked with ``check_wind``).
    rigidity_ratio: scalar or (B,): the worlds' fabrics' reference rigidity
      over the model's (``reference_rigidity``), so one compiled model
      simulates every fabric of its mesh.

  Returns:
    ``WorldInputs`` in float32.
  """
  direction = check_wind(wind)
  b = jnp.shape(wind_speed)[0]
  gusts = jax.vmap(
    lambda k: forces.sample_gusts(k, wind.gust_intensity, wind.gust_modes)
  )(keys)
  f32 = lambda a: jnp.asarray(a, jnp.float32)
  return WorldInputs(
    speed=f32(wind_speed),
    direction=jnp.broadcast_to(f32(direction), (b, 3)),
    bending=f32(bending_scale) * f32(rigidity_ratio),
    gusts=jax.tree.map(f32, gusts),
    body_mass=model.body_masses_jax(area_weight),
  )


def world_keys(key, b: int, wind: Wind):
  """(B,) gust keys from one key (split) or B keys (used as given)."""
  if wind.gust_intensity > 0 and key is None:
    raise ValueError('gusty wind needs a PRNG key (simulate(..., key=...))')
  key = jax.random.key(0) if key is None else key
  typed = jnp.issubdtype(key.dtype, jax.dtypes.prng_key)
  if key.ndim == (1 if typed else 2):  # one key per world, used as given
    if key.shape[0] != b:
      raise ValueError(f'got {key.shape[0]} gust keys for {b} worlds')
    return key
  return jax.random.split(key, b)


def frame_plan(model: ClothModel, frames: int, fps: float, warmup: float):
  if frames < 1 or not fps > 0 or warmup < 0:
    raise ValueError(
      f'need frames >= 1, fps > 0, warmup >= 0; got {frames}, {fps}, {warmup}'
    )
  dt = model.config.timestep
  substeps = round(1.0 / (fps * dt))
  if abs(substeps * dt * fps - 1.0) > 1e-6:
    raise ValueError(f'frame period 1/{fps} s is not a multiple of the timestep {dt} s')
  return substeps, round(warmup * fps)


def valid_worlds(positions, rest):
  finite = jnp.all(jnp.isfinite(positions), axis=(1, 2, 3))
  disp = jnp.max(jnp.abs(positions - rest), axis=(1, 2, 3))
  return finite & (disp < MAX_DISPLACEMENT)
