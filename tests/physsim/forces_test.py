"""Tests for physsim.forces: wind against a float64 loop, bending against MuJoCo C."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from physsim import cloth, forces, mesh

_WIND_RTOL = 1e-5  # float32 JAX vs float64 NumPy
_BEND_RTOL = 1e-4


def _wind_reference(x, v, faces, area, u, rho, drag):
  """ArcSim's formula, one face at a time, in float64."""
  out = np.zeros_like(x)
  for f, (i, j, k) in enumerate(faces):
    n = np.cross(x[j] - x[i], x[k] - x[i])
    n /= np.linalg.norm(n)
    vrel = u[f] - (v[i] + v[j] + v[k]) / 3
    vn = n @ vrel
    force = rho * area[f] * abs(vn) * vn * n + drag * area[f] * (vrel - vn * n)
    for a in (i, j, k):
      out[a] += force / 3
  return out


@pytest.mark.parametrize('drag', [0.0, 0.3])
def test_face_wind_matches_float64_loop(drag):
  rng = np.random.default_rng(1)
  m = mesh.square(5)
  x = m.vertices + 0.05 * rng.normal(size=m.vertices.shape)
  v = rng.normal(size=x.shape)
  u = rng.normal(size=(len(m.faces), 3)) + [0, 3, 0]
  got = forces.face_wind_forces(
    jnp.asarray(x, jnp.float32),
    jnp.asarray(v, jnp.float32),
    m.faces,
    jnp.asarray(m.face_areas, jnp.float32),
    jnp.asarray(u, jnp.float32),
    1.2,
    drag,
  )
  want = _wind_reference(x, v, m.faces, m.face_areas, u, 1.2, drag)
  np.testing.assert_allclose(
    got, want, rtol=_WIND_RTOL, atol=_WIND_RTOL * np.abs(want).max()
  )


def test_flat_cloth_in_normal_wind_feels_rho_v2_area():
  m = mesh.square(6)
  f = forces.face_wind_forces(
    m.vertices, np.zeros_like(m.vertices), m.faces, m.face_areas, np.array([0, 3.0, 0])
  )
  np.testing.assert_allclose(
    np.asarray(f).sum(0), [0, 9.0, 0], rtol=1e-5
  )  # 1 * 1 m^2 * 3^2


def test_gusts_have_requested_intensity_and_zero_is_steady():
  key = jax.random.key(3)
  pts = jax.random.uniform(key, (4000, 3)) * 50.0
  d = jnp.array([0.0, 1.0, 0.0])
  g = forces.sample_gusts(key, intensity=0.2, n_modes=16)
  u = forces.wind_velocity(pts, 0.0, 3.0, d, g) / 3.0 - d
  rms = float(jnp.sqrt(jnp.mean(jnp.sum(u**2, -1))))
  assert rms == pytest.approx(0.2, rel=0.15)
  steady = forces.sample_gusts(key, intensity=0.0)
  np.testing.assert_allclose(
    forces.wind_velocity(pts, 1.0, 3.0, d, steady), jnp.broadcast_to(3 * d, pts.shape)
  )


def test_gusts_are_advected_with_the_mean_flow():
  g = forces.sample_gusts(jax.random.key(0), 0.3)
  d = jnp.array([0.0, 1.0, 0.0])
  p = jnp.array([[0.1, 0.2, 0.3]])
  a = forces.wind_velocity(p, 0.0, 2.0, d, g)
  b = forces.wind_velocity(p + 2.0 * 0.5 * d, 0.5, 2.0, d, g)  # moved with the flow
  np.testing.assert_allclose(a, b, rtol=1e-5)


def test_bending_matches_mujoco_passive_force():
  """Our stencil with scale s equals MuJoCo's own bending at rigidity s * D0."""
  m_ours = cloth.build(mesh.square(6), 'black_denim')
  scale = 3.0
  xml = cloth.mjcf(m_ours.mesh, m_ours.config, scale * m_ours.rigidity)
  ref = mujoco.MjModel.from_xml_string(xml)
  # The cloth's MJCF turns MuJoCo's passive pass off (its bending is applied by
  # the rollout); the reference turns it back on, and gravity off.
  dsbl = mujoco.mjtDisableBit
  ref.opt.disableflags &= ~int(dsbl.mjDSBL_SPRING | dsbl.mjDSBL_DAMPER)
  ref.opt.disableflags |= dsbl.mjDSBL_GRAVITY
  d = mujoco.MjData(ref)
  rng = np.random.default_rng(0)
  d.qpos[:] = 0.02 * rng.normal(size=ref.nq)
  mujoco.mj_forward(ref, d)
  moving = m_ours.vert_qadr >= 0
  x = m_ours.mesh.vertices.copy()
  x[moving] += d.qpos[m_ours.vert_qadr[moving][:, None] + np.arange(3)]
  f = forces.bending_forces(
    x, np.zeros_like(x), m_ours.hinge_verts, m_ours.hinge_coef, m_ours.hinge_c16, scale
  )
  want = d.qfrc_passive[m_ours.vert_qadr[moving][:, None] + np.arange(3)]
  assert np.abs(want).max() > 0
  np.testing.assert_allclose(np.asarray(f)[moving], want, rtol=_BEND_RTOL, atol=1e-9)


def test_bending_force_vanishes_flat_and_scales_linearly():
  m = cloth.build(mesh.square(5))
  args = (m.hinge_verts, m.hinge_coef, m.hinge_c16)
  flat = forces.bending_forces(m.mesh.vertices, 0 * m.mesh.vertices, *args, 1.0)
  np.testing.assert_allclose(flat, 0, atol=1e-9)  # float32 rounding of O(1e-5) terms
  x = m.mesh.vertices + 0.01 * np.random.default_rng(0).normal(
    size=m.mesh.vertices.shape
  )
  f1 = forces.bending_forces(x, 0 * x, *args, 1.0)
  f7 = forces.bending_forces(x, 0 * x, *args, 7.0)
  np.testing.assert_allclose(f7, 7 * np.asarray(f1), rtol=1e-6)
