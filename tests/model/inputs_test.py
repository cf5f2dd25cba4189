"""Tests for model.inputs: depth frames to network inputs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from model import inputs

_TOL = 1e-6


def _frame():
  z = np.zeros((2, 8, 8), np.float32)
  z[:, 2:6, 2:6] = np.linspace(1.9, 2.2, 16).reshape(4, 4)
  z[1, 3, 3] = np.nan  # a NaN pixel is invalid, like a 0
  return z


def test_relative_ignores_camera_distance_and_keeps_background_zero():
  z = _frame()
  a = np.asarray(inputs.depth_input(z, 'relative'))
  b = np.asarray(inputs.depth_input(np.where(z > 0, z + 0.7, 0), 'relative'))
  assert a.shape == (2, 8, 8, 1)
  np.testing.assert_allclose(a, b, atol=_TOL)
  assert np.all(a[:, :2] == 0) and a[1, 3, 3, 0] == 0
  # frame 0's median of 16 evenly spaced values is their mean (2.05 m)
  assert a[0, 2, 2, 0] == pytest.approx(1 + 1.9 - 2.05, abs=1e-5)


def test_minmax_and_metric_by_hand():
  z = _frame()
  mm = np.asarray(inputs.depth_input(z, 'minmax'))[0, ..., 0]
  assert mm[2, 2] == pytest.approx(1.0) and mm[5, 5] == pytest.approx(0.25)
  met = np.asarray(inputs.depth_input(z, 'metric'))[0, ..., 0]
  np.testing.assert_allclose(met, z[0], atol=_TOL)


# NumPy and XLA may round the float32 arithmetic differently (fused multiply-add).
_BACKEND_TOL = 1e-6


@pytest.mark.parametrize('mode', inputs.MODES)
def test_numpy_and_jax_paths_agree(mode):
  # The loader maps NumPy frames with NumPy, the estimate maps traced frames
  # with jax.numpy: one formula, compared here, holes and an empty frame included.
  rng = np.random.default_rng(0)
  z = rng.uniform(1.5, 2.5, (3, 2, 16, 16)).astype(np.float32)
  z[rng.random(z.shape) < 0.3] = 0.0
  z[0, 1, 4, 4] = np.nan
  z[2, 0] = 0.0  # nothing measured
  host = inputs.depth_input(z, mode)
  dev = inputs.depth_input(jnp.asarray(z), mode)
  assert isinstance(host, np.ndarray) and isinstance(dev, jax.Array)
  assert host.dtype == np.float32 and host.shape == (3, 2, 16, 16, 1)
  np.testing.assert_allclose(host, np.asarray(dev), atol=_BACKEND_TOL)
  assert np.all(host[2, 0] == 0)
  jitted = jax.jit(inputs.depth_input, static_argnames='mode')(z, mode=mode)
  np.testing.assert_allclose(host, np.asarray(jitted), atol=_BACKEND_TOL)


def test_bad_mode():
  with pytest.raises(ValueError, match='mode must be one of'):
    inputs.depth_input(np.zeros((4, 4)), 'log')


def test_rgb_input_by_hand():
  rgb = np.array([[[0, 128, 255]]], np.uint8)  # (1, 1, 3)
  out = np.asarray(inputs.rgb_input(rgb))
  assert out.dtype == np.float32 and out.shape == (1, 1, 3)
  np.testing.assert_allclose(out[0, 0], [0.0, 128 / 255, 1.0], atol=_TOL)
  with pytest.raises(ValueError, match=r'\(\.\.\., H, W, 3\)'):
    inputs.rgb_input(np.zeros((4, 4, 1), np.uint8))
