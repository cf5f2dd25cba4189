"""A structured-light depth sensor's errors (Asus Xtion / Kinect v1 style).

Applied to a clean z-depth image (0 = invalid), in this order:

1. Missing pixels where the clean depth jumps: a band ``edge_band`` of the
   sensor's native pixels wide (``native_width`` across the image) around
   every jump to a neighbour whose depth differs by more than
   ``edge_threshold`` (or to an invalid pixel, when ``drop_silhouette``) is
   dropped, as the projector's pattern is shadowed or smeared there. A render
   ``W`` pixels wide is taken as a nearest-neighbour sample of the native
   image, so the band is ``b = edge_band W / native_width`` render pixels:
   pixels within Chebyshev distance ``floor(b)`` of a jump always go, and those
   at distance ``floor(b) + 1`` each go with probability ``b - floor(b)``
   (the chance that their sample point falls inside the band). The other
   steps are already independent of the render's resolution.
2. Missing pixels at grazing angles: the surface normal is estimated from the
   back-projected depth image by central differences; pixels whose viewing ray
   makes more than ``max_incidence_deg`` with the normal are dropped.
3. Axial noise: z + sigma(z) N(0, 1), sigma(z) = sigma_a + sigma_b z^2.
   The defaults fit Nguyen, Izadi and Lovell (3DIMPVT 2012), who measured a
   Kinect v1's axial sigma = 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2, over 1-3 m:
   1.9 mm at 1 m, 6.4 mm at 2 m, 13.9 mm at 3 m.
4. Quantisation to ``quantization`` metres (the Xtion reports whole mm).
5. Random dropouts, each valid pixel independently with ``dropout_rate``.

Invalid pixels stay 0.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from physsim.camera import Intrinsics, pixel_rays


@dataclasses.dataclass(frozen=True)
class SensorNoise:
  """Depth sensor error settings (hashable, static).

  Attributes:
    sigma_a: constant part of the axial noise std, metres.
    sigma_b: quadratic part, metres per metre^2 (sigma = a + b z^2).
    quantization: depth step, metres (0 disables).
    edge_threshold: depth jump to a neighbour that drops a pixel, metres.
    edge_band: width of the dropped band around a depth jump, in the sensor's
      native pixels (0 disables edge dropping); see `edge_band_pixels`.
    native_width: the sensor's pixel count across the image width (640 for
      the Kinect v1 / Xtion).
    drop_silhouette: also drop valid pixels next to invalid (background) ones.
    max_incidence_deg: largest angle between viewing ray and surface normal
      kept, degrees (90 disables).
    dropout_rate: probability that a valid pixel goes missing at random.
  """

  sigma_a: float = 0.00035
  sigma_b: float = 0.0015
  quantization: float = 0.001
  edge_threshold: float = 0.05
  edge_band: float = 2.5
  native_width: int = 640
  drop_silhouette: bool = True
  max_incidence_deg: float = 78.0
  dropout_rate: float = 0.005

  def __post_init__(self):
    for name in ('sigma_a', 'sigma_b', 'quantization', 'edge_threshold'):
      if getattr(self, name) < 0:
        raise ValueError(f'SensorNoise.{name} must be >= 0, got {getattr(self, name)}')
    band = self.edge_band
    if (
      isinstance(band, bool)
      or not isinstance(band, int | float)
      or not (math.isfinite(band) and band >= 0)
    ):
      raise ValueError(f'SensorNoise.edge_band must be a float >= 0, got {band!r}')
    width = self.native_width
    if isinstance(width, bool) or not isinstance(width, int) or width < 1:
      raise ValueError(
        f'SensorNoise.native_width must be a positive int, got {width!r}'
      )
    if not 0 < self.max_incidence_deg <= 90:
      raise ValueError(
        f'SensorNoise.max_incidence_deg must be in (0, 90], got {self.max_incidence_deg}'
      )
    if not 0 <= self.dropout_rate <= 1:
      raise ValueError(
        f'SensorNoise.dropout_rate must be in [0, 1], got {self.dropout_rate}'
      )

  def sigma(self, z):
    """Axial noise std at depth ``z`` (metres), same shape."""
    return self.sigma_a + self.sigma_b * jnp.square(z)


def _shift(a, dy: int, dx: int, fill):
  """a[y + dy, x + dx], ``fill`` outside the image."""
  h, w = a.shape[:2]
  pad = [(abs(dy), abs(dy)), (abs(dx), abs(dx))] + [(0, 0)] * (a.ndim - 2)
  p = jnp.pad(a, pad, constant_values=fill)
  return p[abs(dy) + dy : abs(dy) + dy + h, abs(dx) + dx : abs(dx) + dx + w]


_SNAP = 1e-9  # band widths this close to a whole pixel count are whole


def edge_band_pixels(config: SensorNoise, width: int) -> tuple[int, float]:
  """The dropped band at a render ``width`` pixels across, as ``(r, frac)``.

  The band is ``b = edge_band * width / native_width`` render pixels, split
  into ``r = floor(b)`` (pixels within Chebyshev distance ``r`` of a jump are
  always dropped) and ``frac = b - r`` (the chance that a pixel at distance
  ``r + 1`` is dropped). Within ``1e-9`` of a whole number, ``b`` is taken as
  that number (``frac = 0``), so float rounding never adds a ring.
  """
  b = config.edge_band * width / config.native_width
  r = math.floor(b + _SNAP)
  frac = b - r
  return r, (frac if frac > _SNAP else 0.0)


def _jump_bands(
  depth, config: SensorNoise, intrinsics: Intrinsics | None, r: int, ring: bool
):
  """(H, W) bool ``(near, ring)``, from one pass over the offsets.

  ``near``: valid pixels with a jump within Chebyshev distance ``r``; ``ring``:
  valid pixels whose nearest jump is at distance exactly ``r + 1`` (only looked
  for when ``ring`` is true; all False otherwise).
  """
  valid = depth > 0
  slope = 0.0
  if intrinsics is not None:
    tan = math.tan(math.radians(min(config.max_incidence_deg, 89.0)))
    slope = tan / min(intrinsics.fx, intrinsics.fy)
  reach = r + 1 if ring else r
  near = jnp.zeros(depth.shape, bool)
  far = jnp.zeros(depth.shape, bool)  # jumps at distance exactly r + 1
  for dy in range(-reach, reach + 1):
    for dx in range(-reach, reach + 1):
      if dy == 0 and dx == 0:
        continue
      n = _shift(depth, dy, dx, 0.0)
      n_valid = n > 0
      limit = jnp.maximum(
        config.edge_threshold, slope * math.hypot(dy, dx) * jnp.maximum(n, depth)
      )
      jump = n_valid & (jnp.abs(n - depth) > limit)
      if config.drop_silhouette:
        jump = jump | ~n_valid
      if max(abs(dy), abs(dx)) <= r:
        near = near | jump
      else:
        far = far | jump
  return valid & near, valid & far & ~near


def edge_masks(
  depth, config: SensorNoise = SensorNoise(), intrinsics: Intrinsics | None = None
) -> tuple[jax.Array, jax.Array, float]:
  """Valid pixels near a depth jump (or the silhouette): ``(near, ring, frac)``.

  ``near`` (H, W) bool: pixels always dropped (a jump within Chebyshev distance
  ``r``); ``ring`` (H, W) bool: pixels whose nearest jump is at distance
  exactly ``r + 1``, each dropped with probability ``frac`` (all False when
  ``frac == 0``). ``r`` and ``frac`` come from `edge_band_pixels` at the
  render's width, ``depth.shape[1]`` (equal to ``intrinsics.width`` wherever
  `apply_noise` is used, and known without intrinsics too).

  With ``intrinsics``, a jump must also exceed what a continuous surface seen at
  the largest kept incidence angle spans between the two pixels
  (``d z tan(max_incidence) / f`` for ``d`` pixels apart): otherwise, at low
  resolutions or far away, a merely tilted cloth would count as an edge.
  Without them the fixed ``edge_threshold`` alone decides.
  """
  r, frac = edge_band_pixels(config, depth.shape[1])
  near, ring = _jump_bands(depth, config, intrinsics, r, frac > 0)
  return near, ring, frac


def edge_mask(
  depth, config: SensorNoise = SensorNoise(), intrinsics: Intrinsics | None = None
) -> jax.Array:
  """(H, W) bool: valid pixels always dropped near a depth jump.

  The ``near`` mask of `edge_masks`: a jump within ``floor(b)`` render pixels,
  ``b`` the band's width at this render's width ``depth.shape[1]``.
  """
  return edge_masks(depth, config, intrinsics)[0]


def incidence_cos(depth, intrinsics: Intrinsics) -> jax.Array:
  """(H, W) |cos| of the angle between viewing ray and estimated normal.

  1.0 where the normal cannot be estimated (an invalid 4-neighbour).
  """
  h, w = depth.shape
  ray = pixel_rays(intrinsics, h, w)
  p = ray * depth[..., None]  # (H, W, 3) camera-frame points
  du = _shift(p, 0, 1, 0.0) - _shift(p, 0, -1, 0.0)
  dv = _shift(p, 1, 0, 0.0) - _shift(p, -1, 0, 0.0)
  n = jnp.cross(du, dv)
  ok = (
    (_shift(depth, 0, 1, 0.0) > 0)
    & (_shift(depth, 0, -1, 0.0) > 0)
    & (_shift(depth, 1, 0, 0.0) > 0)
    & (_shift(depth, -1, 0, 0.0) > 0)
  )
  nn = jnp.linalg.norm(n, axis=-1) * jnp.linalg.norm(ray, axis=-1)
  cos = jnp.abs(jnp.sum(n * ray, axis=-1)) / jnp.maximum(nn, 1e-20)
  return jnp.where(ok & (nn > 0), cos, 1.0)


def apply_noise(
  key: jax.Array, depth, intrinsics: Intrinsics, config: SensorNoise = SensorNoise()
) -> jax.Array:
  """Corrupts one clean depth image as the sensor would.

  Args:
    key: PRNG key: ``jax.random.split(key)`` gives the axial noise's and the
      dropouts' keys, ``jax.random.fold_in(key, 1)`` the edge ring's (drawn
      only when the band is not a whole number of render pixels).
    depth: (H, W) clean z-depth, metres, 0 = invalid.
    intrinsics: the camera's intrinsics (for normals and the edge jump rule).
    config: the error model.

  Returns:
    (H, W) float32 noisy depth, 0 = invalid. Vmap over frames/cameras with
    split keys.
  """
  k_noise, k_drop = jax.random.split(key)
  depth = jnp.asarray(depth, jnp.float32)
  if depth.shape != (intrinsics.height, intrinsics.width):
    raise ValueError(
      f'depth must be (H, W) = {(intrinsics.height, intrinsics.width)}, got {depth.shape}'
    )
  keep = depth > 0
  if config.edge_band > 0:
    near, ring, frac = edge_masks(depth, config, intrinsics)
    keep = keep & ~near
    if frac > 0:  # its own key, so k_noise and k_drop never depend on the band
      k_ring = jax.random.fold_in(key, 1)
      keep = keep & ~(ring & jax.random.bernoulli(k_ring, frac, depth.shape))
  if config.max_incidence_deg < 90:
    cos_max = math.cos(math.radians(config.max_incidence_deg))
    keep = keep & (incidence_cos(depth, intrinsics) >= cos_max)
  z = depth + config.sigma(depth) * jax.random.normal(k_noise, depth.shape, jnp.float32)
  if config.quantization > 0:
    z = jnp.round(z / config.quantization) * config.quantization
  if config.dropout_rate > 0:
    keep = keep & ~jax.random.bernoulli(k_drop, config.dropout_rate, depth.shape)
  return jnp.where(keep & (z > 0), z, 0.0)


def apply_noise_frames(
  key: jax.Array, frames, intrinsics: Intrinsics, config: SensorNoise = SensorNoise()
) -> jax.Array:
  """`apply_noise` over any leading axes of ``frames`` (..., H, W).

  Frame ``i`` of the flattened batch uses ``jax.random.split(key, n)[i]``.
  """
  flat = frames.reshape(-1, *frames.shape[-2:])
  keys = jax.random.split(key, flat.shape[0])
  out = jax.vmap(lambda k, d: apply_noise(k, d, intrinsics, config))(keys, flat)
  return out.reshape(frames.shape)
