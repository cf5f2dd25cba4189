"""Estimate a fabric's bending, area weight and the wind from a video.

Each Bayesian-optimisation iteration simulates its q candidates as one batch
(MJX on a GPU, MuJoCo C processes on a CPU), renders them from the recording's
camera (or from cameras drawn like the training set's), embeds them with the
material's trained network and scores each candidate by the physics
similarity distance (an energy distance between the two sets of 2-D
embeddings, so neither frame order nor flapping phase matters).

The paper's four methods (``experiments.table1`` trains them) differ only in
what is embedded: PhySNet embeds every frame, SDN every non-overlapping clip of
its ``num_frames`` frames (points of all cameras pooled); depth networks see
``model.depth_input`` of depth frames, RGB networks ``model.rgb_input`` of
8-bit colour frames (the recording's ``cam0/rgb_*.png``; candidates shaded in
the fabric's ``physsim.FABRIC_COLORS`` colour and rounded to 8 bits, as
``experiments.generate_dataset`` writes them). The run stops by
the paper's rule (the best point moved < 10% of each range over the last three
iterations) or after ``max_iter`` iterations, and resumes from its saved state.

  python -m experiments.estimate --recording=DIR --material=gray_interlock \
      --model=out/train/gray_interlock --workdir=out/estimate

Writes ``estimate.json`` (values, GP uncertainty, 3x5 bending matrix, and the
load ratio rho v^2 / (w g) with its interval: what a sheet's shape constrains
best of wind and area weight),
``trace.png`` (the paper's Figure 3) and ``montage.png`` (recording beside the
best simulation).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import bo  # noqa: E402
import model as model_lib  # noqa: E402
import physsim  # noqa: E402
from experiments import files  # noqa: E402
from experiments import generate_dataset as gen_lib  # noqa: E402
from experiments import train as train_lib  # noqa: E402
from physsim import dataset, video  # noqa: E402


@dataclasses.dataclass(frozen=True)
class EstimateConfig:
  """Settings of one estimate (also what a resumed run must match).

  Attributes:
    material: paper fabric name: the search range and bending reference.
    garment: '' for the 1 m square, else a ``physsim.GARMENTS`` name.
    cloth_resolution: square cloth vertices per side.
    garment_spacing: garment grid spacing, metres.
    frames: most frames compared (at ``fps``); a longer recording is cut, a
      shorter one sets how many frames are simulated.
    fps: frame rate the recording is resampled to.
    warmup: simulated seconds before the first frame.
    gusts: RMS gust intensity of the simulated wind.
    cameras: training-like cameras to render from when the recording's camera
      is unknown (their embeddings are pooled).
    q: candidates per iteration (one simulation batch).
    n_init: initial design size (the first point is the range centre).
    max_iter: most BO iterations.
    stop_rel_change, stop_window: the paper's stopping rule.
    min_iter: iterations before the rule is checked.
    distance: PSD between frame-embedding sets ('energy', 'centroid').
    backend: 'auto' (MJX on GPU, else C), 'mjx' or 'c'.
    workers: processes of the C backend (0: one per core); does not change
      results, so a resumed run may use another value.
    sensor_noise: pass candidates' rendered depth through the depth-sensor
      model (``physsim.sensor``) before embedding, as the recording went
      through a real sensor. Without it the sensor's holes and silhouette
      erosion alone moved the demo's PSD minimum from the true 1.26 to 2 m/s.
    seed: all randomness (design, gusts, cameras).
  """

  material: str = 'gray_interlock'
  garment: str = ''
  cloth_resolution: int = 25
  garment_spacing: float = 0.04
  frames: int = 60
  fps: float = 20.0
  warmup: float = 1.0
  gusts: float = 0.2
  cameras: int = 2
  q: int = 4
  n_init: int = 8
  max_iter: int = 30
  stop_rel_change: float = 0.1
  stop_window: int = 3
  min_iter: int = 5
  distance: str = 'energy'
  backend: str = 'auto'
  workers: int = 0
  sensor_noise: bool = True
  seed: int = 0


class Recording(NamedTuple):
  """A depth (and optionally colour) video to estimate from.

  Attributes:
    depth: (T, H, W) float32 metres, 0 invalid.
    fps: its frame rate after resampling.
    intrinsics: its camera's ``physsim.Intrinsics`` or None.
    pose: its camera's ``physsim.Pose`` (one camera) or None.
    source: where it came from.
    truth: ground-truth parameters when known (evaluation sets), else None.
    rgb: (T, H, W, 3) uint8 colour frames of the same times, or None.
  """

  depth: np.ndarray
  fps: float
  intrinsics: physsim.Intrinsics | None
  pose: physsim.Pose | None
  source: str
  truth: dict | None = None
  rgb: np.ndarray | None = None


def _read_json(path: str) -> dict:
  try:
    with open(path) as f:
      return json.load(f)
  except (OSError, ValueError) as e:
    raise ValueError(f'{path}: cannot read JSON ({e})') from e


def _camera(cam: dict, where: str, size, *, required: bool):
  """(intrinsics resized to ``size``, camera-0 pose) of a camera dict, or Nones.

  A camera file must hold intrinsics; a ``meta.json`` without them means an
  unknown camera. Broken fields are a ValueError naming ``where``.
  """
  if not isinstance(cam, dict) or 'intrinsics' not in cam:
    if required:
      raise ValueError(
        f'{where}: no "intrinsics" (want {{"intrinsics", "extrinsics"}})'
      )
    return None, None
  try:
    intr = physsim.Intrinsics.from_dict(cam['intrinsics'])
    intr = dataclasses.replace(intr, width=size[1], height=size[0])
    pose = None
    ext = cam.get('extrinsics')
    if ext is not None:
      if isinstance(ext, list):
        if not ext:
          raise ValueError('empty extrinsics list')
        ext = ext[0]
      p = physsim.pose_from_dict(ext)
      pose = physsim.Pose(p.rotation.reshape(3, 3), p.position.reshape(3))
      if not (
        np.all(np.isfinite(pose.rotation)) and np.all(np.isfinite(pose.position))
      ):
        raise ValueError('non-finite pose')
  except (ValueError, TypeError, AttributeError) as e:
    raise ValueError(f'{where}: bad camera ({e})') from e
  return intr, pose


def _load_rgb(path: str, meta: dict | None, fps: float, size, n: int) -> np.ndarray:
  """Camera 0's colour frames of a dataset sequence, resampled and resized like
  its depth: (n, H, W, 3) uint8."""
  if meta is None or not os.path.isdir(os.path.join(path, 'cam0')):
    raise ValueError(
      f'{path}: no RGB frames: colour frames are read from a dataset sequence '
      'folder (meta.json, cam0/rgb_*.png)'
    )
  if not meta.get('has_rgb'):
    raise ValueError(
      f'{path}: no RGB frames (meta.json has_rgb is not true, no cam0/rgb_*.png); '
      'an RGB network needs them (generate_dataset --rgb, make_eval_set)'
    )
  colour = dataset.read_sequence(path, cameras=[0], rgb=True).rgb[0]  # (T0, h, w, 3)
  pos = video.resample_indices(len(colour), float(meta['fps']), fps)
  # The nearest source frame, ties to the later one: load_depth_video's rule.
  nearest = np.minimum(np.floor(pos + 0.5 + 1e-9).astype(int), len(colour) - 1)
  return train_lib.resize_rgb(colour[nearest[:n]], size)


def load_recording(
  path: str,
  *,
  fps: float,
  size: tuple[int, int],
  frames: int | None = None,
  camera_json: str | None = None,
  rgb: bool = False,
) -> Recording:
  """Loads a recording in any format ``physsim.video`` reads.

  A dataset sequence folder (``meta.json`` beside ``cam0/``) brings its own
  fps, camera (intrinsics and extrinsics of camera 0) and ground truth.
  ``camera_json`` (``{"intrinsics": ..., "extrinsics": ...}``, as in
  ``meta.json``) gives or overrides the camera of any other recording.

  Args:
    path: the recording.
    fps: frame rate to resample to.
    size: (H, W) to resize to (nearest neighbour).
    frames: keep at most this many frames.
    camera_json: optional camera file.
    rgb: also load camera 0's colour frames (a dataset sequence with
      ``cam0/rgb_*.png``), resampled and resized as ``experiments.train``
      resizes them, for RGB networks.

  Raises:
    ValueError: a bad recording or camera file (or a camera file without
      intrinsics), or ``rgb`` asked of a recording without colour frames, named.
  """
  meta_path = os.path.join(path, 'meta.json')
  meta = _read_json(meta_path) if os.path.isfile(meta_path) else None
  frames_path, source_fps = path, None
  if meta is not None and os.path.isdir(os.path.join(path, 'cam0')):
    frames_path, source_fps = os.path.join(path, 'cam0'), meta.get('fps')
  vid = video.load_depth_video(frames_path, source_fps=source_fps, fps=fps, size=size)
  if frames is not None:
    vid = vid._replace(depth=vid.depth[:frames])
  if vid.normalised:
    raise ValueError(
      f'{path}: normalised (8-bit) depth has no absolute scale; the estimate '
      'needs metric depth (16-bit mm PNG, .npy/.npz in metres)'
    )
  if camera_json:
    intr, pose = _camera(_read_json(camera_json), camera_json, size, required=True)
  elif meta is not None:
    intr, pose = _camera(meta, meta_path, size, required=False)
  else:
    intr = pose = None
  truth = None
  if meta is not None and 'wind_speed' in meta:
    truth = {k: float(meta[k]) for k in ('bending_scale', 'wind_speed', 'area_weight')}
  colour = _load_rgb(path, meta, fps, size, len(vid.depth)) if rgb else None
  if colour is not None and len(colour) != len(vid.depth):
    raise ValueError(
      f'{path}: {len(colour)} colour frames but {len(vid.depth)} depth frames'
    )
  return Recording(vid.depth, fps, intr, pose, path, truth, colour)


# ------------------------------------------------------------------ objective


class Objective(NamedTuple):
  """The pieces an estimate needs, built once.

  Attributes:
    fun: (q, 3) unit-cube points -> (q,) PSD, NaN for blown-up simulations.
    simulate_frames: (q, 3) unit points -> ((q, C, T, H, W) depth or
      (q, C, T, H, W, 3) uint8 colour, as the network sees, (q,) valid).
    space: the material's search space.
    cloth: the compiled cloth.
    mesh: its rest mesh.
    evaluate: (q, 3) unit points -> ((q,) PSD as ``fun``, (q, T, V, 3)
      simulated positions, (q,) valid), for studies that also need the motion.
  """

  fun: object
  simulate_frames: object
  space: physsim.SearchSpace
  cloth: physsim.ClothModel
  mesh: physsim.Mesh | None = None
  evaluate: object = None
  best: BestSeen | None = None


class BestSeen:
  """The lowest PSD a search has scored and its candidate's camera-0 frames.

  A finished search shows its best candidate beside the recording; keeping
  those frames while scoring saves re-simulating it (one whole simulation
  batch, ~7% of an estimate on a GPU). A resumed search has not seen its
  earlier candidates' frames, so ``frames_of`` then returns None.
  """

  def __init__(self):
    self.u, self.y, self.frames = None, np.inf, None

  def update(self, u, y, frames) -> None:
    """Candidates ``u (q, 3)``, their PSDs ``y (q,)`` (NaN: failed) and frames
    ``(q, C, T, ...)`` as the network saw them."""
    y = np.where(np.isfinite(y), y, np.inf)
    i = int(np.argmin(y)) if len(y) else 0
    if len(y) and y[i] < self.y:
      self.u, self.y = np.array(u[i], np.float64), float(y[i])
      self.frames = np.asarray(frames[i, 0])

  def frames_of(self, u) -> np.ndarray | None:
    """The kept frames if ``u`` is the kept candidate, else None."""
    if self.u is None or not np.array_equal(self.u, np.asarray(u, np.float64)):
      return None
    return self.frames


def gp_device():
  """Where estimates fit their GPs: the CPU. The GP holds tens of points, so
  on a GPU its L-BFGS loops only wait on kernel launches (about 0.6 s per q=4
  proposal on an H200 against 0.07 s on two CPU cores), while the GPU has the
  simulations to run."""
  return jax.devices('cpu')[0]


@functools.lru_cache(maxsize=32)
def _renderer(garment: str, spacing: float, resolution: int, intr, color=None):
  """One jitted renderer per mesh, camera and modality (``color`` None: depth,
  else 8-bit colour frames in that colour), so that estimates of several
  recordings in one process compile it once."""
  mesh = physsim.garment(garment, spacing) if garment else physsim.square(resolution)
  if color is None:
    return physsim.make_depth_renderer(mesh.faces, intr)
  faces = np.asarray(mesh.faces, np.int32)

  @jax.jit
  def render(positions, poses):  # (B, T, V, 3), (B, C) -> (B, C, T, H, W, 3) uint8
    rgb = physsim.render_rgb(positions, faces, intr, poses, color=color)
    return jnp.round(rgb * 255).astype(jnp.uint8)  # as generate_dataset writes

  return render


def network_inputs(frames, modality: str, input_mode: str = 'relative') -> jax.Array:
  """Frames to network inputs, as ``experiments.train`` makes them.

  Args:
    frames: (..., H, W) depth in metres ('depth') or (..., H, W, 3) uint8
      colour ('rgb').
    modality: 'depth' or 'rgb'.
    input_mode: ``model.depth_input`` mode (depth only).

  Returns:
    (..., H, W, channels) float32.
  """
  if modality == 'depth':
    return model_lib.depth_input(frames, input_mode)
  if modality == 'rgb':
    return model_lib.rgb_input(frames)
  raise ValueError(f'modality must be one of {train_lib.MODALITIES}, got {modality!r}')


def embed_video(network, params, inputs, clip_frames: int = 0) -> jax.Array:
  """Embeds videos frame by frame (PhySNet) or clip by clip (SDN).

  Args:
    network: a ``model.Network``.
    params: its params.
    inputs: (S, T, H, W, ch) network inputs of S videos.
    clip_frames: 0: every frame is one point; else every non-overlapping clip
      of this many frames is one point (the last ``T % clip_frames`` frames
      are dropped, as ``experiments.train`` clips sequences).

  Returns:
    (S, N, D) points, N = T or T // clip_frames.
  """
  s, t = inputs.shape[:2]
  if not clip_frames:
    return network.apply(params, inputs.reshape(s * t, *inputs.shape[2:])).reshape(
      s, t, -1
    )
  n = t // clip_frames
  if n < 1:
    raise ValueError(f'videos of {t} frames are shorter than a clip of {clip_frames}')
  clips = inputs[:, : n * clip_frames].reshape(s * n, clip_frames, *inputs.shape[2:])
  return network.apply(params, clips).reshape(s, n, -1)


@functools.lru_cache(maxsize=8)
def _sensor(intr):
  """The jitted sensor model: ``(frames (B, C, T, H, W), keys (B,)) -> frames``.

  World ``b`` draws its noise from ``keys[b]`` alone, so a candidate's noise
  does not depend on the batch it is simulated in, and candidates given the
  same key get the same noise (common random numbers)."""
  one = lambda f, k: physsim.apply_noise_frames(k, f, intr)
  return jax.jit(jax.vmap(one))


@functools.lru_cache(maxsize=8)
def _cloth(garment: str, spacing: float, resolution: int):
  """One compiled cloth per mesh. Worlds name their fabric (``simulate``'s
  ``material``), so every fabric of a mesh shares it and its MJX compile."""
  mesh = physsim.garment(garment, spacing) if garment else physsim.square(resolution)
  return physsim.build(mesh, 'gray_interlock')


_JITTED: dict = {}


def _jitted(network, modality: str, input_mode: str, clip_frames: int, distance: str):
  """Jitted ``(embed, score)`` for one network and setting, cached by the
  network's identity (params are arguments: every recording of a fabric,
  and every fabric of one architecture, share the compiles).

  ``embed(params, frames (S, T, H, W[, 3])) -> (S, N, D)`` and
  ``score(params, frames (q, C, T, H, W[, 3]), rec_points) -> (q,)`` PSD.
  """
  k = (id(network), modality, input_mode, clip_frames, distance)
  if k not in _JITTED:

    def embed(params, frames):
      x = network_inputs(frames, modality, input_mode)
      return embed_video(network, params, x, clip_frames)

    def score(params, frames, rec_points):
      q = frames.shape[0]
      pts = embed(params, frames.reshape(-1, *frames.shape[2:]))  # cameras pooled
      pts = pts.reshape(q, -1, rec_points.shape[-1])
      return jax.vmap(lambda p: model_lib.psd.psd(p, rec_points, distance))(pts)

    # The entry holds the network, so its id stays unique while cached.
    _JITTED[k] = (network, jax.jit(embed), jax.jit(score))
  return _JITTED[k][1:]


class Problem(NamedTuple):
  """One recording's objective, in pieces that batch across recordings.

  ``evaluate_problems`` simulates the candidates of every problem of one
  ``sim_group`` as one batch, renders them from each problem's cameras and
  scores them against each recording with its own network.

  Attributes:
    config: its settings.
    source: the recording's path (for messages).
    space: the material's search space.
    mesh: the rest mesh.
    n_frames: frames simulated (the recording's, at ``config.fps``).
    intr: camera intrinsics (the recording's or a default field of view).
    poses: its cameras, a ``physsim.Pose`` with a leading camera axis.
    color: the fabric's RGB colour for an RGB network, else None (depth).
    gust_key: the wind-gust key every candidate shares.
    noise_key: the sensor-noise key every candidate shares.
    network, params: the embedding network.
    modality, input_mode, clip_frames: what it embeds (``EmbeddingNet``).
    rec_points: the recording's embedding ``(N, D)``.
  """

  config: EstimateConfig
  source: str
  space: physsim.SearchSpace
  mesh: physsim.Mesh
  n_frames: int
  intr: physsim.Intrinsics
  poses: physsim.Pose
  color: tuple | None
  gust_key: jax.Array
  noise_key: jax.Array
  network: object
  params: object
  modality: str
  input_mode: str
  clip_frames: int
  rec_points: jax.Array

  def sim_group(self) -> tuple:
    """Problems with equal keys simulate in one batch (same mesh and clock)."""
    c = self.config
    return (
      c.garment, c.garment_spacing if c.garment else 0.0,
      0 if c.garment else c.cloth_resolution, self.n_frames, c.fps, c.warmup,
      c.gusts, physsim.resolve_backend(c.backend), c.workers,
    )  # fmt: skip


def make_problem(
  config: EstimateConfig,
  network,
  net_params,
  input_mode: str,
  recording: Recording,
  *,
  modality: str = 'depth',
  clip_frames: int = 0,
) -> Problem:
  """Sets up one recording's objective (arguments as ``make_objective``)."""
  if modality not in train_lib.MODALITIES:
    raise ValueError(
      f'modality must be one of {train_lib.MODALITIES}, got {modality!r}'
    )
  rec_frames = recording.rgb if modality == 'rgb' else recording.depth
  if rec_frames is None:
    raise ValueError(
      f'{recording.source}: no RGB frames, but the network embeds colour frames '
      '(load_recording(..., rgb=True) of a sequence with cam0/rgb_*.png)'
    )
  n_frames = rec_frames.shape[0]
  if clip_frames and n_frames < clip_frames:
    raise ValueError(
      f'{recording.source}: {n_frames} frames at {recording.fps} fps, shorter '
      f'than one SDN clip of {clip_frames} frames; use a longer recording (and '
      'EstimateConfig.frames >= the clip)'
    )
  space = physsim.search_space(config.material)
  mesh = _cloth(config.garment, config.garment_spacing, config.cloth_resolution).mesh
  h, w = recording.depth.shape[1:]
  key = jax.random.key(config.seed)
  # A known field of view is used even when the pose is unknown.
  intr = recording.intrinsics or physsim.Intrinsics(width=w, height=h)
  if recording.pose is not None:
    poses = jax.tree.map(lambda a: jnp.asarray(a)[None], recording.pose)  # (1, ...)
  else:
    poses = physsim.sample_poses(jax.random.fold_in(key, 1), config.cameras)
  color = (
    tuple(map(float, gen_lib.rgb_color(config.material))) if modality == 'rgb' else None
  )
  embed, _ = _jitted(network, modality, input_mode, clip_frames, config.distance)
  rec_points = embed(net_params, jnp.asarray(rec_frames)[None])[0]
  return Problem(
    config, recording.source, space, mesh, n_frames, intr, poses, color,
    jax.random.fold_in(key, 2),  # common random gusts for all candidates
    jax.random.fold_in(key, 3),  # likewise: every candidate, the same noise
    network, net_params, modality, input_mode, clip_frames, rec_points,
  )  # fmt: skip


def _pad_rows(n: int) -> int:
  """Batch size for ``n`` worlds: the next power of two (>= 4), so that a
  shrinking or growing set of searches recompiles O(log n) times."""
  return max(4, 1 << max(0, int(np.ceil(np.log2(max(n, 1))))))


def simulate_problems(problems, us, *, pad: bool = False):
  """Simulates and renders every problem's candidates in one batch.

  Args:
    problems: ``Problem``s of one ``sim_group``.
    us: per problem, ``(q_i, 3)`` unit-cube candidates (``q_i`` may be 0).
    pad: round the batch up (``_pad_rows``; the extra worlds repeat the
      first candidate and are dropped) so that batches of varying size reuse
      compiles.

  Returns:
    Per problem: ``(frames (q_i, C, T, H, W[, 3]) as its network sees them,
    positions (q_i, T, V, 3), valid (q_i,))``.
  """
  groups = {p.sim_group() for p in problems}
  if len(groups) != 1:
    raise ValueError(f'problems of different simulation groups: {sorted(groups)}')
  c = problems[0].config
  counts = [len(u) for u in us]
  total = sum(counts)
  if total == 0:
    return [(None, None, None) for _ in problems]
  owner = np.repeat(np.arange(len(problems)), counts)
  n = _pad_rows(total) if pad else total
  owner = np.concatenate([owner, np.full(n - total, owner[0])])
  u_all = np.concatenate([np.asarray(u, np.float64).reshape(-1, 3) for u in us])
  u_all = np.concatenate([u_all, np.repeat(u_all[:1], n - total, axis=0)])
  fields = np.zeros((3, n))  # each row mapped by its own problem's range
  for i, p in enumerate(problems):
    rows = owner == i
    if rows.any():
      fields[:, rows] = np.stack(
        [np.asarray(f) for f in physsim.from_unit(u_all[rows], p.space)]
      )
  params = physsim.params.make(*fields)
  cloth = _cloth(c.garment, c.garment_spacing, c.cloth_resolution)
  out = physsim.simulate(
    cloth,
    params,
    frames=problems[0].n_frames,
    fps=c.fps,
    warmup=c.warmup,
    wind=physsim.Wind(gust_intensity=c.gusts),
    key=jnp.stack([problems[i].gust_key for i in owner]),
    backend=physsim.resolve_backend(c.backend),
    workers=c.workers or None,
    material=[physsim.fabric(problems[i].config.material).name for i in owner],
  )
  positions, valid = np.asarray(out.positions), np.asarray(out.valid)
  pos = np.where(valid[:, None, None, None], positions, cloth.mesh.vertices)
  frames = [None] * len(problems)
  # One render call per camera model, colour and camera count.
  views = {}
  for i, p in enumerate(problems):
    views.setdefault((p.intr, p.color, p.poses.position.shape[0]), []).append(i)
  for (intr, color, _), members in views.items():
    rows = np.flatnonzero(np.isin(owner, members))
    # Each world's problem, as an index into ``members``.
    slot = jnp.asarray(np.searchsorted(members, owner[rows]))
    stack = lambda *a, slot=slot: jnp.stack(a)[slot]
    poses = jax.tree.map(stack, *[problems[i].poses for i in members])  # (b, C, ...)
    render = _renderer(c.garment, c.garment_spacing, c.cloth_resolution, intr, color)
    f = render(jnp.asarray(pos[rows]), poses)
    if color is None:
      sensed = [i for i in members if problems[i].config.sensor_noise]
      if sensed:
        keys = stack(*[problems[i].noise_key for i in members])
        noisy = _sensor(intr)(f, keys)
        use = jnp.asarray(np.isin(owner[rows], sensed))
        f = jnp.where(use[:, None, None, None, None], noisy, f)
    for i in members:
      frames[i] = f[np.flatnonzero(owner[rows] == i)[: counts[i]]]
  return [
    (frames[i], positions[owner == i][: counts[i]], valid[owner == i][: counts[i]])
    for i in range(len(problems))
  ]


def evaluate_problems(problems, us, *, pad: bool = False, best=None):
  """PSD of every problem's candidates, simulated as one batch.

  Args:
    problems, us, pad: as ``simulate_problems``.
    best: optional per problem ``BestSeen`` (or None), updated in place with
      its candidates' scores and frames.

  Returns:
    Per problem: ``(psd (q_i,) float64, NaN where the simulation blew up,
    positions (q_i, T, V, 3), valid (q_i,))``.
  """
  best = best or [None] * len(problems)
  out = []
  for p, u, seen, (frames, positions, valid) in zip(
    problems, us, best, simulate_problems(problems, us, pad=pad), strict=True
  ):
    if frames is None:
      out.append((np.zeros(0), None, None))
      continue
    _, score = _jitted(
      p.network, p.modality, p.input_mode, p.clip_frames, p.config.distance
    )
    d = np.asarray(score(p.params, frames, p.rec_points), np.float64)
    d = np.where(valid & np.isfinite(d), d, np.nan)
    if seen is not None:
      seen.update(np.asarray(u), d, frames)
    out.append((d, positions, valid))
  return out


def make_objective(
  config: EstimateConfig,
  network,
  net_params,
  input_mode: str,
  recording: Recording,
  *,
  modality: str = 'depth',
  clip_frames: int = 0,
) -> Objective:
  """Builds the PSD objective of one recording (see module docstring).

  Args:
    config: settings.
    network, net_params: the embedding network and its params.
    input_mode: ``model.depth_input`` mode of a depth network.
    recording: the recording (with ``rgb`` for an RGB network).
    modality: 'depth' or 'rgb': which frames the network embeds.
    clip_frames: 0 for a frame network (PhySNet), else the SDN's clip length.

  Raises:
    ValueError: an RGB objective of a recording without colour frames, or a
      recording shorter than one clip, naming the recording.
  """
  problem = make_problem(
    config, network, net_params, input_mode, recording,
    modality=modality, clip_frames=clip_frames,
  )  # fmt: skip

  def simulate_frames(u):
    frames, _, valid = simulate_problems([problem], [np.asarray(u)])[0]
    return frames, valid

  best = BestSeen()

  def evaluate(u):
    return evaluate_problems([problem], [np.asarray(u)], best=[best])[0]

  def fun(u):
    return evaluate(u)[0]

  cloth = _cloth(config.garment, config.garment_spacing, config.cloth_resolution)
  return Objective(
    fun, simulate_frames, problem.space, cloth, problem.mesh, evaluate, best
  )


# ------------------------------------------------------------------- estimate


RUN_FILE = 'run.json'
# Config fields that do not change what an estimate computes.
_RESUMABLE_FIELDS = ('workers',)


def _check_run(
  workdir: str, config, recording: Recording, model_dir: str, modality: str = 'depth'
) -> None:
  """Writes what defines the run; refuses a workdir holding another run.

  ``bo_state.npz`` alone only knows the optimiser's settings, so without this
  a rerun with another recording, model or material would silently continue
  the old search.
  """
  run = {
    'config': {
      k: v for k, v in dataclasses.asdict(config).items() if k not in _RESUMABLE_FIELDS
    },
    'recording_sha1': hashlib.sha1(
      np.ascontiguousarray(recording.depth, np.float32).tobytes()
    ).hexdigest(),
    'model_dir': os.path.abspath(model_dir),
  }
  if modality == 'rgb':  # depth runs keep their old run.json (they resume)
    run['recording_rgb_sha1'] = hashlib.sha1(
      np.ascontiguousarray(recording.rgb).tobytes()
    ).hexdigest()
  run = json.loads(json.dumps(run))  # tuples -> lists, as read back
  path = os.path.join(workdir, RUN_FILE)
  if os.path.exists(path):
    old = _read_json(path)
    diff = sorted(
      k for k in set(run) | set(old) if k != 'config' and run.get(k) != old.get(k)
    )
    diff += sorted(
      f'config.{k}'
      for k in set(run['config']) | set(old.get('config', {}))
      if run['config'].get(k) != old.get('config', {}).get(k)
    )
    if diff:
      raise ValueError(
        f'{path}: the workdir holds an estimate with different {diff}; use a '
        'new workdir'
      )
    return
  files.write_json(path, run)


def _stats(value, samples: np.ndarray) -> dict:
  """A value with the median, 90% interval and spread of its GP samples."""
  return {
    'value': float(np.asarray(value).ravel()[0]),
    'posterior_median': float(np.median(samples)),
    'interval_90': [
      float(np.quantile(samples, 0.05)),
      float(np.quantile(samples, 0.95)),
    ],
    'std': float(samples.std()),
  }


def _summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  return {n: _stats(best[i], samples_phys[:, i]) for i, n in enumerate(best._fields)}


def _load_ratio_summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  """rho v^2 / (w g) of the best candidate and of the GP samples: the
  combination of wind and area weight a sheet's shape constrains best."""
  i, j = (
    physsim.Params._fields.index('wind_speed'),
    physsim.Params._fields.index('area_weight'),
  )
  ratio = physsim.load_ratio(samples_phys[:, i], samples_phys[:, j])
  return _stats(physsim.load_ratio(best.wind_speed, best.area_weight), ratio)


class EmbeddingNet(NamedTuple):
  """A trained run as the estimate uses it.

  Attributes:
    network, params: the ``model.Network`` and its params.
    modality: 'depth' or 'rgb'.
    input_mode: its ``model.depth_input`` mode.
    clip_frames: 0 for PhySNet (frames), the clip length for SDN.
    image_size: (H, W) its inputs have.
  """

  network: object
  params: object
  modality: str
  input_mode: str
  clip_frames: int
  image_size: tuple[int, int]


def load_embedding(model_dir: str) -> EmbeddingNet:
  """Loads any of ``experiments.table1``'s runs (PhySNet or SDN, depth or RGB).

  Raises:
    ValueError: not a trained run, or an unknown modality, naming ``model_dir``.
  """
  modality = train_lib.modality(model_dir)
  if modality not in train_lib.MODALITIES:
    raise ValueError(
      f'{model_dir}/{train_lib.INPUTS_FILE}: modality {modality!r} is none of '
      f'{train_lib.MODALITIES}'
    )
  network, params, cfg = model_lib.load_network(model_dir)
  sdn = cfg.network == 'sdn'
  trunk = cfg.sdn.trunk if sdn else cfg.physnet
  return EmbeddingNet(
    network,
    params,
    modality,
    train_lib.input_mode(model_dir),
    cfg.sdn.num_frames if sdn else 0,
    tuple(trunk.image_size),
  )


def network_retrieval(model_dir: str) -> dict[str, float] | None:
  """How well the network tells each parameter apart between held-out
  simulations: its logged parameter retrieval (``model.retrieval``) at the
  epoch it ships, over chance (1: the PSD does not constrain that parameter,
  so neither can the estimate). None for runs that did not log it.
  """
  r = model_lib.selected_eval(model_lib.read_evals(model_dir)).get('test_retrieval')
  return model_lib.retrieval.vs_chance(r) if r else None


def estimate(
  config: EstimateConfig,
  recording: Recording,
  model_dir: str,
  workdir: str,
  *,
  progress: bool = True,
  gp_on_cpu: bool = True,
) -> dict:
  """Runs (or resumes) one estimate; returns and writes ``estimate.json``.

  Args:
    config: settings.
    recording: the video (``load_recording``; with ``rgb=True`` for an RGB
      network).
    model_dir: a ``model.fit`` workdir of this material's network (PhySNet or
      SDN, depth or RGB).
    workdir: where state, JSON and pictures go.
    progress: print one line per iteration.
    gp_on_cpu: fit the GP and propose on the CPU (``gp_device``), else on
      JAX's default device.

  Returns:
    The result dict written to ``estimate.json``.

  Raises:
    ValueError: ``model_dir`` is not a trained run or takes another frame
      size, an RGB network and a recording without colour frames, a recording
      shorter than an SDN clip, ``workdir`` holds an estimate of another
      recording, model or config, or every candidate simulation blew up
      (naming the recording).
  """
  net = _check_inputs(recording, model_dir)
  os.makedirs(workdir, exist_ok=True)
  t_start = time.time()
  obj = make_objective(
    config,
    net.network,
    net.params,
    net.input_mode,
    recording,
    modality=net.modality,
    clip_frames=net.clip_frames,
  )
  _check_run(workdir, config, recording, model_dir, net.modality)
  sim_seconds = []

  def fun(u):
    t0 = time.time()
    y = obj.fun(u)
    sim_seconds.append(time.time() - t0)
    return y

  def callback(info: bo.IterationInfo):
    if progress:
      where = describe(info.x_best, info.y_best, obj.space)
      print(f'iter {info.iteration:3d}: {where}', flush=True)

  res = bo.minimize(
    fun, BOUNDS, callback=callback, device=gp_device() if gp_on_cpu else None,
    **minimizer_settings(config, workdir),
  )  # fmt: skip
  if not np.isfinite(res.y_best):
    raise ValueError(f'{recording.source}: every candidate simulation blew up')
  best_frames = obj.best.frames_of(res.x_best)
  if best_frames is None:  # found before a resume
    frames, _ = obj.simulate_frames(res.x_best[None])
    best_frames = np.asarray(frames[0, 0])
  return finish(
    config,
    recording,
    net.modality,
    workdir,
    res,
    best_frames,
    retrieval=network_retrieval(model_dir),
    seconds=time.time() - t_start,
    seconds_in_objective=float(np.sum(sim_seconds)),
  )


BOUNDS = np.array([[-1.0, 1.0]] * 3)  # the search runs in the unit cube


def minimizer_settings(config: EstimateConfig, workdir: str) -> dict:
  """``bo.minimize`` / ``bo.Minimizer`` settings of an estimate."""
  return dict(
    n_init=config.n_init,
    n_iter=config.max_iter,
    q=config.q,
    x0=np.zeros(3),  # the paper starts from the range centre
    seed=config.seed,
    acquisition='logei',
    stop_rel_change=config.stop_rel_change,
    stop_window=config.stop_window,
    stop_min_iter=config.min_iter,
    state_path=os.path.join(workdir, 'bo_state.npz'),
  )


def describe(x_best, y_best, space) -> str:
  """One progress line's worth: the best PSD and its parameters."""
  if not np.isfinite(y_best):
    return 'every simulation so far blew up'
  p = physsim.from_unit(x_best, space)
  return (
    f'best PSD {y_best:.4g} at bending x{float(p.bending_scale):.3g}, wind '
    f'{float(p.wind_speed):.2f} m/s, area weight {float(p.area_weight):.3f} kg/m^2'
  )


def _check_inputs(
  recording: Recording, model_dir: str, net: EmbeddingNet | None = None
) -> EmbeddingNet:
  """Loads the network (unless given) and checks the recording fits it (see
  ``estimate``)."""
  net = net or load_embedding(model_dir)
  size = net.image_size
  if tuple(recording.depth.shape[1:]) != size:
    raise ValueError(
      f'{recording.source}: frames of {recording.depth.shape[1:]} but the network '
      f'in {model_dir} takes {size}; load the recording at that size'
    )
  if net.modality == 'rgb' and recording.rgb is None:
    raise ValueError(
      f'{recording.source}: no RGB frames, but {model_dir} is an RGB network; '
      'load the recording with rgb=True (a sequence with cam0/rgb_*.png)'
    )
  return net


def finish(
  config: EstimateConfig,
  recording: Recording,
  modality: str,
  workdir: str,
  res: bo.Result,
  best_frames: np.ndarray,
  retrieval: dict[str, float] | None = None,
  **timing,
) -> dict:
  """Writes ``estimate.json``, ``trace.png`` and ``montage.png`` of a finished
  search and returns the result dict.

  Args:
    config, recording, modality: the estimate's.
    workdir: where they go.
    res: the search's result (a finite best value).
    best_frames: the best candidate's camera-0 frames as its network saw
      them, ``(T, H, W)`` depth or ``(T, H, W, 3)`` colour.
    retrieval: the network's ``network_retrieval``, recorded beside the
      estimate (a parameter near 1 is not constrained by the video).
    **timing: seconds to record (``seconds``, ``seconds_in_objective``, ...).
  """
  space = physsim.search_space(config.material)
  best = physsim.from_unit(res.x_best, space)
  post = bo.minimizer_samples(res.X, res.Y, BOUNDS, jax.random.key(config.seed))
  samples = np.stack(list(physsim.from_unit(post.samples, space)), axis=1)
  material = physsim.load_material(physsim.fabric(config.material).material)
  result = {
    'recording': recording.source,
    'material': config.material,
    'garment': config.garment,
    'estimate': _summary(samples, best),
    'load_ratio': _load_ratio_summary(samples, best),
    'bending_matrix_Nm': (float(best.bending_scale) * material.bending).tolist(),
    'psd_best': float(res.y_best),
    'evaluations': int(res.n_evals),
    'failed_evaluations': int(np.sum(~np.isfinite(res.Y))),
    'iterations': int(res.n_iter),
    'stopped_by_rule': bool(res.stopped_early),
    **({'network_retrieval_vs_chance': retrieval} if retrieval else {}),
    **{k: float(v) for k, v in timing.items()},
    'config': dataclasses.asdict(config),
  }
  if recording.truth is not None:
    result['truth'] = recording.truth
    result['errors'] = errors(best, recording.truth, space)
  files.write_json(os.path.join(workdir, 'estimate.json'), result)
  plot_trace(res, space, recording.truth, os.path.join(workdir, 'trace.png'))
  plot_montage(
    recording.rgb if modality == 'rgb' else recording.depth,
    best_frames,
    os.path.join(workdir, 'montage.png'),
  )
  return result


_RETRIEVAL_MEANING = 'near 1: the video barely constrains that parameter; trust its interval, not its value'


def report_table(result: dict) -> str:
  """A markdown table of an estimate with ground truth: estimate, truth, GP
  interval, the range-centre guess and the network's retrieval over chance."""
  space = physsim.search_space(result['material'])
  centre = space.center()
  retrieval = result.get('network_retrieval_vs_chance', {})
  lines = [
    '| parameter | true | estimated | GP 90% interval | range centre '
    '| network retrieval (1 = chance) |',
    '|---|---|---|---|---|---|',
  ]
  for i, name in enumerate(physsim.Params._fields):
    e = result['estimate'][name]
    lo, hi = e['interval_90']
    r = f'{retrieval[name]:.2f}' if name in retrieval else 'n/a'
    lines.append(
      f'| {name} | {result["truth"][name]:.3g} | {e["value"]:.3g} | '
      f'[{lo:.3g}, {hi:.3g}] | {float(centre[i]):.3g} | {r} |'
    )
  if ratio := result.get('load_ratio'):  # older results lack it
    t = result['truth']
    true = float(physsim.load_ratio(t['wind_speed'], t['area_weight']))
    lo, hi = ratio['interval_90']
    guess = float(physsim.load_ratio(centre.wind_speed, centre.area_weight))
    lines.append(
      f'| load ratio rho v^2/(w g) | {true:.3g} | {ratio["value"]:.3g} | '
      f'[{lo:.3g}, {hi:.3g}] | {guess:.3g} | - |'
    )
  err = result['errors']
  lines.append('')
  lines.append(
    'errors (estimate vs range centre): '
    + json.dumps(
      {
        k: [round(err['estimate'][k], 2), round(err['range_centre'][k], 2)]
        for k in err['estimate']
      }
    )
  )
  if retrieval:
    lines.append(
      'network retrieval: how well the network tells each parameter apart between '
      f'held-out simulations ({_RETRIEVAL_MEANING})'
    )
  return '\n'.join(lines)


def retrieval_note(retrieval: dict[str, float]) -> str:
  """One line saying which parameters the network barely tells apart."""
  cells = model_lib.retrieval.describe(retrieval)
  return (
    f'network retrieval on held-out simulations, over chance: {cells} '
    f'({_RETRIEVAL_MEANING})'
  )


def errors(best: physsim.Params, truth: dict, space: physsim.SearchSpace) -> dict:
  """Percent errors of wind and area weight, the bending factor, the percent
  error of the load ratio rho v^2 / (w g) (what a sheet's shape constrains
  best), and the same for the trivial estimate (the centre of the search range)."""
  centre = space.center()
  true_ratio = float(physsim.load_ratio(truth['wind_speed'], truth['area_weight']))

  def one(p):
    b = float(np.asarray(p.bending_scale).ravel()[0])
    ratio = float(physsim.load_ratio(p.wind_speed, p.area_weight))
    return {
      'wind_speed_pct': 100
      * abs(float(p.wind_speed) - truth['wind_speed'])
      / truth['wind_speed'],
      'area_weight_pct': 100
      * abs(float(p.area_weight) - truth['area_weight'])
      / truth['area_weight'],
      'bending_factor': float(np.exp(abs(np.log(b / truth['bending_scale'])))),  # >= 1
      'load_ratio_pct': 100 * abs(ratio - true_ratio) / true_ratio,
    }

  return {'estimate': one(best), 'range_centre': one(centre)}


# -------------------------------------------------------------------- figures


def plot_trace(res: bo.Result, space, truth, path: str) -> None:
  """PSD per evaluation and each parameter's value (the paper's Figure 3)."""
  X = np.asarray(physsim.from_unit(res.X, space))  # (3, n)
  Y = res.Y
  n = np.arange(len(Y))
  best = np.fmin.accumulate(np.where(np.isfinite(Y), Y, np.inf))
  fig, axes = plt.subplots(1, 4, figsize=(16, 3.4))
  axes[0].plot(n, Y, '.', color='0.6', label='evaluation')
  axes[0].plot(n, best, '-', color='k', label='best so far')
  axes[0].set(xlabel='evaluation', ylabel='physics similarity distance', yscale='log')
  axes[0].legend(fontsize=8)
  labels = ['bending scale', 'wind speed (m/s)', 'area weight (kg/m$^2$)']
  for i, (ax, label) in enumerate(zip(axes[1:], labels, strict=True)):
    ax.scatter(n, X[i], c=np.log(Y - np.nanmin(Y) + 1e-9), s=12, cmap='viridis_r')
    ax.set(xlabel='evaluation', ylabel=label, ylim=space.bounds()[i])
    if i == 0:
      ax.set_yscale('log')
    if truth is not None:
      ax.axhline(truth[physsim.Params._fields[i]], color='r', lw=1, label='truth')
      ax.legend(fontsize=8)
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def plot_montage(recorded: np.ndarray, simulated: np.ndarray, path: str, n=6) -> None:
  """Rows: the recording and the best simulation, ``n`` frames each; (T, H, W)
  depth or (T, H, W, 3) uint8 colour."""
  idx = np.linspace(0, min(len(recorded), len(simulated)) - 1, n).astype(int)
  colour = recorded.ndim == 4
  valid = recorded[recorded > 0]
  lo, hi = np.quantile(valid, [0.01, 0.99]) if valid.size else (0, 1)
  fig, axes = plt.subplots(2, n, figsize=(2 * n, 4.3))
  for r, (frames, name) in enumerate(
    ((recorded, 'recording'), (simulated, 'best sim'))
  ):
    for c, t in enumerate(idx):
      ax = axes[r, c]
      if colour:
        ax.imshow(frames[t])
      else:
        ax.imshow(
          np.where(frames[t] > 0, frames[t], np.nan), cmap='turbo', vmin=lo, vmax=hi
        )
      ax.set_xticks([])
      ax.set_yticks([])
      if c == 0:
        ax.set_ylabel(name)
  fig.tight_layout()
  files.savefig(fig, path, dpi=80)
  plt.close(fig)


# ------------------------------------------------------------------------ CLI

PRESETS = {
  'default': EstimateConfig(),
  # A quick look on a CPU: small cloth, short clip, few iterations.
  'smoke': EstimateConfig(
    cloth_resolution=10, frames=16, warmup=0.5, q=4, n_init=4, max_iter=6
  ),
}


def main(argv):
  from absl import flags, logging

  del argv
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  f = flags.FLAGS
  config = dataclasses.replace(
    PRESETS[f.preset],
    **{
      k: getattr(f, k)
      for k in ('material', 'garment', 'backend', 'seed', 'q', 'max_iter')
      if f[k].present
    },
  )
  net = load_embedding(f.model)
  rec = load_recording(
    f.recording,
    fps=config.fps,
    size=net.image_size,
    frames=config.frames,
    camera_json=f.camera_json,
    rgb=net.modality == 'rgb',
  )
  result = estimate(config, rec, f.model, f.workdir)
  if 'truth' in result:
    print(report_table(result))
    return
  values = {k: v['value'] for k, v in result['estimate'].items()}
  values['load_ratio'] = result['load_ratio']['value']
  print(json.dumps(values, indent=1))
  if r := result.get('network_retrieval_vs_chance'):
    print(retrieval_note(r))


def _define_flags():
  from absl import flags

  d = EstimateConfig()
  flags.DEFINE_string('recording', None, 'depth video (folder, .npy/.npz, video)')
  flags.DEFINE_string('model', None, 'trained network workdir (experiments.train)')
  flags.DEFINE_string('workdir', 'out/estimate', 'state, JSON and pictures')
  flags.DEFINE_string('camera_json', None, 'optional {"intrinsics", "extrinsics"}')
  flags.DEFINE_enum('preset', 'default', list(PRESETS), 'sizes')
  flags.DEFINE_string('material', d.material, 'paper fabric name')
  flags.DEFINE_string('garment', d.garment, "'' (square) or tshirt/shirt/jeans")
  flags.DEFINE_enum('backend', d.backend, ['auto', 'mjx', 'c'], 'simulator')
  flags.DEFINE_integer('seed', d.seed, 'seed')
  flags.DEFINE_integer('q', d.q, 'candidates per iteration')
  flags.DEFINE_integer('max_iter', d.max_iter, 'most iterations')
  flags.mark_flags_as_required(['recording', 'model'])


if __name__ == '__main__':
  from absl import app

  _define_flags()
  app.run(main)
