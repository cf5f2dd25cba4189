"""Pinhole depth cameras: intrinsics, poses, look-at and random pose sampling.

Conventions (OpenCV): a camera looks along its +z axis, x to the right, y down.
A `Pose` holds the camera-to-world rotation (its columns are the camera axes in
world coordinates) and the camera centre. Pixel centres sit at integer
coordinates, so pixel (u, v) = (0, 0) is the top-left pixel's centre and the
image spans [-0.5, W - 0.5] x [-0.5, H - 0.5]; the field of view covers that
whole span.

The scene: the square cloth hangs in the x-z plane (x in [-0.5, 0.5] m, z in
[0.5, 1.5] m) and the wind pushes it toward +y, so cameras stand on the -y side
looking toward +y.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


@dataclasses.dataclass(frozen=True)
class Intrinsics:
  """A pinhole camera's image size and field of view (hashable, static).

  The defaults are the paper's Asus Xtion (58 x 45 degrees) at 256 x 256. The
  focal lengths are held as fields of view and the principal point as a share
  of the image, so resizing a video (``resized``) keeps the same camera. A
  camera in OpenCV's terms (fx, fy, cx, cy in pixels) is ``from_pinhole``.

  Attributes:
    width: image width, pixels.
    height: image height, pixels.
    fov_x_deg: 2 atan(width / (2 fx)), degrees (the horizontal field of view
      when the principal point is centred).
    fov_y_deg: 2 atan(height / (2 fy)), degrees.
    principal_x: the principal point's column as a share of the image width,
      measured from the image's left edge: (cx + 0.5) / width; 0.5 is centred.
    principal_y: its row as a share of the height: (cy + 0.5) / height.
  """

  width: int = 256
  height: int = 256
  fov_x_deg: float = 58.0
  fov_y_deg: float = 45.0
  principal_x: float = 0.5
  principal_y: float = 0.5

  def __post_init__(self):
    for name in ('width', 'height'):
      v = getattr(self, name)
      if not isinstance(v, int | np.integer) or v < 1:
        raise ValueError(f'Intrinsics.{name} must be a positive int, got {v!r}')
    for name in ('fov_x_deg', 'fov_y_deg'):
      v = getattr(self, name)
      if not 0.0 < v < 180.0:
        raise ValueError(f'Intrinsics.{name} must be in (0, 180) degrees, got {v!r}')
    for name in ('principal_x', 'principal_y'):
      v = getattr(self, name)
      if not -1.0 < v < 2.0:
        raise ValueError(
          f'Intrinsics.{name} must be a share of the image near [0, 1], got {v!r}'
        )

  @classmethod
  def from_pinhole(cls, width, height, fx, fy, cx, cy) -> Intrinsics:
    """OpenCV's pinhole camera (focal lengths and principal point in pixels,
    pixel centres at integer coordinates)."""
    for name, v in (('fx', fx), ('fy', fy)):
      if not (math.isfinite(v) and v > 0):
        raise ValueError(f'{name} must be a positive focal length in pixels, got {v!r}')
    for name, v in (('cx', cx), ('cy', cy)):
      if not math.isfinite(v):
        raise ValueError(f'{name} must be finite, got {v!r}')
    return cls(
      width=int(width),
      height=int(height),
      fov_x_deg=math.degrees(2 * math.atan(0.5 * width / fx)),
      fov_y_deg=math.degrees(2 * math.atan(0.5 * height / fy)),
      principal_x=(cx + 0.5) / width,
      principal_y=(cy + 0.5) / height,
    )

  def resized(self, width: int, height: int) -> Intrinsics:
    """The same camera seeing the image resampled to ``width`` x ``height``."""
    return dataclasses.replace(self, width=int(width), height=int(height))

  @property
  def fx(self) -> float:
    """Horizontal focal length, pixels."""
    return 0.5 * self.width / math.tan(math.radians(self.fov_x_deg) / 2)

  @property
  def fy(self) -> float:
    """Vertical focal length, pixels."""
    return 0.5 * self.height / math.tan(math.radians(self.fov_y_deg) / 2)

  @property
  def cx(self) -> float:
    """Principal point column, pixels."""
    return self.principal_x * self.width - 0.5

  @property
  def cy(self) -> float:
    """Principal point row, pixels."""
    return self.principal_y * self.height - 0.5

  def matrix(self) -> np.ndarray:
    """(3, 3) float64 camera matrix K, mapping camera coordinates to pixels."""
    return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

  def to_dict(self) -> dict[str, Any]:
    """JSON-ready fields."""
    return dataclasses.asdict(self)

  @classmethod
  def from_dict(cls, d: dict[str, Any]) -> Intrinsics:
    """Inverse of `to_dict`. The fields of view are required (a camera is
    never silently given the default's); unknown keys are a ValueError."""
    fields = {f.name for f in dataclasses.fields(cls)}
    extra = set(d) - fields
    if extra:
      raise ValueError(f'Intrinsics: unknown fields {sorted(extra)}')
    missing = [f for f in ('fov_x_deg', 'fov_y_deg') if f not in d]
    if missing:
      raise ValueError(f'Intrinsics: missing {missing}')
    return cls(**{f: type(getattr(cls, f))(d[f]) for f in fields if f in d})


def pixel_rays(intrinsics: Intrinsics, height: int, width: int) -> jax.Array:
  """(height, width, 3) float32 ray of every pixel centre in the camera frame,
  scaled to unit z (a pixel of depth d sees the point ``d * ray``), with the
  focal lengths and principal point of ``intrinsics`` as they are."""
  v, u = jnp.meshgrid(
    jnp.arange(height, dtype=jnp.float32),
    jnp.arange(width, dtype=jnp.float32),
    indexing='ij',
  )
  return jnp.stack(
    [
      (u - intrinsics.cx) / intrinsics.fx,
      (v - intrinsics.cy) / intrinsics.fy,
      jnp.ones_like(u),
    ],
    axis=-1,
  )


class Pose(NamedTuple):
  """Camera pose(s), a pytree; leading axes are batch axes.

  Attributes:
    rotation: (..., 3, 3) camera-to-world rotation; columns are the camera's x
      (right), y (down) and z (forward) axes in world coordinates.
    position: (..., 3) camera centre in world coordinates, metres.
  """

  rotation: Any
  position: Any


def world_to_camera(pose: Pose) -> jax.Array:
  """The (..., 4, 4) extrinsic matrix [R^T | -R^T p] mapping world to camera."""
  r = jnp.asarray(pose.rotation)
  p = jnp.asarray(pose.position)
  rt = jnp.swapaxes(r, -1, -2)
  t = -jnp.einsum('...ij,...j->...i', rt, p)
  top = jnp.concatenate([rt, t[..., None]], axis=-1)
  bottom = jnp.broadcast_to(
    jnp.array([0.0, 0.0, 0.0, 1.0], top.dtype), top.shape[:-2] + (1, 4)
  )
  return jnp.concatenate([top, bottom], axis=-2)


def pose_to_dict(pose: Pose) -> dict[str, list]:
  """JSON-ready nested lists (any leading batch axes kept)."""
  return {
    'rotation': np.asarray(pose.rotation, np.float64).tolist(),
    'position': np.asarray(pose.position, np.float64).tolist(),
  }


def pose_from_dict(d: dict[str, Any]) -> Pose:
  """Inverse of `pose_to_dict`, as float32 NumPy arrays."""
  try:
    r = np.asarray(d['rotation'], np.float32)
    p = np.asarray(d['position'], np.float32)
  except KeyError as e:
    raise ValueError(f'pose dict lacks field {e}') from None
  if r.shape[-2:] != (3, 3) or p.shape[-1:] != (3,) or r.shape[:-2] != p.shape[:-1]:
    raise ValueError(
      f'pose dict: rotation {r.shape} and position {p.shape} do not match '
      '(..., 3, 3) and (..., 3)'
    )
  return Pose(r, p)


def _normalize(v):
  return v / jnp.linalg.norm(v, axis=-1, keepdims=True)


def look_at(eye, target, up=(0.0, 0.0, 1.0), roll_deg=0.0) -> Pose:
  """A camera at ``eye`` looking at ``target`` with the image's up along ``up``.

  Broadcasts over leading axes. ``up`` must not be parallel to the view
  direction.

  Args:
    eye: (..., 3) camera centre, metres.
    target: (..., 3) point on the optical axis.
    up: (..., 3) world direction that appears upward in the image.
    roll_deg: (...) rotation about the optical axis, degrees; positive turns the
      camera's x axis toward its y axis (right toward down).

  Returns:
    Pose with rotation (..., 3, 3) and position (..., 3).
  """
  eye = jnp.asarray(eye, jnp.float32)
  target = jnp.asarray(target, jnp.float32)
  up = jnp.asarray(up, jnp.float32)
  forward = _normalize(target - eye)
  right = _normalize(jnp.cross(forward, up))
  down = jnp.cross(forward, right)
  roll = jnp.deg2rad(jnp.asarray(roll_deg, jnp.float32))[..., None]
  c, s = jnp.cos(roll), jnp.sin(roll)
  # Rotate the x/y axes about the forward axis.
  x = c * right + s * down
  y = -s * right + c * down
  x, y, forward = jnp.broadcast_arrays(x, y, forward)
  rotation = jnp.stack([x, y, forward], axis=-1)
  position = jnp.broadcast_to(eye, rotation.shape[:-1])
  return Pose(rotation, position)


@dataclasses.dataclass(frozen=True)
class PoseRanges:
  """Uniform ranges of random camera poses around a target point.

  The camera sits at ``target + distance * (sin(az) cos(el), -cos(az) cos(el),
  sin(el))``: azimuth 0 is straight in front of the cloth (on the -y side),
  positive azimuth moves the camera toward +x and positive elevation raises it.
  It looks at the (jittered) target with world +z up, then rolls.

  The defaults keep the whole 1 m cloth, swung up to 0.5 m toward +y, inside a
  58 x 45 degree view (the box x in [-0.5, 0.5], y in [0, 0.5], z in [0.5, 1.5]
  stays in view; closer than ~1.75 m its corners can leave it). Evaluation poses (`PoseRanges.evaluation()`) lie in other
  azimuth bands and farther away, so no evaluation pose is a training pose.

  Attributes:
    distance: (min, max) camera-to-target distance, metres.
    azimuth_deg: (min, max) azimuth, degrees.
    elevation_deg: (min, max) elevation, degrees.
    roll_deg: (min, max) roll about the optical axis, degrees.
    target: nominal look-at point, metres (the cloth centre, a little downwind).
    target_jitter: half-width of a uniform box jitter of the target, metres.
    mirror_azimuth: if True, the azimuth's sign is flipped at random, so
      ``azimuth_deg`` describes two bands, [min, max] and [-max, -min].
  """

  distance: tuple[float, float] = (1.8, 2.5)
  azimuth_deg: tuple[float, float] = (-25.0, 25.0)
  elevation_deg: tuple[float, float] = (-10.0, 20.0)
  roll_deg: tuple[float, float] = (-3.0, 3.0)
  target: tuple[float, float, float] = (0.0, 0.15, 1.0)
  target_jitter: float = 0.03
  mirror_azimuth: bool = False

  def __post_init__(self):
    for name in ('distance', 'azimuth_deg', 'elevation_deg', 'roll_deg'):
      lo, hi = getattr(self, name)
      if not lo <= hi:
        raise ValueError(f'PoseRanges.{name} must be (min, max), got {(lo, hi)}')
    if not self.distance[0] > 0:
      raise ValueError(f'PoseRanges.distance must be > 0 m, got {self.distance}')
    if not -90 < self.elevation_deg[0] <= self.elevation_deg[1] < 90:
      raise ValueError(
        f'PoseRanges.elevation_deg must lie in (-90, 90), got {self.elevation_deg}'
      )
    if self.target_jitter < 0:
      raise ValueError(
        f'PoseRanges.target_jitter must be >= 0 m, got {self.target_jitter}'
      )

  @classmethod
  def evaluation(cls) -> PoseRanges:
    """Poses disjoint from the default (training) ranges, for held-out tests.

    Azimuth |az| in [30, 40] degrees (training uses |az| <= 25) and distance
    2.6-3.0 m (training 1.8-2.5 m); elevation and roll stay in the same
    ranges, since the real camera is on a tripod at about cloth height.
    """
    return cls(distance=(2.6, 3.0), azimuth_deg=(30.0, 40.0), mirror_azimuth=True)

  def for_cloth(self, size: float, height: float = 1.5) -> PoseRanges:
    """These ranges for a ``size`` m square whose top edge is at ``height``:
    distances, the target's offsets and its jitter scaled by ``size`` about
    the top edge's midpoint, so a 20 cm swatch fills the view as the 1 m sheet
    does (angles unchanged)."""
    if not size > 0:
      raise ValueError(f'cloth size must be > 0 m, got {size}')
    tx, ty, tz = self.target
    return dataclasses.replace(
      self,
      distance=(self.distance[0] * size, self.distance[1] * size),
      target=(tx * size, ty * size, height - (height - tz) * size),
      target_jitter=self.target_jitter * size,
    )

  def to_dict(self) -> dict[str, Any]:
    """JSON-ready fields."""
    return dataclasses.asdict(self)


def sample_poses(key: jax.Array, n: int, ranges: PoseRanges = PoseRanges()) -> Pose:
  """``n`` random camera poses, reproducible by ``key``.

  Args:
    key: PRNG key.
    n: number of poses (a Python int).
    ranges: the pose distribution.

  Returns:
    Pose with rotation (n, 3, 3) and position (n, 3), float32.
  """
  k_dist, k_az, k_sign, k_el, k_roll, k_target = jax.random.split(key, 6)

  def uniform(k, lo_hi, shape=(n,)):
    return jax.random.uniform(k, shape, jnp.float32, *lo_hi)

  dist = uniform(k_dist, ranges.distance)
  az = jnp.deg2rad(uniform(k_az, ranges.azimuth_deg))
  if ranges.mirror_azimuth:
    az = jnp.where(jax.random.bernoulli(k_sign, 0.5, (n,)), az, -az)
  el = jnp.deg2rad(uniform(k_el, ranges.elevation_deg))
  roll = uniform(k_roll, ranges.roll_deg)
  j = ranges.target_jitter
  target = jnp.asarray(ranges.target, jnp.float32) + uniform(k_target, (-j, j), (n, 3))
  offset = jnp.stack(
    [jnp.sin(az) * jnp.cos(el), -jnp.cos(az) * jnp.cos(el), jnp.sin(el)], axis=-1
  )
  return look_at(target + dist[:, None] * offset, target, roll_deg=roll)
