"""Depth (or colour) frames to network inputs: one definition for training and estimation.

Depth comes in metres with 0 where nothing was measured (renderer, loader and
sensor model agree on that). Absolute depth mostly encodes where the camera
stood, which differs between training cameras and a user's recording, so the
default input is depth relative to the frame's median surface depth: the
cloth's shape and motion, in metres, independent of the camera's distance.

Modes (background is always 0, so the network sees the silhouette):
  * ``'relative'``: ``1 + z - median(z)`` on valid pixels (about 0.5-1.5).
  * ``'metric'``: ``z`` itself.
  * ``'minmax'``: the paper's per-frame normalisation, ``0.25 + 0.75 (zmax - z)
    / (zmax - zmin)`` (near is bright), for recordings that lost absolute depth.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np

MODES = ('relative', 'metric', 'minmax')


def depth_input(depth: jax.Array, mode: str = 'relative') -> jax.Array:
  """Maps depth frames (..., H, W) in metres to inputs (..., H, W, 1).

  A NumPy array is mapped with NumPy (a NumPy array back), anything else with
  jax.numpy, by the same formula: the training loader maps whole sequences on
  the host, where NumPy's partition-based median is ~10x faster than XLA's
  sort-based one, and the estimate maps inside its jitted embedding.

  Args:
    depth: depth frames, 0 (or NaN) where invalid.
    mode: one of ``MODES``.

  Returns:
    float32 inputs with a trailing channel axis; 0 on invalid pixels.
  """
  if mode not in MODES:
    raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
  xp = np if isinstance(depth, np.ndarray) else jnp
  f32 = xp.float32
  z = xp.asarray(depth, f32)
  valid = xp.isfinite(z) & (z > 0)
  z = xp.where(valid, z, f32(0.0))
  if mode == 'metric':
    out = z
  elif mode == 'relative':
    with warnings.catch_warnings():  # a frame with no valid pixel: NaN -> 0 below
      warnings.simplefilter('ignore', RuntimeWarning)
      med = xp.nanmedian(xp.where(valid, z, f32(np.nan)), axis=(-2, -1), keepdims=True)
    out = 1.0 + z - xp.nan_to_num(med)
  else:
    lo = xp.min(xp.where(valid, z, f32(np.inf)), axis=(-2, -1), keepdims=True)
    hi = xp.max(xp.where(valid, z, f32(-np.inf)), axis=(-2, -1), keepdims=True)
    out = 0.25 + 0.75 * (hi - z) / xp.maximum(hi - lo, f32(1e-6))
  return xp.where(valid, out, f32(0.0)).astype(f32)[..., None]


def rgb_input(rgb) -> jax.Array:
  """Maps 8-bit colour frames (..., H, W, 3) to float32 inputs in [0, 1].

  Args:
    rgb: uint8 (or integer-valued) colour frames.

  Returns:
    ``rgb / 255`` as float32, shape unchanged (three channels).
  """
  x = jnp.asarray(rgb)
  if x.ndim < 3 or x.shape[-1] != 3:
    raise ValueError(f'rgb must have shape (..., H, W, 3), got {x.shape}')
  return x.astype(jnp.float32) / 255.0
