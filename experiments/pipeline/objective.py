"""The estimate's objective: one fused, jitted simulate-render-sense-embed-score.

A candidate is a point ``u`` of the unit cube ``[-1, 1]^3`` (bending
log-uniform, wind and area weight linear over the material's search box).
``Objective`` maps a batch of candidates of one or several recordings to their
physics similarity distance (PSD) in one ``jax.jit``::

  u (P, q, 3), keys ──► physical parameters ──► rollout (MJX, or MuJoCo C
  through a host callback) ──► blown-up worlds replaced by the rest mesh ──►
  ray-cast from each recording's camera(s) ──► depth-sensor model ──►
  network inputs ──► embedding (each recording's own network params; every
  member of an ensemble) ──► energy distance to the recording's embedding
  (an ensemble's: the members' geometric mean) ──► PSD (P, q), NaN where the
  simulation blew up

or, with ``distance='shape'``, no network: the squared distance between the
sheet's mean shape in the world (``physsim.shape``) in each candidate's frames
and in the recording's (the recording's camera pose is needed), and with
``'energy+shape'`` the geometric mean of that and the PSD.

Nothing returns to the host in between; only the scores come back (and, when
asked, the best candidate's frames or every candidate's positions). The
program depends on the ``Problem.structure`` (mesh, clock, camera model,
network architecture, sensor, distance); recordings of one structure share one
compile and are scored in one call, with their arrays (poses, network params,
embedding of the recording, search box) stacked on a leading axis.

Randomness: every candidate has its own gust and sensor-noise key (explicit
arguments). A posterior search (``point='median'``) draws fresh keys for every
evaluation, so repeated candidates show the simulator's noise, which its GP
models; the paper's argmin (``point='argmin'``) gives all candidates of a
search the same keys (common random numbers: a smoother objective for a
minimiser, at the price of one gust history's bias).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import model as model_lib
import physsim
from experiments.pipeline import embedding

# The settings (a section per stage), re-exported: objective.EstimateConfig, ...
from experiments.pipeline.config import BACKENDS as BACKENDS
from experiments.pipeline.config import DISTANCES as DISTANCES
from experiments.pipeline.config import EMBEDDING_DISTANCES as EMBEDDING_DISTANCES
from experiments.pipeline.config import LIKELIHOODS as LIKELIHOODS
from experiments.pipeline.config import NETWORK_DISTANCE as NETWORK_DISTANCE
from experiments.pipeline.config import PAPER as PAPER
from experiments.pipeline.config import POINTS as POINTS
from experiments.pipeline.config import PRESETS as PRESETS
from experiments.pipeline.config import SECTIONS as SECTIONS
from experiments.pipeline.config import SHAPE_DISTANCES as SHAPE_DISTANCES
from experiments.pipeline.config import EstimateConfig as EstimateConfig
from experiments.pipeline.config import Hardware as Hardware
from experiments.pipeline.config import Scoring as Scoring
from experiments.pipeline.config import Search as Search
from experiments.pipeline.config import record as record
from experiments.pipeline.problem import Problem as Problem
from experiments.pipeline.problem import ProblemData as ProblemData
from experiments.pipeline.problem import make_problem as make_problem
from experiments.pipeline.problem import stack as stack

# The simulation section and its cloth, re-exported (objective.mesh, ...).
from experiments.pipeline.simulation import Simulation as Simulation
from experiments.pipeline.simulation import cloth as cloth
from experiments.pipeline.simulation import mesh as mesh
from experiments.pipeline.simulation import pin_centre as pin_centre
from experiments.pipeline.simulation import sim_config as sim_config


class Scores(NamedTuple):
  """What one ``Objective`` call returns (host arrays).

  Attributes:
    psd: (P, q) float64 PSD, NaN where the simulation blew up.
    valid: (P, q) bool, False where it blew up.
    frames: (P, T, H, W) depth or (P, T, H, W, 3) uint8 colour of each
      problem's lowest-PSD candidate, camera 0, as its network saw them; or
      None when not asked.
    positions: (P, q, T, V, 3) simulated vertex positions, or None.
    residual: (P, q, 2) float64 the candidates' ``physsim.shape.summary``
      minus the recording's (NaN where the PSD is; zeros without a shape
      distance): what the 'synthetic' likelihood is told.
  """

  psd: np.ndarray
  valid: np.ndarray
  frames: np.ndarray | None = None
  positions: np.ndarray | None = None
  residual: np.ndarray | None = None


class Objective:
  """The fused program of one ``Problem.structure``, compiled once per
  (P, q) shape (and count of distinct simulations, where worlds repeat:
  ``distinct_worlds``) and kept by this object (no global caches).

  Call it with stacked ``ProblemData`` of P problems of that structure,
  candidates ``u (P, q, 3)`` and per-candidate keys ``(P, q)``. Worlds whose
  simulations are the same are simulated once and scored each against its own
  recording.
  """

  def __init__(self, problem: Problem):
    c, net = problem.config, problem.net
    s, hw, sc = c.simulation, c.hardware, c.scoring
    self.structure = problem.structure()
    self.cloth = cloth(s)
    self.mesh = self.cloth.mesh
    self.n_frames = problem.n_frames
    self._rollout = physsim.rollout_fn(
      self.cloth, frames=problem.n_frames, fps=s.fps, warmup=s.warmup,
      backend=hw.backend, workers=hw.workers or None,
    )  # fmt: skip
    self._wind = physsim.Wind(gust_intensity=s.gusts)
    self._intr = problem.intr
    self._net = net
    self._sensor = s.sensor_noise and net.modality == 'depth'
    self._distance = sc.distance
    # whether its recordings' cameras carry an error (its size: ProblemData's)
    self._camera_error = bool(sc.camera_sd_m or sc.camera_sd_deg)
    self._pins = pin_centre(s)
    cams, (h, w) = (
      problem.data.poses.position.shape[0],
      (problem.intr.height, problem.intr.width),
    )
    # Worlds scored at once per device (render, sensor, network), from the
    # device's free memory: the network's activations dominate.
    per_world = (
      cams
      * problem.n_frames
      * h
      * w
      * _bytes_per_pixel(net.params)
      * max(net.members, 1)
    )
    self._chunk = physsim.devices.chunk_size(per_world)
    # The worlds of a call split over every local device (MuJoCo Warp), but
    # for a call small enough to cost one step's fixed time on one device
    # (``physsim.devices.mesh_for``); MuJoCo C runs on the host through a
    # callback, whose process pool is the parallelism.
    on_device = physsim.resolve_backend(hw.backend) != 'c'
    self.world_mesh = physsim.devices.world_mesh() if on_device else None
    self._program = jax.jit(
      self._fused, static_argnames=('with_frames', 'with_positions', 'worlds_on')
    )
    self.simulated = 0  # simulations run by the calls so far (``distinct_worlds``)

  def _frames(self, positions, poses, noise_keys, colors):
    """Worlds' frames as their network sees them: (B, C, T, H, W) depth after
    the sensor model, or (B, C, T, H, W, 3) uint8 colour."""
    faces = jnp.asarray(self.mesh.faces, jnp.int32)
    if self._net.modality == 'rgb':  # each fabric's colour, 8 bits, as datasets are
      return physsim.render_rgb8(positions, faces, self._intr, poses, colors)
    frames = physsim.render_depth(positions, faces, self._intr, poses)
    if self._sensor:
      frames = jax.vmap(lambda k, f: physsim.apply_noise_frames(k, f, self._intr))(
        noise_keys, frames
      )
    return frames

  def _simulate(self, x, ratio, gust_keys):
    """One device's worlds simulated: positions (B, T, V, 3) (the rest mesh
    where a world blew up) and validity (B,)."""
    w = physsim.world_inputs(
      self.cloth, x[:, 0], x[:, 1], x[:, 2], gust_keys, self._wind, ratio
    )
    positions, valid = self._rollout(w)  # (B, T, V, 3), (B,)
    rest = jnp.asarray(self.mesh.vertices, positions.dtype)
    return jnp.where(valid[:, None, None, None], positions, rest), valid

  def _score(self, data: ProblemData, positions, owner, noise_keys):
    """One device's simulated worlds rendered, sensed, embedded and scored,
    each against its problem's recording: PSDs (B,) and the shape summaries'
    residuals to the recording's (B, 2) (zeros without a shape distance)."""
    net = self._net

    kind = self._distance

    def score(args):  # one world: render, sense, then its discrepancy
      i, pos, key = args
      pose = jax.tree.map(lambda a: a[i], data.poses)  # (C,)
      seen_from = pose
      if self._camera_error:  # the recording's camera, misplaced as it may be
        sd = data.camera_sd[i]
        seen_from = physsim.shape.misplaced_poses(
          camera_key(key), pose, sd[0], sd[1], self._pins
        )
      frames = self._frames(
        pos[None], jax.tree.map(lambda a: a[None], seen_from), key[None],
        data.color[i][None],
      )[0]  # fmt: skip
      d, resid = [], jnp.zeros(len(physsim.shape.SUMMARY), jnp.float32)
      if kind in EMBEDDING_DISTANCES:  # embed with its problem's net, PSD
        x = embedding.network_inputs(frames, net.modality, net.input_mode)
        params = jax.tree.map(lambda a: a[i], data.params)
        pts = embedding.embed_videos(
          net.network, params, x, net.clip_frames, net.members
        )  # ([K,] C, N, D)
        pts = pts.reshape(*pts.shape[:-3], -1, pts.shape[-1])  # cameras pooled
        psd_kind = 'energy' if kind == 'energy+shape' else kind
        d.append(embedding.video_distance(net, pts, data.rec_points[i], psd_kind))
      if kind in SHAPE_DISTANCES:  # the recording's own camera (C = 1)
        cam = jax.tree.map(lambda a: a[0], pose)
        s = physsim.shape.summary(frames[0], self._intr, cam)
        d.append(physsim.shape.summary_distance(s, data.rec_shape[i]))
        resid = s - data.rec_shape[i]
      d = d[0] if len(d) == 1 else model_lib.psd.geometric_mean(jnp.stack(d))
      return d, resid

    # Worlds in chunks sized from free memory: the network's activations of
    # every frame at once would not fit (paper size: ~8 MB per frame).
    return jax.lax.map(score, (owner, positions, noise_keys), batch_size=self._chunk)

  def _worlds(self, data: ProblemData, x, ratio, gust_keys, owner, noise_keys):
    """One device's worlds: simulate, render, sense, embed and score each
    against its problem's recording (``_simulate``, then ``_score``, on the
    device that simulated them). Returns PSDs (B,), residuals (B, 2), validity
    (B,) and positions (B, T, V, 3)."""
    positions, valid = self._simulate(x, ratio, gust_keys)
    d, resid = self._score(data, positions, owner, noise_keys)
    return d, resid, valid, positions

  def _fused(self, data: ProblemData, u, gust_keys, noise_keys, sims=None, *,
             with_frames, with_positions, worlds_on=None):  # fmt: skip
    p, q = u.shape[:2]
    x = physsim.params.from_unit_traced(
      u, data.lo[:, None], data.hi[:, None], data.log[:, None]
    ).reshape(p * q, 3)  # (Pq, 3) physical
    ratio = jnp.repeat(data.rigidity_ratio, q)
    owner = jnp.arange(p * q) // q  # each world's problem
    noise_keys = noise_keys.reshape(-1)
    gust_keys = gust_keys.reshape(-1)
    # worlds_on: the mesh this call's worlds split over (``__call__``)
    if sims is None:  # every world its own simulation, scored where it ran
      worlds = physsim.devices.shard_worlds(self._worlds, worlds_on, replicated=(0,))
      d, resid, valid, positions = worlds(data, x, ratio, gust_keys, owner, noise_keys)
    else:  # the distinct simulations once (``distinct_worlds``), then every world
      rows, inverse = sims
      simulate = physsim.devices.shard_worlds(self._simulate, worlds_on)
      positions, valid = simulate(x[rows], ratio[rows], gust_keys[rows])
      positions, valid = positions[inverse], valid[inverse]
      score = physsim.devices.shard_worlds(self._score, worlds_on, replicated=(0,))
      d, resid = score(data, positions, owner, noise_keys)
    d = d.reshape(p, q)
    ok = valid.reshape(p, q) & jnp.isfinite(d)
    d = jnp.where(ok, d, jnp.nan)
    resid = jnp.where(ok[..., None], resid.reshape(p, q, -1), jnp.nan)
    out = {'psd': d, 'residual': resid, 'valid': valid.reshape(p, q)}
    if with_frames:  # the best candidate of each problem, rendered again (same keys)
      best = jnp.arange(p) * q + jnp.argmin(jnp.where(ok, d, jnp.inf), axis=1)
      frames = self._frames(
        positions[best], data.poses, noise_keys[best], data.color
      )  # (P, C, T, ...)
      out['frames'] = frames[:, 0]
    if with_positions:
      out['positions'] = positions.reshape(p, q, *positions.shape[1:])
    return out

  def _arguments(self, data: ProblemData, u, gust_keys, noise_keys):
    """A call's program arguments, checked, on the host, and the mesh its
    worlds split over."""
    u = np.asarray(u, np.float64)
    p = data.lo.shape[0]
    if u.ndim != 3 or u.shape[0] != p or u.shape[2] != 3:
      raise ValueError(f'candidates must be (P={p}, q, 3), got {u.shape}')
    if not np.all(np.isfinite(u)) or np.any(np.abs(u) > 1 + 1e-9):
      raise ValueError('candidates must be finite and inside [-1, 1]^3')
    if gust_keys.shape != u.shape[:2] or noise_keys.shape != u.shape[:2]:
      raise ValueError(
        f'need (P, q) = {u.shape[:2]} keys, got {gust_keys.shape}, {noise_keys.shape}'
      )
    u, n = u.astype(np.float32), u.shape[0] * u.shape[1]
    on_device = self.world_mesh is not None
    min_saved = DEVICE_SAVED_CALLS * physsim.devices.FLAT_WORLDS if on_device else 0
    sims = distinct_worlds(data, u, gust_keys, min_saved=min_saved)
    mesh = physsim.devices.mesh_for(self.world_mesh, n)
    return (data, u, gust_keys, noise_keys, sims), mesh

  def compile(self, data: ProblemData, u, gust_keys: jax.Array,
              noise_keys: jax.Array, *, frames: bool = False,
              positions: bool = False) -> None:  # fmt: skip
    """Compiles the program that ``__call__`` with these arguments runs,
    without running it: only their shapes, and whether their worlds repeat
    (``distinct_worlds``), matter. A driver calls it in a thread while an
    earlier call of another shape runs; the call then finds the program
    compiled (JAX's caches). MuJoCo Warp's own set-up for a batch size
    (buffers, the frame's graph) still happens on the first call."""
    args, mesh = self._arguments(data, u, gust_keys, noise_keys)
    self._compile(physsim.devices.abstract(args, mesh), mesh, frames, positions)

  def _compile(self, args, mesh, frames: bool, positions: bool) -> None:
    """The program for ``args`` (arrays, or their ``abstract`` shapes) lowered
    and compiled into JAX's caches, where its call finds it."""
    self._program.lower(
      *args, with_frames=frames, with_positions=positions, worlds_on=mesh
    ).compile()

  def __call__(
    self,
    data: ProblemData,
    u,
    gust_keys: jax.Array,
    noise_keys: jax.Array,
    *,
    frames: bool = False,
    positions: bool = False,
    compiled: Callable[[], object] | None = None,
  ) -> Scores:
    """Scores candidates ``u (P, q, 3)`` of the P stacked problems in ``data``.

    Args:
      data: stacked ``ProblemData`` (leading axis P).
      u: (P, q, 3) unit-cube candidates.
      gust_keys, noise_keys: (P, q) typed PRNG keys, one per candidate.
      frames: also return each problem's best candidate's camera-0 frames.
      positions: also return every candidate's vertex positions.
      compiled: called once the program is compiled, before it runs (a
        driver starts work there that should not contend with the compile
        for Python's lock, whether or not the run blocks this thread).

    Raises:
      ValueError: ``u`` of the wrong shape, not finite or outside the cube.
    """
    args, mesh = self._arguments(data, u, gust_keys, noise_keys)
    sims = args[-1]
    self.simulated += args[1].size // 3 if sims is None else len(sims[0])
    placed = physsim.devices.place(args, mesh)
    if compiled is not None:
      self._compile(placed, mesh, frames, positions)
      compiled()
    out = self._program(
      *placed, with_frames=frames, with_positions=positions, worlds_on=mesh
    )
    out = jax.device_get(out)
    # A Ctrl-C during the simulator's callbacks left NaN worlds: not scores.
    physsim.interrupt.raise_if_pending()
    return Scores(
      np.asarray(out['psd'], np.float64),
      np.asarray(out['valid']),
      out.get('frames'),
      out.get('positions'),
      np.asarray(out['residual'], np.float64),
    )


def camera_key(noise_key: jax.Array) -> jax.Array:
  """The key of a candidate's camera error (``Scoring.camera_sd_m``),
  drawn from its sensor-noise key."""
  return jax.random.fold_in(noise_key, 7)


# A call that simulates only its distinct worlds pads their count up to a
# multiple of 1/SIM_BUCKETS of its worlds: a few program shapes per call
# shape, not one for every count. It does so only where that at least halves
# its simulations: each count is a program of its own to compile (seconds on
# a CPU, where a small cloth simulates in milliseconds).
SIM_BUCKETS = 16


# On a device a call simulates its distinct worlds alone only where that saves
# at least this many times FLAT_WORLDS worlds: a call of up to FLAT_WORLDS costs
# one step's fixed time however many it simulates (a padded call runs the
# design's program, ``evaluation._call_size``), and a new program shape costs its
# compile and the simulator's graph, about 6 s on an H200 (an estimate's first
# step against its later ones, BENCHMARKS.md), what some 200 worlds take to
# simulate there at scale (28 a second).
DEVICE_SAVED_CALLS = 4


def distinct_worlds(
  data: ProblemData, u: np.ndarray, gust_keys: jax.Array, *, min_saved: int = 0
):
  """The simulations a call of candidates ``u (P, q, 3)`` needs: one per set of
  worlds with equal inputs (the same unit-cube point in the same search box
  and fabric, with the same gust key), which then differ only in how they are
  seen and scored.

  Searches of one fabric with one seed share their initial design and its
  keys (a calibration's recordings, several recordings of one fabric), and a
  call's padding rows repeat a problem: without this every such world would
  be simulated again.

  Args:
    data: the call's stacked ``ProblemData``.
    u: (P, q, 3) float32 unit-cube candidates.
    gust_keys: (P, q) their gust keys.
    min_saved: fewest worlds sharing must save (on a device:
      ``DEVICE_SAVED_CALLS`` x ``FLAT_WORLDS``).

  Returns:
    None when fewer than half of the worlds, or than ``min_saved``, would be
    saved (the call then simulates every world, as one program), else
    ``(rows, inverse)`` int32: the worlds to simulate (the first of each set,
    in call order, the last repeated to the padded count) and, for each of the
    P*q worlds, its simulation's index in ``rows``.
  """
  p, q = u.shape[:2]
  per_problem = np.concatenate(
    [
      np.asarray(data.lo, np.float32),
      np.asarray(data.hi, np.float32),
      np.asarray(data.log, np.float32),
      np.asarray(data.rigidity_ratio, np.float32).reshape(p, 1),
    ],
    axis=1,
  )  # (P, 10): what maps a problem's unit point to its simulation
  owner = np.repeat(np.arange(p), q)
  keys = np.asarray(jax.random.key_data(gust_keys), np.uint32).reshape(p * q, -1)
  inputs = np.concatenate(
    [
      np.ascontiguousarray(u, np.float32).reshape(p * q, 3).view(np.uint32),
      per_problem[owner].view(np.uint32),
      keys,
    ],
    axis=1,
  )  # bit patterns: equal rows simulate alike
  _, first, inverse = np.unique(inputs, axis=0, return_index=True, return_inverse=True)
  order = np.argsort(first)  # the sets in call order
  rank = np.empty_like(order)
  rank[order] = np.arange(len(order))
  n = physsim.devices.padded(len(first), max(1, (p * q) // SIM_BUCKETS))
  if 2 * n > p * q or p * q - n < min_saved:
    return None
  rows = first[order]
  rows = np.concatenate([rows, np.repeat(rows[-1:], n - len(rows))])
  return rows.astype(np.int32), rank[inverse.reshape(-1)].astype(np.int32)


def _bytes_per_pixel(params) -> int:
  """Working memory per rendered pixel while a frame is sensed and embedded:
  float32 activations of the widest convolution, in and out, plus the
  renderer's and sensor's buffers (per network: an ensemble's kernels carry
  a leading member axis); without a network, the latter alone."""
  if not jax.tree.leaves(params):
    return 4 * 2 * 16
  widest = max(
    (leaf.shape[-1] for leaf in jax.tree.leaves(params) if np.ndim(leaf) >= 4),
    default=32,
  )
  return 4 * 2 * (int(widest) + 16)


def candidate_keys(seed: int, search: Search, first: int, q: int):
  """(gust keys, noise keys), each (q,), of a search's evaluations
  ``first .. first + q - 1`` (its running count, so a resumed search draws the
  same keys), from the estimate's ``seed``. With the search's
  ``common_random_numbers`` every evaluation gets its one pair of keys."""
  key = jax.random.key(seed)
  gust, noise = jax.random.fold_in(key, 2), jax.random.fold_in(key, 3)
  if search.common_random_numbers:
    return (
      jnp.broadcast_to(gust, (q,)),
      jnp.broadcast_to(noise, (q,)),
    )
  idx = jnp.arange(first, first + q)
  fold = jax.vmap(jax.random.fold_in, in_axes=(None, 0))
  return fold(gust, idx), fold(noise, idx)


class BestSeen:
  """The lowest PSD a search has scored and its candidate's camera-0 frames.

  A finished search shows its best candidate beside the recording; keeping
  those frames while scoring saves re-simulating it. A resumed search has not
  seen its earlier candidates' frames, so ``frames_of`` then returns None.
  """

  def __init__(self):
    self.u, self.y, self.frames = None, np.inf, None

  def update(self, u, y, frames) -> None:
    """Candidates ``u (q, 3)``, their PSDs ``y (q,)`` (NaN: failed) and the
    lowest one's frames ``(T, ...)``."""
    y = np.where(np.isfinite(y), y, np.inf)
    i = int(np.argmin(y)) if len(y) else 0
    if len(y) and y[i] < self.y:
      self.u, self.y = np.array(u[i], np.float64), float(y[i])
      self.frames = None if frames is None else np.asarray(frames)

  def frames_of(self, u) -> np.ndarray | None:
    """The kept frames if ``u`` is the kept candidate, else None."""
    if self.u is None or not np.array_equal(self.u, np.asarray(u, np.float64)):
      return None
    return self.frames
