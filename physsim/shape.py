"""The sheet's mean shape in the world, from depth frames and the camera's pose.

In the paper's set-up the sheet's static shape is a function of the load ratio
rho v^2 / (w g) alone (``experiments.studies.separability``: its mean
deflection is, with R^2 0.996), so where the sheet sits on average is a direct
gauge of that ratio, with no network. Every valid pixel of a depth frame is
lifted to a world point (the camera's pose in the simulator's frame: cloth in
the x-z plane, wind toward +y, z up), and each frame reduces to the centroid
of its visible cloth. The summary is the clip's mean of those centroids'
wind-wise and vertical coordinates::

  (mean y, mean z), metres

how far the sheet is blown back and lifted. (How much the centroid swings is
left out: it follows the one gust history of a clip about as much as the
parameters.) On a hanging sheet the centroid moves on an arc about the pins:
mostly back (y) in light wind, mostly up (z) in strong wind, so both count,
in metres alike. The pixels sample the cloth unevenly (more where it is near
and faces the camera), which is why a recording is only compared with
simulations rendered from its own camera, through the same sensor model.
``summary_distance`` is the squared distance between two summaries (m^2): a
discrepancy that rises quadratically away from the truth, as the posterior's
likelihood expects.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from physsim.camera import Intrinsics, Pose, pixel_rays

SUMMARY = ('mean_y_m', 'mean_z_m')


def world_points(depth, intrinsics: Intrinsics, pose: Pose) -> jax.Array:
  """(..., H, W, 3) world points of (..., H, W) depth (z along the optical
  axis, metres) seen from one camera ``pose`` (rotation (3, 3), position (3,))."""
  depth = jnp.asarray(depth, jnp.float32)
  h, w = depth.shape[-2:]
  cam = pixel_rays(intrinsics, h, w) * depth[..., None]
  rot = jnp.asarray(pose.rotation, jnp.float32)
  return cam @ rot.T + jnp.asarray(pose.position, jnp.float32)


def summary(depth, intrinsics: Intrinsics, pose: Pose) -> jax.Array:
  """(2,) ``SUMMARY`` of a depth clip (T, H, W) (0 or non-finite: no cloth).

  Frames without a valid pixel are left out; a clip with none is all NaN
  (the caller treats it as a failed simulation).
  """
  depth = jnp.asarray(depth, jnp.float32)
  valid = jnp.isfinite(depth) & (depth > 0)
  pts = world_points(jnp.where(valid, depth, 0.0), intrinsics, pose)  # (T, H, W, 3)
  count = valid.sum(axis=(-2, -1))  # (T,)
  centre = (
    jnp.einsum('thwk,thw->tk', pts, valid.astype(pts.dtype))
    / jnp.maximum(count, 1)[:, None]
  )
  seen = (count > 0).astype(pts.dtype)
  n = seen.sum()
  mean = jnp.einsum('tk,t->k', centre[:, 1:], seen) / n
  return jnp.where(n > 0, mean, jnp.nan)


def summary_distance(a, b) -> jax.Array:
  """Squared distance (m^2) between summaries (..., 2)."""
  return jnp.sum((jnp.asarray(a) - jnp.asarray(b)) ** 2, axis=-1)


def _rotation(axis_angle) -> jax.Array:
  """(3, 3) rotation of an axis-angle vector (Rodrigues), radians."""
  theta = jnp.sqrt(jnp.sum(axis_angle**2) + 1e-30)
  k = axis_angle / theta
  kx = jnp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
  return jnp.eye(3) + jnp.sin(theta) * kx + (1.0 - jnp.cos(theta)) * kx @ kx


def misplaced_pose(key, pose: Pose, sd_m: float, sd_deg: float, centre) -> Pose:
  """A camera ``pose`` moved by a random rigid error of the world frame.

  A recording's camera is placed in the simulator's world by an alignment
  (the intake's pins and up) that is off by a few centimetres and degrees.
  Rendering a simulation from a camera moved by such an error (a rotation of
  ``sd_deg`` per axis about ``centre``, then a shift of ``sd_m`` per axis,
  1 sd) and lifting its frames with the given ``pose`` gives its summary the
  scatter the recording's has, so a posterior built on it carries the
  alignment's error instead of trusting the camera to the millimetre.
  """
  k_rot, k_shift = jax.random.split(key)
  return displaced_pose(
    pose,
    jnp.deg2rad(sd_deg) * jax.random.normal(k_rot, (3,)),
    sd_m * jax.random.normal(k_shift, (3,)),
    centre,
  )


def displaced_pose(pose: Pose, axis_angle, shift, centre) -> Pose:
  """A camera ``pose`` rotated by ``axis_angle`` (radians, an axis-angle
  vector of the world frame) about ``centre``, then shifted by ``shift``
  (metres): one rigid error, the move ``misplaced_pose`` draws."""
  rot = _rotation(jnp.asarray(axis_angle, jnp.float32))
  centre = jnp.asarray(centre, jnp.float32)
  position = (
    rot @ (jnp.asarray(pose.position, jnp.float32) - centre)
    + centre
    + jnp.asarray(shift, jnp.float32)
  )
  return Pose(rot @ jnp.asarray(pose.rotation, jnp.float32), position)


def misplaced_poses(key, poses: Pose, sd_m: float, sd_deg: float, centre) -> Pose:
  """``misplaced_pose`` of each of C cameras (rotation (C, 3, 3), position
  (C, 3)), each with its own error drawn from ``key``."""
  keys = jax.random.split(key, poses.position.shape[0])
  return jax.vmap(lambda k, p: misplaced_pose(k, p, sd_m, sd_deg, centre))(keys, poses)
