"""Tests for physsim.render against analytic planes, MuJoCo's renderer and itself."""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from physsim import camera, gl_depth, mesh, render
from tests import mujoco_gl

_DEPTH_TOL = 2e-5  # metres: float32 projection and 1/z interpolation at ~2 m
_MUJOCO_DEPTH_TOL = 2e-4  # metres: OpenGL depth buffer precision (measured 2e-6 here)
_MUJOCO_AGREE = 0.99  # fraction of interior pixels within _MUJOCO_DEPTH_TOL
_EDGE_MARGIN = 1e-3  # pixels: skip analytic pixels this close to a boundary

_STATIC = ('intrinsics', 'method', 'fragments_per_pass')
_depth = jax.jit(render.depth_image, static_argnames=_STATIC)
_shade = jax.jit(render.shade_rgb, static_argnames=_STATIC)


def _quad(half_w, half_h):
  """Two triangles spanning [-w, w] x [-h, h] in the x-z plane around z = 1."""
  v = np.array(
    [
      [-half_w, 0, 1 - half_h],
      [half_w, 0, 1 - half_h],
      [half_w, 0, 1 + half_h],
      [-half_w, 0, 1 + half_h],
    ]
  )
  return v, np.array([[0, 1, 2], [0, 2, 3]])


def _rays(intr):
  """(H, W, 3) float64 ray directions with unit z, camera frame."""
  v, u = np.meshgrid(np.arange(intr.height), np.arange(intr.width), indexing='ij')
  return np.stack(
    [(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], axis=-1
  )


@pytest.mark.parametrize('method', render.METHODS)
def test_fronto_parallel_plane(method):
  intr = camera.Intrinsics(48, 32, 58.0, 45.0)
  d = 1.7
  pose = camera.look_at([0.0, -d, 1.0], [0.0, 0.0, 1.0])
  verts, faces = _quad(0.4, 0.25)
  z = np.asarray(_depth(verts, faces, intr, pose, method=method))
  assert z.shape == (32, 48) and z.dtype == np.float32
  hit = _rays(intr)[..., :2] * d  # camera x (= world x), camera y (= -world z)
  inside = (np.abs(hit[..., 0]) < 0.4) & (np.abs(hit[..., 1]) < 0.25)
  margin = 2 * _EDGE_MARGIN * d / intr.fx
  clear = (np.abs(np.abs(hit[..., 0]) - 0.4) > margin) & (
    np.abs(np.abs(hit[..., 1]) - 0.25) > margin
  )
  np.testing.assert_allclose(z[inside & clear], d, atol=_DEPTH_TOL)
  assert np.all(z[~inside & clear] == 0.0)
  assert inside.sum() > 100 and (~inside).sum() > 100


def _tilted_plane_reference(intr, pose, origin, axis_a, axis_b, half):
  """Float64 ray-plane depth of the square origin + s a + t b, |s|, |t| < half."""
  r = np.asarray(pose.rotation, np.float64)
  p = np.asarray(pose.position, np.float64)
  rays = _rays(intr) @ r.T  # world directions with unit camera-z component
  n = np.cross(axis_a, axis_b)
  t = ((origin - p) @ n) / (rays @ n)  # the ray parameter is the z-depth
  x = p + t[..., None] * rays - origin
  s, q = x @ axis_a, x @ axis_b
  inside = (np.abs(s) < half) & (np.abs(q) < half) & (t > 0)
  clear = (np.abs(np.abs(s) - half) > 1e-3) & (np.abs(np.abs(q) - half) > 1e-3)
  return np.where(inside, t, 0.0), clear


@pytest.mark.parametrize('method', render.METHODS)
@pytest.mark.parametrize('principal', [(0.5, 0.5), (0.62, 0.41)])
def test_tilted_plane_matches_float64_ray_plane_intersection(method, principal):
  # An off-centre principal point (OpenCV cx, cy) moves the image, not the rays.
  intr = camera.Intrinsics(40, 40, 50.0, 50.0, *principal)
  # A 0.8 m square mesh, rotated 25 degrees about z and tilted 30 degrees.
  rz, rx = math.radians(25.0), math.radians(30.0)
  a = np.array([math.cos(rz), math.sin(rz), 0.0])
  b = math.cos(rx) * np.array([0, 0, 1.0]) + math.sin(rx) * np.cross(a, [0, 0, 1.0])
  origin = np.array([0.1, 0.2, 1.0])
  m = mesh.square(5, size=0.8)
  s, q = m.vertices[:, 0], m.vertices[:, 2] - (1.5 - 0.4)
  verts = origin + s[:, None] * a + q[:, None] * b
  pose = camera.look_at([0.5, -1.6, 1.4], [0.0, 0.1, 1.0], roll_deg=10.0)
  z = np.asarray(_depth(verts, m.faces, intr, pose, method=method))
  ref, clear = _tilted_plane_reference(intr, pose, origin, a, b, 0.4)
  assert (ref > 0).sum() > 200 and (ref == 0).sum() > 50
  np.testing.assert_allclose(z[clear], ref[clear], atol=_DEPTH_TOL)


def _crumpled_cloth(n=8, seed=0):
  """A square cloth with folds that overlap in view (several layers per pixel)."""
  m = mesh.square(n)
  rng = np.random.default_rng(seed)
  v = m.vertices.copy()
  x, z = v[:, 0], v[:, 2]
  v[:, 1] = 0.25 * np.sin(6.0 * x) * np.cos(3.0 * z) + 0.05 * rng.normal(size=len(v))
  v[:, 0] = x + 0.2 * np.sin(4.0 * z)  # shear so the surface folds over itself
  return v, m.faces


def test_brute_and_raster_agree_on_folded_cloth_and_many_passes():
  intr = camera.Intrinsics(64, 48)
  verts, faces = _crumpled_cloth()
  pose = camera.look_at([0.6, -1.8, 1.3], [0.0, 0.0, 1.0], roll_deg=-8.0)
  brute = np.asarray(_depth(verts, faces, intr, pose, method='brute'))
  # A small pass size forces many while-loop passes and boxes split across passes.
  raster = np.asarray(
    _depth(verts, faces, intr, pose, method='raster', fragments_per_pass=97)
  )
  default = np.asarray(_depth(verts, faces, intr, pose))
  assert (brute > 0).mean() > 0.2
  np.testing.assert_allclose(raster, brute, atol=_DEPTH_TOL)
  np.testing.assert_allclose(default, brute, atol=_DEPTH_TOL)


def test_empty_views_and_cameras_behind():
  intr = camera.Intrinsics(16, 16)
  verts, faces = _quad(0.4, 0.25)
  away = camera.look_at([0.0, -2.0, 1.0], [0.0, -4.0, 1.0])  # looking away
  for method in render.METHODS:
    z = _depth(verts, faces, intr, away, method=method)
    assert np.all(np.asarray(z) == 0.0)
  with pytest.raises(ValueError, match='method'):
    _depth(verts, faces, intr, away, method='zbuffer')
  with pytest.raises(ValueError, match='faces'):
    _depth(verts, faces[:, :2], intr, away)


def test_shade_rgb_two_sided_lambert():
  intr = camera.Intrinsics(32, 32)
  verts, faces = _quad(0.3, 0.3)
  color = render.FABRIC_COLORS['gray_interlock']
  for side in (-1.0, 1.0):  # the cloth looks the same from both sides
    pose = camera.look_at([0.0, 2.0 * side, 1.0], [0.0, 0.0, 1.0])
    rgb = {
      m: np.asarray(
        _shade(verts, faces, intr, pose, color=color, light_dir=(0, side, 0), method=m)
      )
      for m in render.METHODS
    }
    np.testing.assert_array_equal(rgb['raster'], rgb['brute'])
    z = np.asarray(_depth(verts, faces, intr, pose))
    lit = rgb['raster'][z > 0]
    np.testing.assert_allclose(lit, np.broadcast_to(color, lit.shape), atol=1e-6)
    assert np.all(rgb['raster'][z == 0] == 0.0)
  # Light grazing the plane: only the ambient part remains.
  dim = np.asarray(_shade(verts, faces, intr, pose, color=color, light_dir=(1, 0, 0)))
  np.testing.assert_allclose(
    dim[z > 0], render._AMBIENT * np.broadcast_to(color, dim[z > 0].shape), atol=1e-6
  )


def test_batched_renderer_matches_loop_and_does_not_recompile():
  intr = camera.Intrinsics(24, 20)
  verts, faces = _crumpled_cloth(6)
  b, t, c = 2, 3, 2
  rng = np.random.default_rng(0)
  positions = verts + 0.05 * rng.normal(size=(b, t) + verts.shape)
  keys = jax.random.split(jax.random.key(0), b)
  poses = jax.vmap(lambda k: camera.sample_poses(k, c))(keys)
  for method in render.METHODS:
    fn = render.make_depth_renderer(faces, intr, method=method, chunk=5)
    out = np.asarray(fn(positions, poses))
    assert out.shape == (b, c, t, 20, 24)
    for i in range(b):
      for j in range(c):
        for k in range(t):
          pose = camera.Pose(poses.rotation[i, j], poses.position[i, j])
          ref = _depth(positions[i, k], faces, intr, pose, method=method)
          np.testing.assert_allclose(out[i, j, k], ref, atol=_DEPTH_TOL)
    fn(positions + 0.01, poses).block_until_ready()
    assert fn._cache_size() == 1
  rgb = render.render_rgb(positions, faces, intr, poses, chunk=4)
  assert rgb.shape == (b, c, t, 20, 24, 3)
  jitted = jax.jit(
    render.render_depth, static_argnames=('intrinsics', 'method', 'chunk')
  )
  np.testing.assert_allclose(
    jitted(positions, jnp.asarray(faces), intr, poses), out, atol=_DEPTH_TOL
  )


# --- MuJoCo's OpenGL renderer as an independent reference -------------------------


def _mjcf(verts, faces, pose, fovy):
  both = np.concatenate([faces, faces[:, ::-1]])  # both sides, whatever GL culls
  r = np.asarray(pose.rotation, np.float64)
  # MuJoCo cameras look along -z with y up: x_mj = x_cv, y_mj = -y_cv.
  xy = np.concatenate([r[:, 0], -r[:, 1]])
  fmt = lambda a: ' '.join(f'{x:.9g}' for x in np.ravel(a))
  return f"""
<mujoco>
  <statistic extent="1" center="0 0 1"/>
  <visual><map znear="0.01" zfar="20"/></visual>
  <asset>
    <mesh name="cloth" vertex="{fmt(verts)}" face="{fmt(both)}" inertia="shell"/>
  </asset>
  <worldbody>
    <geom type="mesh" mesh="cloth" contype="0" conaffinity="0"/>
    <camera name="cam" pos="{fmt(pose.position)}" xyaxes="{fmt(xy)}" fovy="{fovy}"/>
  </worldbody>
</mujoco>"""


def test_depth_matches_mujoco_opengl_renderer():
  size, fov = 64, 45.0  # square, so MuJoCo's horizontal FoV equals fovy
  intr = camera.Intrinsics(size, size, fov, fov)
  m = mesh.square(9)
  v = m.vertices.copy()
  x, z = v[:, 0], v[:, 2]
  v[:, 1] = 0.3 * (1.5 - z) ** 2 + 0.08 * np.sin(5 * x) * (1.5 - z)  # swung, rippled
  pose = camera.look_at([0.5, -1.9, 1.25], [0.0, 0.15, 1.0], roll_deg=4.0)
  model = mujoco.MjModel.from_xml_string(_mjcf(v, m.faces, pose, fov))
  renderer = mujoco_gl.offscreen_renderer(model, size, size)
  ref = gl_depth.mujoco_depth(model, renderer, far=0.9 * 20.0)  # far plane: background
  ours = np.asarray(_depth(v, m.faces, intr, pose))
  valid = (ref > 0) & (ours > 0)
  interior = valid.copy()
  for axis in (0, 1):  # erode by 1 px so silhouette pixels are left out
    for shift in (-1, 1):
      interior &= np.roll(valid, shift, axis=axis)
  assert interior.sum() > 0.2 * size * size
  close = np.abs(ours - ref)[interior] < _MUJOCO_DEPTH_TOL
  assert close.mean() >= _MUJOCO_AGREE, (
    close.mean(),
    np.abs(ours - ref)[interior].max(),
  )
  # The silhouettes agree too, apart from pixels on the boundary.
  assert np.mean((ref > 0) != (ours > 0)) < 0.01
