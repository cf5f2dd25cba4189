"""A dataset sweep's rendering: each world's cameras drawn (and drawn again
where the cloth covers too little of a frame), and the jitted depth (and
colour) renderer run over a call's worlds in chunks that fit device memory."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline.dataset_config import POSES, Config


def draw_poses(config: Config, keys, seq_idx, attempt: int) -> physsim.Pose:
  """(B, C) camera poses of sequences ``seq_idx``; draw 0 is the one a sweep
  without ``min_coverage`` uses, so turning it on changes only the re-drawn."""

  def one(key, i):
    key = jax.random.fold_in(key, i)
    if attempt:
      key = jax.random.fold_in(key, attempt)
    ranges = POSES[config.poses]
    if not config.garment:
      ranges = ranges.for_cloth(config.cloth_size)
    return physsim.sample_poses(key, config.cameras, ranges)

  return jax.vmap(one)(keys, seq_idx)


def coverage(depth: np.ndarray) -> np.ndarray:
  """(B, C, T, H, W) depth -> (B, C): the least share of cloth pixels in a frame."""
  return (depth > 0).mean(axis=(-1, -2)).min(axis=-1)


def where_cameras(low: np.ndarray, new, old) -> np.ndarray:
  """Per (world, camera): ``new`` where ``low``, else ``old``."""
  return np.where(low.reshape(low.shape + (1,) * (np.ndim(old) - 2)), new, old)


def frame_cameras(config: Config, draw, render, poses, frames, valid):
  """Draws new poses for the cameras of valid worlds whose cloth covers less
  than ``config.min_coverage`` of some frame, until none does or a camera has
  had ``config.pose_draws`` poses, and keeps each camera's best-covered pose
  (a sheet blown flat can stay grazing from every pose); only those cameras'
  frames change. ``render(worlds, poses)`` renders those worlds alone: a few
  worlds of a call are redrawn, and rendering the call's every world for
  each draw cost more than its simulation on a GPU.

  Returns:
    (poses, depth, rgb or None, (B, C) poses drawn per camera, (B, C) coverage,
    or None when ``min_coverage`` is off: the sweep's hot path skips it).
  """
  depth, rgb = frames
  if not config.min_coverage:
    return poses, depth, rgb, None, None
  poses = jax.tree.map(np.array, poses)  # host copies, updated in place
  cover = coverage(depth)
  draws = np.ones(cover.shape, np.int64)
  for attempt in range(1, config.pose_draws):
    low = (cover < config.min_coverage) & np.asarray(valid)[:, None]
    if not low.any():
      break
    worlds = np.flatnonzero(low.any(axis=1))
    some = low[worlds]
    old = jax.tree.map(lambda a: a[worlds], poses)  # noqa: B023 - used at once
    new_poses = jax.tree.map(
      lambda a, o: where_cameras(some, np.asarray(a)[worlds], o),  # noqa: B023
      draw(attempt),
      old,
    )
    new_depth, new_rgb = render(worlds, new_poses)
    new_cover = coverage(new_depth)
    pick = functools.partial(where_cameras, some & (new_cover > cover[worlds]))
    for a, new in zip(poses, jax.tree.map(pick, new_poses, old), strict=True):
      a[worlds] = new
    depth[worlds] = pick(new_depth, depth[worlds])
    cover[worlds] = pick(new_cover, cover[worlds])
    if rgb is not None:
      rgb[worlds] = pick(new_rgb, rgb[worlds])
    draws += low
  return poses, depth, rgb, draws, cover


def renderer(faces, intrinsics, config: Config, mesh=None):
  """The jitted per-batch render stage: (positions, poses, (B,) keys, (B, 3)
  colours) -> depth[, rgb], its worlds split over ``mesh``'s devices."""
  noise = None
  if config.noise:
    try:
      from physsim import sensor  # imported only when used
    except ImportError as e:
      raise ValueError(f'--noise needs physsim.sensor, which is missing ({e})') from e
    noise = sensor.SensorNoise()
  faces = jnp.asarray(faces, jnp.int32)

  def render(positions, poses, keys, colors):
    depth = physsim.render_depth(
      positions, faces, intrinsics, poses, method=config.render_method
    )  # (B, C, T, H, W)
    if noise is not None:  # each world's own key: the same noise on any devices
      depth = jax.vmap(lambda k, d: sensor.apply_noise_frames(k, d, intrinsics, noise))(
        keys, depth
      )
    rgb = None
    if config.rgb:  # a batch mixes materials: one colour per world
      rgb = physsim.render_rgb8(
        positions, faces, intrinsics, poses, colors, method=config.render_method
      )  # (B, C, T, H, W, 3)
    return depth, rgb

  return jax.jit(physsim.devices.shard_worlds(render, mesh))


def render_chunk(config: Config, batch: int, n_devices: int) -> int:
  """Worlds rendered per call: what fits in free device memory (each world's
  frames, colour too, with room for the renderer's buffers), a multiple of
  the device count, at most the batch."""
  pixels = config.cameras * config.frames * config.resolution**2
  per_world = 3 * pixels * (4 + (3 if config.rgb else 0))
  n = physsim.devices.chunk_size(per_world, cap=batch)
  return max(n_devices, n // n_devices * n_devices)


def some_worlds(render, positions, keys, colors):
  """``(worlds, poses) -> render`` of those worlds of a call (indices), seen
  from ``poses``, each with its own noise key and colour."""
  return lambda w, poses: render(positions[w], poses, keys[w], colors[w])


def chunked(render, chunk: int):
  """``render(positions, poses, keys, colors)`` over the worlds in chunks of
  ``chunk`` (the last one padded with its last world, so one compile serves
  every call); its arguments are host arrays, the keys as their key data
  (gathered on the host: a device gather compiles for every count of worlds),
  and depth and colour come back as host arrays."""

  def run(positions, poses, keys, colors):
    b = positions.shape[0]
    depth, rgb = [], []
    for start in range(0, b, chunk):
      idx = np.minimum(np.arange(start, start + chunk), b - 1)
      take = lambda a: np.asarray(a)[idx]  # noqa: B023 - used at once
      d, c = render(
        take(positions),
        jax.tree.map(take, poses),
        jax.random.wrap_key_data(take(keys)),
        take(colors),
      )
      n = min(chunk, b - start)
      depth.append(np.asarray(d)[:n])
      rgb.append(None if c is None else np.asarray(c)[:n])
    return np.concatenate(depth), None if rgb[0] is None else np.concatenate(rgb)

  return run
