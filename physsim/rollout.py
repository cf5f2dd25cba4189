"""Batched cloth rollouts on MuJoCo Warp (two ways) and the MuJoCo C oracle.

``simulate`` takes a batch of parameter sets and returns vertex positions at the
frame rate, ``(batch, frames, vertices, 3)``, and a per-world validity flag.
Every backend runs the same physics: MuJoCo integrates (Euler) with edge
equality constraints; each substep the rollout computes ArcSim's face wind
(with optional gusts) and MuJoCo's bending stencil times the world's bending
scale, and applies them as ``xfrc_applied`` on the vertex bodies.

Backends (``BACKENDS``; ``'auto'`` picks ``'warp'`` on a GPU, else ``'c'``):

* ``'warp'``: MuJoCo Warp a frame at a time (``physsim.warp_frames``): one
  JAX FFI call per recorded frame runs its substeps, the forces as Warp
  kernels, captured once as a CUDA graph. The fastest on a GPU.
* ``'mjx'``: ``mjx.step`` (``impl='warp'``) per substep inside a
  ``lax.scan``, the forces in JAX between the steps. The same kernels, one
  hand-over per substep; kept as a cross-check of ``'warp'``.
* ``'c'``: MuJoCo C in worker threads (MuJoCo releases the GIL while it
  steps), float64 NumPy forces: the oracle, and the fastest on a CPU.

Per-world fields (``WorldInputs``: ``body_mass`` from the area weight, wind
speed, direction, gusts and bending scale) are all arrays, so new values never
recompile. Frame count, substeps, mesh and batch size are static.

Two ways in: ``simulate`` (NumPy in, NumPy out, validated) for sweeps and
studies, and ``world_inputs`` + ``rollout_fn`` (traceable, not jitted) for a
pipeline that fuses simulation with rendering and scoring under one ``jit``.
A ``ClothModel`` keeps what it compiles (``ClothModel.programs``). The
inputs are in ``rollout_inputs``, the forces in ``rollout_forces``; this module
runs them on each backend.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import importlib
import os
import threading
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from physsim import forces, interrupt
from physsim import params as params_lib
from physsim.cloth import ClothModel, build, reference_rigidity
from physsim.devices import mesh_key, shard_worlds, world_mesh
from physsim.rollout_forces import (
  applied_forces,
  applied_forces_np,
  consts,
  np_consts,
)
from physsim.rollout_inputs import (
  MAX_DISPLACEMENT,
  MAX_SPEED,
  Wind,
  WorldInputs,
  check_wind,
  frame_plan,
  valid_worlds,
  world_inputs,
  world_keys,
)

# The inputs' names, importable from here as before.
__all__ = [
  'BACKENDS', 'MAX_DISPLACEMENT', 'MAX_SPEED', 'Rollout', 'Wind', 'WorldInputs',
  'check_wind', 'cpu_only_children', 'jit_program', 'material_ratio', 'prefetch',
  'resolve_backend', 'rollout_fn', 'simulate', 'world_inputs',
]  # fmt: skip
# The rollout's parts under the names they had here: the backends below call
# the forces through these (tests and benchmarks swap them in).
_applied_forces = applied_forces
_applied_forces_np = applied_forces_np
_consts = consts
_np_consts = np_consts
_frame_plan = frame_plan
_world_keys = world_keys
_valid = valid_worlds


class Rollout(NamedTuple):
  """Result of ``simulate``.

  Attributes:
    positions: (B, T, V, 3) float32 vertex positions at the frame times, m.
    valid: (B,) bool, False where the world produced NaN or blew up.
    times: (T,) float seconds of each frame after the warm-up.
  """

  positions: np.ndarray
  valid: np.ndarray
  times: np.ndarray

  def check(self) -> Rollout:
    """Returns self, or raises ValueError listing the worlds that blew up."""
    bad = np.flatnonzero(~self.valid)
    if bad.size:
      raise ValueError(f'simulation blew up (NaN or runaway) in worlds {bad.tolist()}')
    return self


# ---------------------------------------------------------------- MJX backend


def _mjx_rollout(model: ClothModel, frames: int, substeps: int, warm_frames: int):
  """A traceable ``(WorldInputs) -> (positions (B,T,V,3), valid (B,))``."""
  from mujoco import mjx  # imported lazily: the C backend works without it

  m = model.mj_model
  from mujoco.mjx.third_party import mujoco_warp as mjw
  from mujoco.mjx.warp import types as mjx_warp_types

  mode = model.config.graph_mode
  graph_mode = (
    None if mode == 'auto' else getattr(mjx_warp_types.GraphMode, mode.upper())
  )
  mx = mjx.put_model(m, impl='warp', graph_mode=graph_mode)
  # The cloth has no contacts, and CG stopping at its iteration cap is expected
  # (the cap is the setting we chose): skip the collision pass, keep the other
  # overflow warnings (e.g. constraint buffers).
  opt_impl = mx.opt._impl.replace(
    run_collision_detection=False,
    warn_overflow=mx.opt._impl.warn_overflow & ~int(mjw.OverflowType.ITERATIONS),
  )
  mx = mx.replace(opt=mx.opt.replace(_impl=opt_impl))
  d0 = mjx.make_data(m, impl='warp', njmax=max(m.nflexedge, 1) + 8)
  c = _consts(model, jnp.float32)
  dt = model.config.timestep
  nbody = m.nbody

  def world(w: WorldInputs, d):
    mxw = mx.replace(body_mass=w.body_mass)

    def substep(d, t):
      f = _applied_forces(c, model, d.qpos, d.qvel, t, w)
      xfrc = jnp.zeros((nbody, 6), f.dtype).at[c.body, :3].set(f)
      return mjx.step(mxw, d.replace(xfrc_applied=xfrc)), None

    def frame(d, i):
      d, _ = jax.lax.scan(substep, d, (i * substeps + jnp.arange(substeps)) * dt)
      return d, c.rest.at[c.moving].add(d.qpos[c.qidx])

    d, _ = jax.lax.scan(lambda d, i: (frame(d, i)[0], None), d, jnp.arange(warm_frames))
    _, xs = jax.lax.scan(frame, d, warm_frames + jnp.arange(frames))
    return xs  # (T, V, 3)

  def run(w: WorldInputs):
    # d0 is shared: MJX-warp broadcasts the data fields it writes per world.
    xs = jax.vmap(world, in_axes=(0, None))(w, d0)  # (B, T, V, 3)
    return xs, _valid(xs, c.rest)

  return run


def _warp_rollout(model: ClothModel, frames: int, substeps: int, warm_frames: int):
  """A traceable ``(WorldInputs) -> (positions (B,T,V,3), valid (B,))`` on
  MuJoCo Warp a frame at a time (``physsim.warp_frames``)."""
  from physsim import warp_frames  # imported lazily: the C backend works without it

  run = warp_frames.frame_rollout(model, frames, substeps, warm_frames)
  rest = jnp.asarray(model.mesh.vertices, jnp.float32)

  def fn(w: WorldInputs):
    xs = run(w)
    return xs, _valid(xs, rest)

  return fn


# ------------------------------------------------------------ MuJoCo C backend


@contextlib.contextmanager
def cpu_only_children():
  """Processes spawned inside keep JAX on the CPU (they must not grab the GPU)."""
  saved = {
    k: os.environ.get(k) for k in ('JAX_PLATFORMS', 'XLA_PYTHON_CLIENT_PREALLOCATE')
  }
  os.environ.update(JAX_PLATFORMS='cpu', XLA_PYTHON_CLIENT_PREALLOCATE='false')
  try:
    yield
  finally:
    for k, v in saved.items():
      if v is None:
        os.environ.pop(k, None)
      else:
        os.environ[k] = v


def _c_world(model: ClothModel, w: dict, frames: int, substeps: int, warm_frames: int):
  """One world on MuJoCo C; returns (T, V, 3) float64 positions."""
  m = model.mj_model
  d = mujoco.MjData(m)
  saved = m.body_mass.copy(), m.dof_M0.copy()
  c = _np_consts(model)
  moving = c.moving
  dt = model.config.timestep
  out = np.empty((frames, model.n_vertices, 3))
  try:
    m.body_mass[:] = w['body_mass']
    # MuJoCo C takes the mass of "simple" slide-joint bodies from the compiled
    # dof_M0, not body_mass; MuJoCo Warp recomputes it from body_mass.
    m.dof_M0[c.qidx] = w['body_mass'][c.body][:, None]
    for i in range(warm_frames + frames):
      if interrupt.pending():  # Ctrl-C inside the callback (physsim.interrupt)
        out[max(i - warm_frames, 0) :] = np.nan
        break
      for s in range(substeps):
        f = _applied_forces_np(c, model, d.qpos, d.qvel, (i * substeps + s) * dt, w)
        d.xfrc_applied[c.body, :3] = f
        mujoco.mj_step(m, d)
      if i >= warm_frames:
        x = model.mesh.vertices.copy()
        x[moving] += d.qpos[c.qidx]
        out[i - warm_frames] = x
        if not np.all(np.isfinite(x)):
          out[i - warm_frames :] = np.nan
          break
  finally:
    m.body_mass[:], m.dof_M0[:] = saved
  return out


def _np_world_inputs(w: dict, i: int) -> dict:
  g = forces.Gusts(*(np.asarray(a[i], np.float64) for a in w['gusts']))
  return {k: (g if k == 'gusts' else np.asarray(w[k][i], np.float64)) for k in w}


def _c_threads(model: ClothModel, workers: int):
  """The model's ``workers`` threads for MuJoCo C, each with its own compiled
  copy of the cloth (``_c_world`` sets a world's masses on the MjModel it is
  given), started once and kept with the model.

  Threads, not processes: MuJoCo releases the GIL inside ``mj_step``, where a
  rollout spends its time, so threads use the cores as worker processes did,
  and a library user's plain script (no ``if __name__ == '__main__'`` guard,
  which spawned processes re-import) works.
  """
  key = ('c_threads', workers)
  if key not in model.programs:
    copies = [model] + [
      build(model.mesh, model.material, model.config) for _ in range(workers - 1)
    ]
    pool = concurrent.futures.ThreadPoolExecutor(workers, 'mujoco-c')
    model.programs[key] = (pool, copies)
  return model.programs[key]


def _c_rollout(model, w: dict, frames, substeps, warm_frames, workers):
  """Host rollout of every world on MuJoCo C: ``w`` holds ``WorldInputs``
  fields as NumPy arrays. Returns (positions (B,T,V,3) float64, valid (B,))."""
  b = int(w['speed'].shape[0])
  worlds = [_np_world_inputs(w, i) for i in range(b)]
  workers = min(workers, b)
  if workers <= 1:
    xs = [_c_world(model, wi, frames, substeps, warm_frames) for wi in worlds]
  else:
    pool, copies = _c_threads(model, workers)
    chunks = [worlds[i::workers] for i in range(workers)]
    parts = list(
      pool.map(
        lambda k: [
          _c_world(copies[k], wi, frames, substeps, warm_frames) for wi in chunks[k]
        ],
        range(workers),
      )
    )
    xs = [None] * b
    for i, part in enumerate(parts):
      for j, x in enumerate(part):
        xs[i + j * workers] = x
  xs = np.stack(xs)
  finite = np.all(np.isfinite(xs), axis=(1, 2, 3))
  disp = np.nanmax(np.abs(xs - model.mesh.vertices), axis=(1, 2, 3))
  return xs, finite & (disp < MAX_DISPLACEMENT)


def _c_callback_rollout(
  model: ClothModel, frames: int, substeps: int, warm_frames: int, workers: int
):
  """MuJoCo C as a traceable ``(WorldInputs) -> (positions, valid)``: a
  ``jax.pure_callback`` to the host rollout, so a jitted pipeline keeps one
  shape whichever backend simulates."""
  v = model.n_vertices

  def host(w):
    with interrupt.deferred():  # Ctrl-C here cannot unwind (physsim.interrupt)
      w = jax.tree.map(np.asarray, w)._asdict()
      xs, valid = _c_rollout(model, w, frames, substeps, warm_frames, workers)
      return xs.astype(np.float32), valid

  interrupt.defer_in(jax.pure_callback)  # JAX's wrapper runs the host rollout
  interrupt.install()

  def run(w: WorldInputs):
    b = w.speed.shape[0]
    out = (
      jax.ShapeDtypeStruct((b, frames, v, 3), jnp.float32),
      jax.ShapeDtypeStruct((b,), jnp.bool_),
    )
    return jax.pure_callback(host, out, w)

  return run


# ------------------------------------------------------------------ public API


BACKENDS = ('auto', 'warp', 'mjx', 'c')


def resolve_backend(name: str) -> str:
  """``'auto'`` -> ``'warp'`` on a GPU, else ``'c'`` (MuJoCo Warp on a CPU is
  ~10x slower than MuJoCo C); ``'warp'``, ``'mjx'`` and ``'c'`` pass through."""
  if name == 'auto':
    return 'warp' if jax.default_backend() == 'gpu' else 'c'
  if name not in BACKENDS:
    raise ValueError(f'backend must be one of {BACKENDS}, got {name!r}')
  return name


# What a backend's rollout imports on first use: seconds of Python (MuJoCo
# Warp defines its kernels as its modules load, MJX builds its JAX functions).
_BACKEND_MODULES = {'warp': 'physsim.warp_frames', 'mjx': 'mujoco.mjx'}


def prefetch(backend: str = 'auto') -> threading.Thread | None:
  """Starts importing ``backend``'s simulator modules in a background thread,
  so that a process that will simulate on it reads and aligns its recording
  meanwhile; the rollout's own import later finds them loaded, or waits for
  the thread (Python imports a module once). Returns the thread, or None
  where there is nothing to import (MuJoCo C). An import that fails there is
  left to fail again, with its error, where the rollout imports it."""
  name = _BACKEND_MODULES.get(resolve_backend(backend))
  if name is None:
    return None

  def load():
    try:
      importlib.import_module(name)
    except Exception:  # noqa: BLE001 - see the docstring
      pass

  t = threading.Thread(target=load, name=f'prefetch {name}', daemon=True)
  t.start()
  return t


def rollout_fn(
  model: ClothModel,
  *,
  frames: int = 60,
  fps: float = 20.0,
  warmup: float = 1.0,
  backend: str = 'auto',
  workers: int | None = None,
):
  """The rollout as a traceable ``(WorldInputs) -> (positions, valid)``.

  Not jitted: callers fuse it with what follows (rendering, scoring) under
  their own ``jax.jit``. Built once per setting and kept with the model.

  Args:
    model: compiled cloth.
    frames, fps, warmup: the frame plan (as ``simulate``).
    backend: ``'warp'`` (MuJoCo Warp a frame at a time, ``physsim.warp_frames``),
      ``'mjx'`` (``mjx.step`` per substep in a ``lax.scan``), ``'c'`` (MuJoCo
      C through a host callback, ``workers`` threads; default all cores) or
      ``'auto'`` (``resolve_backend``).
    workers: see ``backend``.

  Returns:
    ``fn(w) -> (positions (B, T, V, 3) float32, valid (B,) bool)``.
  """
  substeps, warm_frames = _frame_plan(model, frames, fps, warmup)
  backend = resolve_backend(backend)
  workers = workers or os.cpu_count() or 1
  key = ('rollout', backend, frames, substeps, warm_frames)
  key += (workers,) if backend == 'c' else ()
  if key not in model.programs:
    if backend == 'mjx':
      fn = _mjx_rollout(model, frames, substeps, warm_frames)
    elif backend == 'warp':
      fn = _warp_rollout(model, frames, substeps, warm_frames)
    else:
      fn = _c_callback_rollout(model, frames, substeps, warm_frames, workers)
    model.programs[key] = fn
  return model.programs[key]


def jit_program(
  model: ClothModel,
  frames: int = 60,
  fps: float = 20.0,
  warmup=1.0,
  devices=None,
  backend: str = 'warp',
):
  """The jitted rollout ``(WorldInputs) -> (positions, valid)`` that
  ``simulate`` runs on a device backend (``'warp'`` or ``'mjx'``), its worlds
  split over ``devices`` (default: every local device; ``physsim.devices``).
  Kept with the model; exposed for benchmarks and tests."""
  if backend not in ('warp', 'mjx'):
    raise ValueError(f"jit_program runs 'warp' or 'mjx', got {backend!r}")
  substeps, warm_frames = _frame_plan(model, frames, fps, warmup)
  mesh = world_mesh(devices)
  key = ('jit', backend, frames, substeps, warm_frames, mesh_key(mesh))
  if key not in model.programs:
    fn = rollout_fn(model, frames=frames, fps=fps, warmup=warmup, backend=backend)
    model.programs[key] = jax.jit(shard_worlds(fn, mesh))
  return model.programs[key]


def material_ratio(model: ClothModel, material, b: int) -> np.ndarray:
  """(B,) reference rigidity of each world's fabric over the model's (1 where
  ``material`` is None); raises ValueError on a count mismatch."""
  if material is None:
    return np.ones(b)
  names = [material] * b if isinstance(material, str) else list(material)
  if len(names) != b:
    raise ValueError(f'material names {len(names)} for a batch of {b} worlds')
  return np.array([reference_rigidity(n) for n in names]) / model.rigidity


def simulate(
  model: ClothModel,
  params: params_lib.Params,
  *,
  frames: int = 60,
  fps: float = 20.0,
  warmup: float = 1.0,
  wind: Wind | None = None,
  key: jax.Array | None = None,
  backend: str = 'auto',
  space: params_lib.SearchSpace | None = None,
  workers: int | None = None,
  material: str | Sequence[str] | None = None,
  devices: Sequence[jax.Device] | None = None,
) -> Rollout:
  """Simulates a batch of parameter sets (host in, host out).

  Args:
    model: compiled cloth (``physsim.cloth.build``).
    params: ``Params`` with fields of shape (B,) (scalars count as B = 1).
    frames: recorded frames T (the paper: 60).
    fps: frame rate (the paper: 20 Hz); 1/fps must be a multiple of the timestep.
    warmup: seconds simulated from rest before the first recorded frame.
    wind: direction and gusts; default steady wind normal to the cloth.
    key: PRNG key for the gusts, split into one sub-key per world; or a
      batch of B keys, one per world (the same key for every world gives
      every world the same gusts: common random numbers).
    backend: ``'warp'`` (MuJoCo Warp, batched, a frame's substeps per call),
      ``'mjx'`` (MuJoCo Warp through ``mjx.step``, one call per substep), ``'c'``
      (MuJoCo C, one world at a time, float64 forces; the oracle and CPU
      fallback) or ``'auto'`` (``'warp'`` on a GPU, else ``'c'``).
    space: allowed parameter ranges (default: the union over the paper's fabrics).
    workers: threads for the C backend (default: all cores).
    material: the fabric (or one per world) whose measured bending a scale of 1
      means; default the model's. MuJoCo's bending stencil is linear in the
      rigidity, so one compiled model simulates every material of the same
      mesh: worlds of different fabrics share a batch and nothing recompiles.
    devices: the devices the MJX backend splits the worlds over (default:
      every local device, e.g. all GPUs of the machine).

  Returns:
    ``Rollout`` with positions (B, T, V, 3) and validity (B,).

  Raises:
    ValueError: parameters out of range or not finite, bad frame plan or wind.
  """
  params = params_lib.validate(params, space)
  params = params_lib.make(*(np.atleast_1d(p) for p in params))
  if params.bending_scale.ndim != 1:
    raise ValueError(
      f'params must be scalars or 1-D batches, got {params.bending_scale.shape}'
    )
  b = params.bending_scale.shape[0]
  ratio = material_ratio(model, material, b)
  wind = wind or Wind()
  check_wind(wind)
  substeps, warm_frames = _frame_plan(model, frames, fps, warmup)
  backend = resolve_backend(backend)
  keys = _world_keys(key, b, wind)
  times = np.arange(frames) / fps
  if backend != 'c':
    w = world_inputs(model, *params, keys, wind, ratio)
    xs, valid = jit_program(model, frames, fps, warmup, devices, backend)(w)
    xs, valid = np.asarray(xs), np.asarray(valid)
    interrupt.raise_if_pending()  # a Ctrl-C during it: the result is not kept
    return Rollout(xs, valid, times)
  # The oracle keeps float64 parameters and masses (the gusts are float32).
  w = world_inputs(model, *params, keys, wind, ratio)._asdict()
  w = jax.tree.map(np.asarray, w)
  w.update(
    body_mass=model.body_masses(params.area_weight),
    speed=params.wind_speed,
    bending=params.bending_scale * ratio,
  )
  xs, valid = _c_rollout(
    model, w, frames, substeps, warm_frames, workers or os.cpu_count() or 1
  )
  return Rollout(xs.astype(np.float32), valid, times)
