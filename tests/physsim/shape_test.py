"""Tests of physsim.shape: the sheet's mean shape from depth, against a float64
NumPy reference (physsim.scene.backproject) and planes placed by hand."""

from __future__ import annotations

import jax
import numpy as np

import physsim
from physsim import camera, render, scene, shape

_F32_TOL = 1e-5  # metres: float32 back-projection of points ~2 m from the camera
_RENDER_TOL = 1e-4  # metres: a rendered plane's centroid (float32 ray casting)
# metres: a plate seen from another place is sampled by other pixels; those
# its silhouette gains or loses move the centroid (1 px ~ 0.8 cm at 256 px
# and 1.9 m; a row more or less of the plate's 48 moves it ~2 mm)
_EDGE_TOL = 3e-3

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


def _plate(intr, pose, offsets, seen_from=None):
  """Summary of a 0.6 m x 0.4 m plate in the x-z plane centred at z = 1.0,
  moved by ``offsets`` (T, 3), rendered from ``seen_from`` (default ``pose``)
  and lifted with ``pose``."""
  base = np.array([[-0.3, 0, 0.8], [0.3, 0, 0.8], [0.3, 0, 1.2], [-0.3, 0, 1.2]])
  faces = np.array([[0, 1, 2], [0, 2, 3]])
  pos = base[None] + np.asarray(offsets)[:, None]
  poses = jax.tree.map(lambda a: np.asarray(a)[None, None], seen_from or pose)
  depth = np.asarray(render.render_depth(pos[None], faces, intr, poses))[0, 0]
  return np.asarray(_summary(depth, intr, pose))


def test_rendered_plates_give_their_mean_place():
  # A 0.6 m x 0.4 m plate at y = 0.1 or 0.3 (alternating frames), centred at
  # z = 1.0, seen head-on: its centroid's mean is y = 0.2, z = 1.0 (by hand).
  intr = camera.Intrinsics(32, 32, 58.0, 58.0)
  pose = camera.look_at((0.0, -1.8, 1.0), (0.0, 0.2, 1.0))
  offsets = [[0.0, 0.1 + 0.2 * (t % 2), 0.0] for t in range(4)]
  np.testing.assert_allclose(_plate(intr, pose, offsets), [0.2, 1.0], atol=_RENDER_TOL)


def test_a_camera_seen_from_a_shifted_place_moves_the_plate_back():
  # Rendered from a camera shifted by s and lifted with the given pose, the
  # plate appears moved by -s (derived by hand), up to the pixels its
  # silhouette gains or loses.
  intr = camera.Intrinsics(256, 256, 58.0, 58.0)
  pose = camera.look_at((0.2, -1.8, 1.1), (0.0, 0.2, 1.0))
  for seed in range(3):
    moved = shape.misplaced_pose(jax.random.key(seed), pose, 0.05, 0.0, [0, 0, 1.5])
    shift = np.asarray(moved.position) - np.asarray(pose.position)
    got = _plate(intr, pose, np.zeros((2, 3)), moved)
    np.testing.assert_allclose(got, np.array([0.0, 1.0]) - shift[1:], atol=_EDGE_TOL)


def test_summary_distance_is_a_squared_distance():
  a = np.array([0.1, 1.0])
  b = np.array([0.13, 0.96])
  got = float(shape.summary_distance(a, b))  # float32
  np.testing.assert_allclose(got, 0.03**2 + 0.04**2, rtol=1e-5)
  assert 'shape' in physsim.__all__


def test_misplaced_pose_is_a_rigid_error_of_the_given_size():
  pose = camera.look_at((0.5, -1.9, 1.2), (0.0, 0.2, 1.0))
  centre = np.array([0.0, 0.0, 1.5])
  n, sd_m, sd_deg = 4000, 0.02, 3.0
  keys = jax.random.split(jax.random.key(0), n)
  many = jax.vmap(lambda k: shape.misplaced_pose(k, pose, sd_m, sd_deg, centre))
  rot = np.asarray(many(keys).rotation, np.float64)
  eye = np.broadcast_to(np.eye(3), rot.shape)
  np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), eye, atol=1e-5)
  np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-5)
  # The error's rotation angle: RMS sqrt(3) sd_deg for sd_deg per axis.
  err = rot @ np.asarray(pose.rotation, np.float64).T
  angle = np.degrees(
    np.arccos(np.clip((np.trace(err, axis1=1, axis2=2) - 1) / 2, -1, 1))
  )
  np.testing.assert_allclose(np.sqrt(np.mean(angle**2)), np.sqrt(3) * sd_deg, rtol=0.05)
  # A rotation alone turns about the centre (the camera keeps its distance);
  # a shift alone moves the camera by sd_m per axis.
  turned = jax.vmap(lambda k: shape.misplaced_pose(k, pose, 0.0, sd_deg, centre))(keys)
  dist = np.linalg.norm(np.asarray(turned.position) - centre, axis=1)
  np.testing.assert_allclose(dist, np.linalg.norm(pose.position - centre), rtol=1e-5)
  moved = jax.vmap(lambda k: shape.misplaced_pose(k, pose, sd_m, 0.0, centre))(keys)
  np.testing.assert_allclose(np.asarray(moved.rotation)[0], pose.rotation, atol=1e-6)
  shift = np.asarray(moved.position) - np.asarray(pose.position)
  np.testing.assert_allclose(shift.std(0), sd_m, rtol=0.05)
