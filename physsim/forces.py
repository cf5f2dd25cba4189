"""Per-vertex forces computed in JAX each substep: ArcSim face wind and bending.

Wind (ArcSim physics.cpp ``wind_force``), per face with unit normal n and rest
area A: ``vrel = u - mean(vertex velocities)``, ``vn = n . vrel``,
``vt = vrel - vn n``, ``f = rho A |vn| vn n + drag A vt``, a third per vertex.

Gusts: a fan's outflow is turbulent. We model it as frozen turbulence (Taylor's
hypothesis): M random Fourier modes advected with the mean flow,
``u(x, t) = v [d + sum_m a_m e_m sin(k_m . (x - v t d) + phi_m)]``, so the
fluctuation's frequencies scale with the wind speed and its ripples travel over
the cloth at that speed. ``sum_m a_m^2 / 2 = intensity^2``: ``intensity`` is the
RMS relative fluctuation (fans: roughly 0.1-0.3).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


class Gusts(NamedTuple):
  """Frozen-turbulence modes of one world (batch with a leading axis).

  Attributes:
    wavevector: (M, 3) k_m, rad/m.
    direction: (M, 3) unit e_m, the direction each mode pushes.
    amplitude: (M,) a_m, relative to the mean speed.
    phase: (M,) phi_m, rad.
  """

  wavevector: jax.Array
  direction: jax.Array
  amplitude: jax.Array
  phase: jax.Array


def _unit(x, axis=-1):
  return x / jnp.linalg.norm(x, axis=axis, keepdims=True)


def sample_gusts(
  key: jax.Array,
  intensity: float = 0.2,
  n_modes: int = 8,
  wavelength: tuple[float, float] = (0.4, 2.0),
) -> Gusts:
  """Draws one world's gust modes; ``intensity=0`` gives steady wind.

  Args:
    key: PRNG key.
    intensity: RMS relative speed fluctuation.
    n_modes: number of Fourier modes M.
    wavelength: (min, max) eddy size in metres, log-uniform.

  Returns:
    ``Gusts`` with leading axis M.
  """
  k_dir, k_len, k_e, k_amp, k_phase = jax.random.split(key, 5)
  lam = jnp.exp(
    jax.random.uniform(
      k_len, (n_modes,), minval=jnp.log(wavelength[0]), maxval=jnp.log(wavelength[1])
    )
  )
  kvec = _unit(jax.random.normal(k_dir, (n_modes, 3))) * (2 * jnp.pi / lam)[:, None]
  raw = jax.random.uniform(k_amp, (n_modes,), minval=0.5, maxval=1.5)
  amp = intensity * jnp.sqrt(2.0) * raw / jnp.linalg.norm(raw)
  return Gusts(
    wavevector=kvec,
    direction=_unit(jax.random.normal(k_e, (n_modes, 3))),
    amplitude=amp,
    phase=jax.random.uniform(k_phase, (n_modes,), maxval=2 * jnp.pi),
  )


def wind_velocity(points, t, speed, direction, gusts: Gusts):
  """Flow velocity (N, 3) at ``points`` (N, 3) and time ``t``, m/s."""
  advected = points - speed * t * direction
  arg = advected @ gusts.wavevector.T + gusts.phase  # (N, M)
  fluct = (jnp.sin(arg) * gusts.amplitude) @ gusts.direction  # (N, 3)
  return speed * (direction + fluct)


def face_wind_forces(x, v, faces, rest_area, wind, density=1.0, drag=0.0):
  """ArcSim's wind force, gathered to vertices.

  Args:
    x: (V, 3) vertex positions.
    v: (V, 3) vertex velocities.
    faces: (F, 3) int vertex indices.
    rest_area: (F,) rest areas, m^2.
    wind: (F, 3) flow velocity at each face (or (3,) uniform).
    density: ArcSim's wind density (1 by default; no 1/2 factor).
    drag: ArcSim's tangential drag coefficient.

  Returns:
    (V, 3) forces, N.
  """
  p = x[faces]
  n = jnp.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
  n = n / jnp.maximum(jnp.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
  vrel = wind - v[faces].mean(axis=1)
  vn = jnp.sum(n * vrel, axis=-1, keepdims=True)
  f = rest_area[:, None] * (density * jnp.abs(vn) * vn * n + drag * (vrel - vn * n))
  return jax.ops.segment_sum(
    jnp.repeat(f / 3.0, 3, axis=0), faces.reshape(-1), num_segments=x.shape[0]
  )


def bending_forces(x, v, hinge_verts, hinge_coef, hinge_c16, scale, damping=0.0):
  """MuJoCo's 2-D flex bending force with a per-world stiffness scale.

  Per hinge (edge vertices then flaps, stencil K): ``f_i = -scale (sum_j K_ij x_j
  + c16 c_i) - scale damping sum_j K_ij v_j``, where c_i are the cross products
  MuJoCo uses for curved rest shapes (c16 = 0 for flat ones).

  Returns:
    (V, 3) forces, N.
  """
  p = x[hinge_verts]  # (H, 4, 3)
  e0, e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
  c1, c2, c3 = jnp.cross(e1, e2), jnp.cross(e2, e0), jnp.cross(e0, e1)
  curved = jnp.stack([-(c1 + c2 + c3), c1, c2, c3], axis=1)
  f = jnp.einsum('hij,hjk->hik', hinge_coef, p) + hinge_c16[:, None, None] * curved
  f = f + damping * jnp.einsum('hij,hjk->hik', hinge_coef, v[hinge_verts])
  return -scale * jax.ops.segment_sum(
    f.reshape(-1, 3), hinge_verts.reshape(-1), num_segments=x.shape[0]
  )
