"""The forces a rollout applies each substep (wind on the faces, MuJoCo's
bending stencil times the world's bending scale) on the moving vertices:
in JAX for the device backends, in float64 NumPy for MuJoCo C."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from physsim import forces
from physsim.cloth import ClothModel


class Consts(NamedTuple):
  """Static arrays of a ``ClothModel`` as JAX arrays (closed over by jit)."""

  rest: jax.Array  # (V, 3)
  faces: jax.Array  # (F, 3)
  face_area: jax.Array  # (F,)
  moving: np.ndarray  # (Vm,) vertices with dofs
  qidx: jax.Array  # (Vm, 3) qpos/qvel indices of those vertices
  body: jax.Array  # (Vm,) their body ids
  hinge_verts: jax.Array
  hinge_coef: jax.Array
  hinge_c16: jax.Array


def consts(model: ClothModel, dtype) -> Consts:
  moving = np.flatnonzero(model.vert_qadr >= 0)
  return Consts(
    rest=jnp.asarray(model.mesh.vertices, dtype),
    faces=jnp.asarray(model.mesh.faces, jnp.int32),
    face_area=jnp.asarray(model.mesh.face_areas, dtype),
    moving=moving,
    qidx=jnp.asarray(model.vert_qadr[moving][:, None] + np.arange(3), jnp.int32),
    body=jnp.asarray(model.vert_body[moving], jnp.int32),
    hinge_verts=jnp.asarray(model.hinge_verts, jnp.int32),
    hinge_coef=jnp.asarray(model.hinge_coef, dtype),
    hinge_c16=jnp.asarray(model.hinge_c16, dtype),
  )


def applied_forces(c: Consts, model: ClothModel, qpos, qvel, t, w):
  """(Vm, 3) wind + bending forces on the moving vertices at time ``t``."""
  x = c.rest.at[c.moving].add(qpos[c.qidx])
  v = jnp.zeros_like(c.rest).at[c.moving].set(qvel[c.qidx])
  centroid = x[c.faces].mean(axis=1)
  u = forces.wind_velocity(centroid, t, w.speed, w.direction, w.gusts)
  cfg = model.config
  f = forces.face_wind_forces(
    x, v, c.faces, c.face_area, u, cfg.air_density, cfg.air_drag
  ) + forces.bending_forces(
    x, v, c.hinge_verts, c.hinge_coef, c.hinge_c16, w.bending, cfg.bending_damping
  )
  return f[c.moving]


def _cross(a, b):
  """Row-wise cross product of (N, 3) arrays (``np.cross`` costs more in
  overhead than arithmetic at a cloth's sizes)."""
  a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
  b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
  return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def _gather_add(index, values, n):
  """(n, 3) sums of the rows of ``values`` (m, 3) at ``index`` (m,)."""
  return np.stack([np.bincount(index, values[:, k], minlength=n) for k in range(3)], 1)


def applied_forces_np(c, model, qpos, qvel, t, w):
  """``applied_forces`` in float64 NumPy for the MuJoCo C backend."""
  x = c.rest.copy()
  v = np.zeros_like(x)
  x[c.moving] += qpos[c.qidx]
  v[c.moving] = qvel[c.qidx]
  faces = c.faces
  p0, p1, p2 = x[faces[:, 0]], x[faces[:, 1]], x[faces[:, 2]]
  g = w['gusts']
  cen = (p0 + p1 + p2) / 3.0
  arg = (cen - w['speed'] * t * w['direction']) @ g.wavevector.T + g.phase
  u = w['speed'] * (w['direction'] + (np.sin(arg) * g.amplitude) @ g.direction)
  n = _cross(p1 - p0, p2 - p0)
  n /= np.maximum(np.sqrt(np.sum(n * n, axis=1, keepdims=True)), 1e-12)
  vrel = u - (v[faces[:, 0]] + v[faces[:, 1]] + v[faces[:, 2]]) / 3.0
  vn = np.sum(n * vrel, axis=1, keepdims=True)
  cfg = model.config
  fface = c.face_area * (
    cfg.air_density * np.abs(vn) * vn * n + cfg.air_drag * (vrel - vn * n)
  )
  nv = x.shape[0]
  out = _gather_add(c.face_index, np.repeat(fface / 3.0, 3, axis=0), nv)
  hv = model.hinge_verts
  ph = x[hv]
  e0, e1, e2 = ph[:, 1] - ph[:, 0], ph[:, 2] - ph[:, 0], ph[:, 3] - ph[:, 0]
  c1, c2, c3 = _cross(e1, e2), _cross(e2, e0), _cross(e0, e1)
  curved = np.stack([-(c1 + c2 + c3), c1, c2, c3], axis=1)
  fb = model.hinge_coef @ ph + model.hinge_c16[:, None, None] * curved
  if cfg.bending_damping:
    fb += cfg.bending_damping * (model.hinge_coef @ v[hv])
  out += _gather_add(c.hinge_index, -w['bending'] * fb.reshape(-1, 3), nv)
  return out[c.moving]


class NpConsts(NamedTuple):
  """Static arrays of a ``ClothModel`` for the NumPy forces."""

  moving: np.ndarray
  qidx: np.ndarray
  body: np.ndarray
  rest: np.ndarray  # (V, 3)
  faces: np.ndarray  # (F, 3)
  face_area: np.ndarray  # (F, 1)
  face_index: np.ndarray  # (3F,) the faces' vertices, flat
  hinge_index: np.ndarray  # (4H,) the hinges' vertices, flat


def np_consts(model: ClothModel) -> NpConsts:
  moving = np.flatnonzero(model.vert_qadr >= 0)
  faces = np.asarray(model.mesh.faces)
  return NpConsts(
    moving=moving,
    qidx=model.vert_qadr[moving][:, None] + np.arange(3),
    body=model.vert_body[moving],
    rest=np.asarray(model.mesh.vertices, np.float64),
    faces=faces,
    face_area=np.asarray(model.mesh.face_areas, np.float64)[:, None],
    face_index=faces.ravel(),
    hinge_index=np.asarray(model.hinge_verts).ravel(),
  )
