"""Tests for physsim.sensor: statistics of the depth noise model on planes."""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from physsim import camera, sensor

_INTR = camera.Intrinsics(48, 48, 58.0, 45.0)
_SIGMA_REL_TOL = 0.04  # sample std over ~40k pixels: ~0.4 % standard error
_RATE_ABS_TOL = 0.004  # dropout fraction over ~40k pixels: ~0.05 % standard error
_QUANT_TOL = 1e-6  # metres: float32 rounding of whole millimetres
# A band of exactly one render pixel at _INTR's 48 px (the default 2.5 of 640
# native pixels is 0.1875 of a pixel there).
_BAND_1PX = dict(edge_band=1.0, native_width=_INTR.width)
_RING_SIGMAS = 4.0  # binomial standard errors allowed for a ring's drop fraction


def _plane(depth_at_centre, tilt_deg=0.0, intr=_INTR):
  """(H, W) z-depth of a plane through (0, 0, d), turned tilt_deg about the y axis."""
  v, u = np.meshgrid(np.arange(intr.height), np.arange(intr.width), indexing='ij')
  x = (u - intr.cx) / intr.fx
  t = math.tan(math.radians(tilt_deg))
  # Plane z = d + t X with X = x z  =>  z = d / (1 - t x).
  z = depth_at_centre / (1.0 - t * x)
  return np.where(z > 0, z, 0.0).astype(np.float32) + 0 * v


def _samples(depth, config, n=20, seed=0):
  keys = jax.random.split(jax.random.key(seed), n)
  return np.asarray(
    jax.vmap(lambda k: sensor.apply_noise(k, depth, _INTR, config))(keys)
  )


@pytest.mark.parametrize('d', [1.0, 2.0])
def test_axial_noise_std_follows_sigma_of_z(d):
  config = sensor.SensorNoise(dropout_rate=0.0)
  depth = _plane(d)
  out = _samples(jnp.asarray(depth), config)
  interior = out[:, 2:-2, 2:-2]
  assert np.all(interior > 0)
  resid = interior - d
  # Rounding to q adds q^2 / 12 of variance (Sheppard) when sigma > q.
  expected = math.sqrt(config.sigma(d) ** 2 + config.quantization**2 / 12)
  assert np.std(resid) == pytest.approx(expected, rel=_SIGMA_REL_TOL)
  assert abs(np.mean(resid)) < 4 * expected / math.sqrt(resid.size) + 1e-4
  # Every value is a whole number of millimetres.
  mm = interior / config.quantization
  np.testing.assert_allclose(mm, np.round(mm), atol=_QUANT_TOL / config.quantization)
  assert float(config.sigma(1.0)) == pytest.approx(0.00185)


def test_dropout_rate_and_reproducibility():
  config = sensor.SensorNoise(dropout_rate=0.05)
  depth = jnp.asarray(_plane(1.5))
  out = _samples(depth, config)
  interior = out[:, 2:-2, 2:-2]
  assert np.mean(interior == 0) == pytest.approx(0.05, abs=_RATE_ABS_TOL)
  again = _samples(depth, config)
  np.testing.assert_array_equal(out, again)
  other = _samples(depth, config, seed=1)
  assert not np.array_equal(out, other)


def test_edges_and_silhouette_are_dropped():
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, **_BAND_1PX)
  depth = np.full((48, 48), 1.0, np.float32)
  depth[:, 24:] = 1.3  # a 30 cm step between columns 23 and 24
  depth[:10] = 0.0  # background above row 10
  out = np.asarray(
    sensor.apply_noise(jax.random.key(0), jnp.asarray(depth), _INTR, config)
  )
  assert np.all(out[:, 23:25] == 0)  # both sides of the step
  assert np.all(out[10] == 0)  # next to the background
  assert np.all(out[:10] == 0)  # invalid stays invalid
  np.testing.assert_allclose(out[12:-1, 1:22], depth[12:-1, 1:22], atol=_QUANT_TOL)
  np.testing.assert_allclose(out[12:-1, 26:-1], depth[12:-1, 26:-1], atol=_QUANT_TOL)
  # No silhouette rule: only the step goes.
  keep = sensor.SensorNoise(
    dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, drop_silhouette=False, **_BAND_1PX
  )
  out = np.asarray(
    sensor.apply_noise(jax.random.key(0), jnp.asarray(depth), _INTR, keep)
  )
  np.testing.assert_allclose(out[10, 1:22], 1.0, atol=_QUANT_TOL)


def test_tilted_surface_far_away_is_not_an_edge():
  # At 3 m and 48 px a pixel spans ~7 cm, so a plane tilted 60 degrees steps
  # ~12 cm between neighbours: more than the 5 cm jump threshold, but no edge.
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, **_BAND_1PX)
  depth = _plane(3.0, 60.0)
  assert np.abs(np.diff(depth, axis=1)).max() > config.edge_threshold
  # Columns 17-30: rays within ~10 degrees of the axis, incidence <= ~70 degrees
  # (further out, rays graze the plane and the incidence rule drops them).
  edges = np.asarray(sensor.edge_mask(jnp.asarray(depth), config, _INTR))
  assert not edges[1:-1, 17:31].any()
  # Without intrinsics the fixed threshold alone would drop it all.
  assert np.asarray(sensor.edge_mask(jnp.asarray(depth), config))[1:-1, 17:31].all()
  # A real occlusion step at that distance is still an edge.
  step = np.full((48, 48), 3.0, np.float32)
  step[:, 24:] = 3.6
  edges = np.asarray(sensor.edge_mask(jnp.asarray(step), config, _INTR))
  assert edges[5:-5, 23:25].all() and not edges[5:-5, 2:20].any()


def _jump_distance(depth, intr, config, reach):
  """(H, W) Chebyshev distance from each pixel to its nearest depth jump.

  Brute force in float64 NumPy, independent of physsim.sensor: a jump is an
  invalid neighbour (or one outside the image) or a depth difference above
  both ``edge_threshold`` and the tilted-surface span ``d z tan(max) / f``.
  ``reach + 1`` where no jump lies within ``reach``.
  """
  d = np.asarray(depth, np.float64)
  h, w = d.shape
  tan = math.tan(math.radians(min(config.max_incidence_deg, 89.0)))
  slope = tan / min(intr.fx, intr.fy)
  pad = np.pad(d, reach)
  dist = np.full(d.shape, reach + 1)
  for dy in range(-reach, reach + 1):
    for dx in range(-reach, reach + 1):
      n = pad[reach + dy : reach + dy + h, reach + dx : reach + dx + w]
      limit = np.maximum(
        config.edge_threshold, slope * math.hypot(dy, dx) * np.maximum(n, d)
      )
      jump = (n <= 0) | (np.abs(n - d) > limit)
      if (dy, dx) != (0, 0):
        dist = np.where(jump, np.minimum(dist, max(abs(dy), abs(dx))), dist)
  return dist


def _with_and_without_edges(depth, intr, config, n, seed=0):
  """(n, H, W) outputs of ``config`` and of it with ``edge_band=0``, same keys.

  Where the second is valid and the first not, edge dropping alone removed the
  pixel (the band's ring draw must not change the other draws).
  """
  keys = jax.random.split(jax.random.key(seed), n)
  run = lambda c: np.asarray(
    jax.jit(jax.vmap(lambda k: sensor.apply_noise(k, depth, intr, c)))(keys)
  )
  return run(config), run(dataclasses.replace(config, edge_band=0.0))


def _ring_tol(p, count):
  return _RING_SIGMAS * math.sqrt(p * (1 - p) / count)


def test_band_of_one_pixel_matches_the_old_radius_one_model_bit_for_bit():
  # Paper size: 2.5 native pixels of 640 is exactly 1.0 render pixel at 256.
  intr = camera.Intrinsics()
  config = sensor.SensorNoise()
  assert sensor.edge_band_pixels(config, intr.width) == (1, 0.0)
  depth = np.full((intr.height, intr.width), 1.2, np.float32)
  depth[:40] = 0.0  # background: a silhouette along row 40
  depth[100:160, 80:180] = 0.9  # a box 30 cm in front: a depth jump
  cols = np.arange(200, intr.width)
  depth[40:, 200:] = 1.2 + 0.01 * (cols - 200)  # a ramp: 1 cm steps, no edge
  depth[20, 20] = 1.0  # a lone valid pixel in the background
  key = jax.random.key(3)
  out = np.asarray(sensor.apply_noise(key, jnp.asarray(depth), intr, config))
  # The old model: radius-1 edge dropping and these two draws of these keys.
  k_noise, k_drop = jax.random.split(key)
  d = jnp.asarray(depth)
  z = d + config.sigma(d) * jax.random.normal(k_noise, d.shape, jnp.float32)
  z = jnp.round(z / config.quantization) * config.quantization
  near = (depth > 0) & (_jump_distance(depth, intr, config, 1) <= 1)
  cos_max = math.cos(math.radians(config.max_incidence_deg))
  keep = (
    (depth > 0)
    & ~near
    & (np.asarray(sensor.incidence_cos(d, intr)) >= cos_max)
    & ~np.asarray(jax.random.bernoulli(k_drop, config.dropout_rate, d.shape))
  )
  expected = np.where(keep & (np.asarray(z) > 0), np.asarray(z), 0.0)
  assert near.sum() > 1000 and not near[60:90, 20:60].any()
  assert np.sum((out == 0) & (depth > 0)) > near.sum()  # dropouts happened too
  np.testing.assert_array_equal(out, expected)
  np.testing.assert_array_equal(np.asarray(sensor.edge_mask(d, config, intr)), near)


def test_band_below_a_pixel_drops_the_boundary_ring_at_its_fraction():
  # The CPU demo's 32 px: the default band is 2.5 * 32 / 640 = 0.125 px.
  intr = camera.Intrinsics(32, 32)
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0)
  assert sensor.edge_band_pixels(config, intr.width) == (0, 0.125)
  depth = np.full((32, 32), 1.5, np.float32)
  depth[:, 16:] = 0.0  # a straight silhouette down the middle
  dist = _jump_distance(depth, intr, config, 2)
  valid = depth > 0
  ring = valid & (dist == 1)
  out, base = _with_and_without_edges(depth, intr, config, n=400)
  assert np.all(base[:, valid] > 0)  # no other rule drops anything here
  dropped = out == 0
  assert not dropped[:, valid & (dist > 1)].any()
  per_frame = dropped[:, ring].sum(axis=1)
  assert np.all((per_frame > 0) & (per_frame < ring.sum()))  # independent draws
  count = dropped.shape[0] * ring.sum()
  assert per_frame.sum() / count == pytest.approx(0.125, abs=_ring_tol(0.125, count))
  near, ring_mask, frac = sensor.edge_masks(jnp.asarray(depth), config, intr)
  assert not np.asarray(near).any() and frac == 0.125
  np.testing.assert_array_equal(np.asarray(ring_mask), ring)


def test_band_of_2_4_pixels_drops_2_always_and_the_third_at_0_4():
  config = sensor.SensorNoise(
    dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, edge_band=2.4, native_width=48
  )
  r, frac = sensor.edge_band_pixels(config, _INTR.width)
  assert r == 2 and frac == pytest.approx(0.4)
  depth = np.full((48, 48), 1.0, np.float32)
  depth[:, 24:] = 2.0  # a 1 m step: a jump even 3 diagonal pixels apart
  depth[:10] = 0.0  # background above row 10
  dist = _jump_distance(depth, _INTR, config, 4)
  valid = depth > 0
  out, base = _with_and_without_edges(depth, _INTR, config, n=100)
  assert np.all(out[:, valid & (dist <= 2)] == 0)
  # Only the step's two columns fall to the grazing-angle rule; no other drops.
  assert np.all(base[:, valid & (dist >= 2)] > 0)
  dropped = out == 0
  assert not dropped[:, valid & (dist > 3)].any()
  near, ring_mask, _ = sensor.edge_masks(jnp.asarray(depth), config, _INTR)
  np.testing.assert_array_equal(np.asarray(near), valid & (dist <= 2))
  np.testing.assert_array_equal(np.asarray(ring_mask), valid & (dist == 3))
  ring = dropped[:, valid & (dist == 3)]
  assert ring.size > 10000
  assert ring.mean() == pytest.approx(0.4, abs=_ring_tol(0.4, ring.size))


@pytest.mark.parametrize('tilt, dropped', [(55.0, False), (80.0, True)])
def test_grazing_pixels_are_dropped(tilt, dropped):
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, edge_band=0.0)
  depth = _plane(1.5, tilt)
  # Off-centre rays meet the plane at other angles; in the two central columns
  # and middle rows the incidence is within ~1.5 degrees of ``tilt`` (the
  # default limit is 78 degrees).
  inc = np.degrees(np.arccos(sensor.incidence_cos(jnp.asarray(depth), _INTR)))
  np.testing.assert_allclose(inc[10:-10, 23:25], tilt, atol=2.0)
  out = np.asarray(
    sensor.apply_noise(jax.random.key(0), jnp.asarray(depth), _INTR, config)
  )
  centre = out[10:-10, 23:25]
  assert np.all(centre == 0) if dropped else np.all(centre > 0)


def test_bad_config_and_shape():
  with pytest.raises(ValueError, match='dropout_rate'):
    sensor.SensorNoise(dropout_rate=1.5)
  with pytest.raises(ValueError, match='max_incidence_deg'):
    sensor.SensorNoise(max_incidence_deg=0.0)
  for bad in (-0.5, float('nan'), float('inf'), '2.5', True):
    with pytest.raises(ValueError, match='edge_band'):
      sensor.SensorNoise(edge_band=bad)
  for bad in (0, -640, 640.0, True):
    with pytest.raises(ValueError, match='native_width'):
      sensor.SensorNoise(native_width=bad)
  with pytest.raises(ValueError, match='depth must be'):
    sensor.apply_noise(jax.random.key(0), jnp.zeros((3, 3)), _INTR)
