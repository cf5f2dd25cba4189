"""Tests of physsim.shape: the sheet's mean shape from depth, against a float64
NumPy reference (physsim.scene.backproject) and planes placed by hand."""

from __future__ import annotations

import jax
import numpy as np

import physsim
from physsim import camera, render, scene, shape

_F32_TOL = 1e-5  # metres: float32 back-projection of points ~2 m from the camera
_RENDER_TOL = 1e-4  # metres: a rendered plane's centroid (float32 ray casting)

_summary = jax.jit(shape.summary, static_argnums=1)


def reference_summary(depth, intr, pose) -> np.ndarray:
  """float64 NumPy summary: lift with scene.backproject, centroid per frame."""
  cents = []
  for frame in depth:
    ok = np.isfinite(frame) & (frame > 0)
    if not ok.any():
      continue
    cam = scene.backproject(np.where(ok, frame, 0.0), intr)[ok]
    world = cam @ np.asarray(pose.rotation, np.float64).T + np.asarray(pose.position)
    cents.append(world.mean(0))
  return np.array(cents)[:, 1:].mean(0)


def test_summary_matches_a_float64_reference():
  rng = np.random.default_rng(0)
  intr = camera.Intrinsics(32, 24, 58.0, 45.0, 0.45, 0.55)
  pose = camera.look_at((0.5, -1.9, 1.2), (0.0, 0.2, 1.0))
  depth = rng.uniform(1.5, 2.5, (6, 24, 32)).astype(np.float32)
  depth[rng.random(depth.shape) < 0.3] = 0.0  # holes
  depth[0, 3, 4] = np.nan  # a NaN pixel counts as no cloth
  depth[2] = 0.0  # a frame with nothing: left out
  got = np.asarray(_summary(depth, intr, pose))
  np.testing.assert_allclose(got, reference_summary(depth, intr, pose), atol=_F32_TOL)
  assert np.all(np.isnan(np.asarray(_summary(np.zeros_like(depth), intr, pose))))


def test_rendered_plates_give_their_mean_place():
  # A 0.6 m x 0.4 m plate at y = 0.1 or 0.3 (alternating frames), centred at
  # z = 1.0, seen head-on: its centroid's mean is y = 0.2, z = 1.0 (by hand).
  intr = camera.Intrinsics(32, 32, 58.0, 58.0)
  pose = camera.look_at((0.0, -1.8, 1.0), (0.0, 0.2, 1.0))
  base = np.array([[-0.3, 0, 0.8], [0.3, 0, 0.8], [0.3, 0, 1.2], [-0.3, 0, 1.2]])
  faces = np.array([[0, 1, 2], [0, 2, 3]])
  pos = np.stack([base + [0.0, 0.1 + 0.2 * (t % 2), 0.0] for t in range(4)])
  poses = jax.tree.map(lambda a: np.asarray(a)[None, None], pose)
  depth = np.asarray(render.render_depth(pos[None], faces, intr, poses))[0, 0]
  got = np.asarray(_summary(depth, intr, pose))
  np.testing.assert_allclose(got, [0.2, 1.0], atol=_RENDER_TOL)


def test_summary_distance_is_a_squared_distance():
  a = np.array([0.1, 1.0])
  b = np.array([0.13, 0.96])
  got = float(shape.summary_distance(a, b))  # float32
  np.testing.assert_allclose(got, 0.03**2 + 0.04**2, rtol=1e-5)
  assert 'shape' in physsim.__all__
