"""Tests for physsim.camera: intrinsics, look-at, extrinsics and pose sampling."""

import json
import math

import jax
import numpy as np
import pytest

from physsim import camera

_TOL = 1e-5  # float32 rotations and projections, relative to O(1) values
_PIXEL_TOL = 1e-3  # pixels


def _project(intr, pose, points):
  """Pixels (N, 2) and z (N,) of world points, in float64 NumPy."""
  r = np.asarray(pose.rotation, np.float64)
  p = np.asarray(pose.position, np.float64)
  xc = (np.asarray(points, np.float64) - p) @ r
  uv = xc @ intr.matrix().T
  return uv[:, :2] / uv[:, 2:], xc[:, 2]


def test_intrinsics_focal_lengths_span_the_field_of_view():
  intr = camera.Intrinsics(64, 48, 58.0, 45.0)
  # A ray at half the field of view lands on the outer edge of the edge pixel.
  pose = camera.Pose(np.eye(3), np.zeros(3))
  pts = [
    [math.tan(math.radians(29.0)), 0, 1],
    [0, -math.tan(math.radians(22.5)), 1],
  ]
  uv, _ = _project(intr, pose, pts)
  np.testing.assert_allclose(uv[0, 0], intr.width - 0.5, atol=_PIXEL_TOL)
  np.testing.assert_allclose(uv[1, 1], -0.5, atol=_PIXEL_TOL)
  assert intr.matrix().shape == (3, 3)
  assert hash(intr) == hash(camera.Intrinsics(64, 48, 58.0, 45.0))


def test_intrinsics_dict_round_trip_and_bad_values():
  intr = camera.Intrinsics(32, 24, 50.0, 40.0)
  assert camera.Intrinsics.from_dict(json.loads(json.dumps(intr.to_dict()))) == intr
  with pytest.raises(ValueError, match='width'):
    camera.Intrinsics(width=0)
  with pytest.raises(ValueError, match='fov_y_deg'):
    camera.Intrinsics(fov_y_deg=180.0)
  with pytest.raises(ValueError, match='unknown'):
    camera.Intrinsics.from_dict({'focal': 3})


@pytest.mark.parametrize('roll', [0.0, 17.0])
def test_look_at_is_orthonormal_and_centres_the_target(roll):
  eye, target = np.array([0.4, -2.0, 1.3]), np.array([0.05, 0.1, 0.95])
  pose = camera.look_at(eye, target, roll_deg=roll)
  r = np.asarray(pose.rotation, np.float64)
  np.testing.assert_allclose(r.T @ r, np.eye(3), atol=_TOL)
  assert np.linalg.det(r) == pytest.approx(1.0, abs=_TOL)
  intr = camera.Intrinsics(64, 64)
  uv, z = _project(intr, pose, [target, target + [0, 0, 0.1]])
  np.testing.assert_allclose(uv[0], [intr.cx, intr.cy], atol=_PIXEL_TOL)
  assert z[0] == pytest.approx(np.linalg.norm(target - eye), rel=_TOL)
  if roll == 0:
    assert uv[1, 1] < intr.cy  # world up is image up (rows grow downward)
    assert uv[1, 0] == pytest.approx(intr.cx, abs=_PIXEL_TOL)


def test_world_to_camera_matches_pose():
  pose = camera.look_at([[0.3, -2, 1.1], [-1, -1.5, 0.7]], [0, 0, 1.0], roll_deg=5.0)
  m = np.asarray(camera.world_to_camera(pose))
  assert m.shape == (2, 4, 4)
  cam_h = np.concatenate([np.asarray(pose.position), np.ones((2, 1))], 1)
  np.testing.assert_allclose(
    np.einsum('bij,bj->bi', m, cam_h), [[0, 0, 0, 1]] * 2, atol=_TOL
  )
  np.testing.assert_allclose(m[:, :3, :3], np.swapaxes(pose.rotation, 1, 2), atol=_TOL)


def test_pose_dict_round_trip():
  pose = camera.sample_poses(jax.random.key(0), 3)
  back = camera.pose_from_dict(json.loads(json.dumps(camera.pose_to_dict(pose))))
  np.testing.assert_allclose(back.rotation, pose.rotation, atol=1e-7)
  np.testing.assert_allclose(back.position, pose.position, atol=1e-7)
  with pytest.raises(ValueError, match='position'):
    camera.pose_from_dict({'rotation': np.eye(3).tolist()})


def _spherical(pose, ranges):
  """Azimuth, elevation (degrees) of the view direction; distance to the target box."""
  f = np.asarray(pose.rotation, np.float64)[..., 2]  # forward axes
  back = -f
  az = np.degrees(np.arctan2(back[:, 0], -back[:, 1]))
  el = np.degrees(np.arcsin(back[:, 2]))
  d = np.linalg.norm(np.asarray(pose.position) - np.asarray(ranges.target), axis=1)
  return az, el, d


def test_sample_poses_reproducible_and_in_range():
  ranges = camera.PoseRanges()
  a = camera.sample_poses(jax.random.key(3), 400, ranges)
  b = camera.sample_poses(jax.random.key(3), 400, ranges)
  c = camera.sample_poses(jax.random.key(4), 400, ranges)
  np.testing.assert_array_equal(a.position, b.position)
  assert not np.allclose(a.position, c.position)
  assert a.rotation.shape == (400, 3, 3) and a.position.shape == (400, 3)
  az, el, d = _spherical(a, ranges)
  slack = math.sqrt(3) * ranges.target_jitter
  assert np.all((az >= -25 - _TOL) & (az <= 25 + _TOL))
  assert np.all((el >= -10 - _TOL) & (el <= 20 + _TOL))
  lo, hi = ranges.distance
  assert np.all((d >= lo - slack) & (d <= hi + slack))
  assert az.min() < -20 and az.max() > 20  # fills the range


def test_training_poses_see_the_whole_swinging_cloth():
  intr = camera.Intrinsics()
  poses = camera.sample_poses(jax.random.key(1), 200)
  corners = np.array(
    [[x, y, z] for x in (-0.5, 0.5) for y in (0.0, 0.5) for z in (0.5, 1.5)]
  )
  r = np.asarray(poses.rotation, np.float64)
  xc = np.einsum('nij,nki->nkj', r, corners[None] - np.asarray(poses.position)[:, None])
  uv = xc @ intr.matrix().T
  uv = uv[..., :2] / uv[..., 2:]
  assert np.all(xc[..., 2] > 0)
  assert np.all((uv >= -0.5) & (uv <= [intr.width - 0.5, intr.height - 0.5]))


def test_evaluation_poses_are_disjoint_from_training_poses():
  train, held = camera.PoseRanges(), camera.PoseRanges.evaluation()
  az_t, _, d_t = _spherical(camera.sample_poses(jax.random.key(0), 500, train), train)
  az_e, _, d_e = _spherical(camera.sample_poses(jax.random.key(0), 500, held), held)
  assert np.abs(az_t).max() <= 25 + _TOL
  assert np.abs(az_e).min() >= 30 - _TOL and np.abs(az_e).max() <= 40 + _TOL
  assert (az_e > 0).any() and (az_e < 0).any()  # both sides
  assert d_e.min() > d_t.max()
  with pytest.raises(ValueError, match='distance'):
    camera.PoseRanges(distance=(2.0, 1.0))
