"""Tests for physsim.sensor: statistics of the depth noise model on planes."""

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
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0)
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
    dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, drop_silhouette=False
  )
  out = np.asarray(
    sensor.apply_noise(jax.random.key(0), jnp.asarray(depth), _INTR, keep)
  )
  np.testing.assert_allclose(out[10, 1:22], 1.0, atol=_QUANT_TOL)


def test_tilted_surface_far_away_is_not_an_edge():
  # At 3 m and 48 px a pixel spans ~7 cm, so a plane tilted 60 degrees steps
  # ~12 cm between neighbours: more than the 5 cm jump threshold, but no edge.
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0)
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


@pytest.mark.parametrize('tilt, dropped', [(55.0, False), (80.0, True)])
def test_grazing_pixels_are_dropped(tilt, dropped):
  config = sensor.SensorNoise(dropout_rate=0.0, sigma_a=0.0, sigma_b=0.0, edge_radius=0)
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
  with pytest.raises(ValueError, match='depth must be'):
    sensor.apply_noise(jax.random.key(0), jnp.zeros((3, 3)), _INTR)
