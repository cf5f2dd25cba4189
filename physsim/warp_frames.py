"""MuJoCo Warp a frame at a time: the rollout's substeps inside one graph.

The ``'mjx'`` backend calls ``mjx.step`` once per substep from a ``lax.scan``,
with the wind and bending forces computed in JAX between the calls. This
module runs the same physics with the loop on the other side: one JAX FFI call
(``warp.jax_callable``) per recorded frame advances every world by the
frame's substeps, each substep being the ArcSim face wind and MuJoCo's bending
stencil as Warp kernels followed by MuJoCo Warp's own ``step``. On a GPU the
frame's substeps are captured once as a CUDA graph over persistent MuJoCo
Warp buffers (one set per device and batch size) and replayed every frame;
JAX hands over only the state that carries between frames (``qpos``,
``qvel``, ``qacc_warmstart``) and the per-world inputs.

Physics is the ``'mjx'`` backend's, term for term (``physsim.forces``):
``f = rho A |vn| vn n + drag A vt`` per face, a third per vertex, with the
frozen-turbulence gusts; bending ``-scale (K x + c16 c) - scale damping K v``
per hinge; forces applied as ``xfrc_applied`` on the vertex bodies; per-world
``body_mass``. The forces are summed with atomics, so results agree with the
``'mjx'`` backend to float32 rounding, not bitwise.

Only ``rollout_fn`` (``backend='warp'``) uses this; nothing here is public
beyond ``frame_rollout``.
"""

from __future__ import annotations

import threading
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import warp as wp
from mujoco.mjx.third_party import mujoco_warp as mjw

from physsim import interrupt, one_off
from physsim.cloth import ClothModel

_LOCK = threading.Lock()


@wp.func
def _position(
  qpos: wp.array2d(dtype=float),
  rest: wp.array(dtype=wp.vec3),
  qadr: wp.array(dtype=int),
  w: int,
  v: int,
):
  a = qadr[v]
  x = rest[v]
  if a >= 0:
    x = x + wp.vec3(qpos[w, a], qpos[w, a + 1], qpos[w, a + 2])
  return x


@wp.func
def _velocity(qvel: wp.array2d(dtype=float), qadr: wp.array(dtype=int), w: int, v: int):
  a = qadr[v]
  u = wp.vec3(0.0)
  if a >= 0:
    u = wp.vec3(qvel[w, a], qvel[w, a + 1], qvel[w, a + 2])
  return u


@wp.func
def _push(
  xfrc: wp.array2d(dtype=wp.spatial_vector),
  qadr: wp.array(dtype=int),
  body: wp.array(dtype=int),
  w: int,
  v: int,
  f: wp.vec3,
):
  if qadr[v] >= 0:
    wp.atomic_add(xfrc, w, body[v], wp.spatial_vector(f, wp.vec3(0.0)))


@wp.kernel
def _wind_kernel(
  qpos: wp.array2d(dtype=float),
  qvel: wp.array2d(dtype=float),
  rest: wp.array(dtype=wp.vec3),
  qadr: wp.array(dtype=int),
  body: wp.array(dtype=int),
  faces: wp.array(dtype=wp.vec3i),
  area: wp.array(dtype=float),
  speed: wp.array(dtype=float),
  direction: wp.array(dtype=wp.vec3),
  wavevector: wp.array2d(dtype=wp.vec3),
  gust_direction: wp.array2d(dtype=wp.vec3),
  amplitude: wp.array2d(dtype=float),
  phase: wp.array2d(dtype=float),
  time: wp.array(dtype=float),
  offset: float,
  density: float,
  drag: float,
  xfrc: wp.array2d(dtype=wp.spatial_vector),
):
  w, f = wp.tid()
  i = faces[f]
  x0 = _position(qpos, rest, qadr, w, i[0])
  x1 = _position(qpos, rest, qadr, w, i[1])
  x2 = _position(qpos, rest, qadr, w, i[2])
  s = speed[w]
  d = direction[w]
  advected = (x0 + x1 + x2) / 3.0 - s * (time[0] + offset) * d
  fluct = wp.vec3(0.0)
  for m in range(wavevector.shape[1]):
    arg = wp.dot(wavevector[w, m], advected) + phase[w, m]
    fluct = fluct + amplitude[w, m] * wp.sin(arg) * gust_direction[w, m]
  vrel = (
    s * (d + fluct)
    - (
      _velocity(qvel, qadr, w, i[0])
      + _velocity(qvel, qadr, w, i[1])
      + _velocity(qvel, qadr, w, i[2])
    )
    / 3.0
  )
  n = wp.cross(x1 - x0, x2 - x0)
  n = n / wp.max(wp.length(n), 1e-12)
  vn = wp.dot(n, vrel)
  force = area[f] * (density * wp.abs(vn) * vn * n + drag * (vrel - vn * n)) / 3.0
  _push(xfrc, qadr, body, w, i[0], force)
  _push(xfrc, qadr, body, w, i[1], force)
  _push(xfrc, qadr, body, w, i[2], force)


@wp.func
def _stencil_row(k: wp.mat44, r: int, a: wp.vec3, b: wp.vec3, c: wp.vec3, d: wp.vec3):
  return k[r, 0] * a + k[r, 1] * b + k[r, 2] * c + k[r, 3] * d


@wp.kernel
def _bending_kernel(
  qpos: wp.array2d(dtype=float),
  qvel: wp.array2d(dtype=float),
  rest: wp.array(dtype=wp.vec3),
  qadr: wp.array(dtype=int),
  body: wp.array(dtype=int),
  hinges: wp.array(dtype=wp.vec4i),
  coef: wp.array(dtype=wp.mat44),
  c16: wp.array(dtype=float),
  scale: wp.array(dtype=float),
  damping: float,
  xfrc: wp.array2d(dtype=wp.spatial_vector),
):
  w, h = wp.tid()
  i = hinges[h]
  p0 = _position(qpos, rest, qadr, w, i[0])
  p1 = _position(qpos, rest, qadr, w, i[1])
  p2 = _position(qpos, rest, qadr, w, i[2])
  p3 = _position(qpos, rest, qadr, w, i[3])
  v0 = _velocity(qvel, qadr, w, i[0])
  v1 = _velocity(qvel, qadr, w, i[1])
  v2 = _velocity(qvel, qadr, w, i[2])
  v3 = _velocity(qvel, qadr, w, i[3])
  e0 = p1 - p0
  e1 = p2 - p0
  e2 = p3 - p0
  c1 = wp.cross(e1, e2)
  c2 = wp.cross(e2, e0)
  c3 = wp.cross(e0, e1)
  k = coef[h]
  g = c16[h]
  s = -scale[w]
  f0 = _stencil_row(k, 0, p0, p1, p2, p3) - g * (c1 + c2 + c3)
  f1 = _stencil_row(k, 1, p0, p1, p2, p3) + g * c1
  f2 = _stencil_row(k, 2, p0, p1, p2, p3) + g * c2
  f3 = _stencil_row(k, 3, p0, p1, p2, p3) + g * c3
  f0 = f0 + damping * _stencil_row(k, 0, v0, v1, v2, v3)
  f1 = f1 + damping * _stencil_row(k, 1, v0, v1, v2, v3)
  f2 = f2 + damping * _stencil_row(k, 2, v0, v1, v2, v3)
  f3 = f3 + damping * _stencil_row(k, 3, v0, v1, v2, v3)
  _push(xfrc, qadr, body, w, i[0], s * f0)
  _push(xfrc, qadr, body, w, i[1], s * f1)
  _push(xfrc, qadr, body, w, i[2], s * f2)
  _push(xfrc, qadr, body, w, i[3], s * f3)


class _Inputs(NamedTuple):
  """Per-world inputs a frame reads (persistent copies on one device)."""

  time: wp.array
  speed: wp.array
  direction: wp.array
  bending: wp.array
  wavevector: wp.array
  gust_direction: wp.array
  amplitude: wp.array
  phase: wp.array


class _Worlds:
  """MuJoCo Warp's model and data for ``nworld`` worlds on one device, the
  cloth's constant arrays, persistent inputs, and the frame's graph."""

  def __init__(self, model: ClothModel, nworld: int, modes: int, substeps: int, device):
    mjm = model.mj_model
    self.model, self.substeps, self.graph = model, substeps, None
    with wp.ScopedDevice(device):
      self.m = mjw.put_model(mjm, batch_sizes={'body_mass': nworld})
      # The cloth has no contacts, and CG stopping at its iteration cap is the
      # setting chosen (as the 'mjx' backend).
      self.m.opt.run_collision_detection = False
      self.m.opt.warn_overflow = int(self.m.opt.warn_overflow) & ~int(
        mjw.OverflowType.ITERATIONS
      )
      mjd = mujoco.MjData(mjm)
      self.d = mjw.put_data(mjm, mjd, nworld=nworld, njmax=max(mjm.nflexedge, 1) + 8)
      mesh = model.mesh
      self.rest = wp.array(mesh.vertices, dtype=wp.vec3)
      self.qadr = wp.array(model.vert_qadr, dtype=int)
      self.body = wp.array(model.vert_body, dtype=int)
      self.faces = wp.array(mesh.faces, dtype=wp.vec3i)
      self.area = wp.array(mesh.face_areas, dtype=float)
      self.hinges = wp.array(model.hinge_verts, dtype=wp.vec4i)
      self.coef = wp.array(model.hinge_coef, dtype=wp.mat44)
      self.c16 = wp.array(model.hinge_c16, dtype=float)
      self.inputs = _Inputs(
        time=wp.zeros(1, dtype=float),
        speed=wp.zeros(nworld, dtype=float),
        direction=wp.zeros(nworld, dtype=wp.vec3),
        bending=wp.zeros(nworld, dtype=float),
        wavevector=wp.zeros((nworld, modes), dtype=wp.vec3),
        gust_direction=wp.zeros((nworld, modes), dtype=wp.vec3),
        amplitude=wp.zeros((nworld, modes), dtype=float),
        phase=wp.zeros((nworld, modes), dtype=float),
      )

  def forces(self, s: int):
    """Launches substep ``s``'s wind and bending into ``xfrc_applied``."""
    cfg, d, x = self.model.config, self.d, self.inputs
    nworld = d.qpos.shape[0]
    d.xfrc_applied.zero_()
    wp.launch(
      _wind_kernel,
      dim=(nworld, self.faces.shape[0]),
      inputs=[
        d.qpos, d.qvel, self.rest, self.qadr, self.body, self.faces, self.area,
        x.speed, x.direction, x.wavevector, x.gust_direction, x.amplitude,
        x.phase, x.time, float(s * cfg.timestep), float(cfg.air_density),
        float(cfg.air_drag), d.xfrc_applied,
      ],
    )  # fmt: skip
    if self.hinges.shape[0]:
      wp.launch(
        _bending_kernel,
        dim=(nworld, self.hinges.shape[0]),
        inputs=[
          d.qpos, d.qvel, self.rest, self.qadr, self.body, self.hinges,
          self.coef, self.c16, x.bending, float(cfg.bending_damping),
          d.xfrc_applied,
        ],
      )  # fmt: skip

  def _substeps(self):
    """The frame: ``substeps`` x (forces, MuJoCo Warp step)."""
    for s in range(self.substeps):
      self.forces(s)
      mjw.step(self.m, self.d)

  def load(self, qpos, qvel, warmstart, time, speed, direction, bending,
           wavevector, gust_direction, amplitude, phase, body_mass):  # fmt: skip
    """Copies a frame's state and the worlds' inputs into the buffers."""
    x = self.inputs
    for dst, src in (
      (self.d.qpos, qpos), (self.d.qvel, qvel), (self.d.qacc_warmstart, warmstart),
      (self.m.body_mass, body_mass), (x.time, time), (x.speed, speed),
      (x.direction, direction), (x.bending, bending), (x.wavevector, wavevector),
      (x.gust_direction, gust_direction), (x.amplitude, amplitude), (x.phase, phase),
    ):  # fmt: skip
      wp.copy(dst, src)

  def store(self, qpos, qvel, warmstart):
    """Copies the state that carries to the next frame out of the buffers."""
    wp.copy(qpos, self.d.qpos)
    wp.copy(qvel, self.d.qvel)
    wp.copy(warmstart, self.d.qacc_warmstart)

  def run(self):
    """Advances every world by one frame (a graph replay on a GPU)."""
    if self.graph is not None:
      wp.capture_launch(self.graph)
      return
    if not self.d.qpos.device.is_cuda:
      self._substeps()
      return
    # First call on this GPU: the frame runs eagerly (loading every kernel),
    # then is captured against the persistent buffers, to be replayed by
    # every later call.
    self._substeps()
    with wp.ScopedCapture() as capture:
      self._substeps()
    self.graph = capture.graph


def _frame_callable(model: ClothModel, substeps: int):
  """The FFI call that advances a batch by one frame (see module doc)."""
  worlds: dict = {}
  clock = time.perf_counter  # ``time`` is a frame's argument below

  def frame(
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    warmstart: wp.array2d(dtype=float),
    time: wp.array(dtype=float),
    speed: wp.array(dtype=float),
    direction: wp.array(dtype=wp.vec3),
    bending: wp.array(dtype=float),
    wavevector: wp.array2d(dtype=wp.vec3),
    gust_direction: wp.array2d(dtype=wp.vec3),
    amplitude: wp.array2d(dtype=float),
    phase: wp.array2d(dtype=float),
    body_mass: wp.array2d(dtype=float),
  ):
    with interrupt.deferred():  # Ctrl-C here cannot unwind (physsim.interrupt)
      if interrupt.pending():  # the run is stopping: NaN worlds, at once
        qpos.fill_(float('nan'))
        return
      # One set of buffers per device and batch shape; calls are serialised
      # (Warp's FFI lock), so shards of one device may share it.
      device, nworld, modes = qpos.device, qpos.shape[0], wavevector.shape[1]
      key = (device.alias, nworld, modes)
      t0 = clock()
      with _LOCK:
        first = key not in worlds
        if first:
          worlds[key] = _Worlds(model, nworld, modes, substeps, device)
      st = worlds[key]
      st.load(qpos, qvel, warmstart, time, speed, direction, bending, wavevector,
              gust_direction, amplitude, phase, body_mass)  # fmt: skip
      st.run()
      if first:  # buffers, kernels and the graph: once per device and batch
        one_off.add_setup(device.alias, clock() - t0)
      st.store(qpos, qvel, warmstart)

  # The state is updated in place (aliased buffers); the graph is Warp's own,
  # over persistent buffers, so JAX's buffer addresses never matter.
  return wp.jax_callable(
    frame,
    num_outputs=3,
    graph_mode=wp.JaxCallableGraphMode.NONE,
    in_out_argnames=('qpos', 'qvel', 'warmstart'),
  )


def frame_rollout(model: ClothModel, frames: int, substeps: int, warm_frames: int):
  """A traceable ``(WorldInputs) -> positions (B, T, V, 3)`` on MuJoCo Warp a
  frame at a time (module doc)."""
  step = _frame_callable(model, substeps)
  interrupt.defer_in(wp.jax_callable)  # Warp's FFI wrapper runs the frame
  interrupt.install()
  mjm = model.mj_model
  rest = jnp.asarray(model.mesh.vertices, jnp.float32)
  moving = np.flatnonzero(model.vert_qadr >= 0)
  qidx = jnp.asarray(model.vert_qadr[moving][:, None] + np.arange(3), jnp.int32)
  frame_time = substeps * model.config.timestep

  def run(w):
    b = w.speed.shape[0]
    state = (
      jnp.broadcast_to(jnp.asarray(mjm.qpos0, jnp.float32), (b, mjm.nq)),
      jnp.zeros((b, mjm.nv), jnp.float32),
      jnp.zeros((b, mjm.nv), jnp.float32),
    )
    g = w.gusts

    def frame(state, i):
      t0 = jnp.reshape(i * frame_time, (1,)).astype(jnp.float32)
      out = step(
        *state,
        t0,
        w.speed,
        w.direction,
        w.bending,
        g.wavevector,
        g.direction,
        g.amplitude,
        g.phase,
        w.body_mass,
      )
      return tuple(out), jnp.broadcast_to(rest, (b, *rest.shape)).at[:, moving].add(
        out[0][:, qidx]
      )

    state, _ = jax.lax.scan(
      lambda s, i: (frame(s, i)[0], None), state, jnp.arange(warm_frames)
    )
    _, xs = jax.lax.scan(frame, state, warm_frames + jnp.arange(frames))
    return jnp.moveaxis(xs, 0, 1)  # (B, T, V, 3)

  return run
