"""Estimate a fabric's bending, area weight and the wind from a depth video.

Each Bayesian-optimisation iteration simulates its q candidates as one batch
(MJX on a GPU, MuJoCo C processes on a CPU), renders them from the recording's
camera (or from cameras drawn like the training set's), embeds every frame with
the material's trained PhySNet and scores each candidate by the physics
similarity distance (an energy distance between the two sets of 2-D frame
embeddings, so neither frame order nor flapping phase matters). The run stops by
the paper's rule (the best point moved < 10% of each range over the last three
iterations) or after ``max_iter`` iterations, and resumes from its saved state.

  python -m experiments.estimate --recording=DIR --material=gray_interlock \
      --model=out/train/gray_interlock --workdir=out/estimate

Writes ``estimate.json`` (values, GP uncertainty, 3x5 bending matrix),
``trace.png`` (the paper's Figure 3) and ``montage.png`` (recording beside the
best simulation).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import tempfile
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
from experiments import train as train_lib  # noqa: E402
from physsim import video  # noqa: E402


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
  """A depth video to estimate from.

  Attributes:
    depth: (T, H, W) float32 metres, 0 invalid.
    fps: its frame rate after resampling.
    intrinsics: its camera's ``physsim.Intrinsics`` or None.
    pose: its camera's ``physsim.Pose`` (one camera) or None.
    source: where it came from.
    truth: ground-truth parameters when known (evaluation sets), else None.
  """

  depth: np.ndarray
  fps: float
  intrinsics: physsim.Intrinsics | None
  pose: physsim.Pose | None
  source: str
  truth: dict | None = None


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


def load_recording(
  path: str,
  *,
  fps: float,
  size: tuple[int, int],
  frames: int | None = None,
  camera_json: str | None = None,
) -> Recording:
  """Loads a recording in any format ``physsim.video`` reads.

  A dataset sequence folder (``meta.json`` beside ``cam0/``) brings its own
  fps, camera (intrinsics and extrinsics of camera 0) and ground truth.
  ``camera_json`` (``{"intrinsics": ..., "extrinsics": ...}``, as in
  ``meta.json``) gives or overrides the camera of any other recording.

  Raises:
    ValueError: a bad recording or camera file (or a camera file without
      intrinsics), named.
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
  return Recording(vid.depth, fps, intr, pose, path, truth)


# ------------------------------------------------------------------ objective


class Objective(NamedTuple):
  """The pieces an estimate needs, built once.

  Attributes:
    fun: (q, 3) unit-cube points -> (q,) PSD, NaN for blown-up simulations.
    simulate_frames: (q, 3) unit points -> ((q, C, T, H, W) depth, (q,) valid).
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


def _backend(name: str) -> str:
  if name == 'auto':
    return 'mjx' if jax.default_backend() == 'gpu' else 'c'
  return name


@functools.lru_cache(maxsize=8)
def _renderer(garment: str, spacing: float, resolution: int, intr):
  """One jitted renderer per mesh and camera, so that estimates of several
  recordings in one process compile it once."""
  mesh = physsim.garment(garment, spacing) if garment else physsim.square(resolution)
  return physsim.make_depth_renderer(mesh.faces, intr)


@functools.lru_cache(maxsize=8)
def _sensor(intr):
  """Jitted sensor model over a batch of frames (..., H, W), one key each."""

  @jax.jit
  def apply(frames, key):
    flat = frames.reshape(-1, *frames.shape[-2:])
    keys = jax.random.split(key, flat.shape[0])
    out = jax.vmap(lambda k, d: physsim.apply_noise(k, d, intr))(keys, flat)
    return out.reshape(frames.shape)

  return apply


def make_objective(
  config: EstimateConfig, network, net_params, input_mode: str, recording: Recording
) -> Objective:
  """Builds the PSD objective of one recording (see module docstring)."""
  fab = physsim.fabric(config.material)
  space = physsim.search_space(config.material)
  mesh = (
    physsim.garment(config.garment, config.garment_spacing)
    if config.garment
    else physsim.square(config.cloth_resolution)
  )
  cloth = physsim.build(mesh, fab.name)
  h, w = recording.depth.shape[1:]
  key = jax.random.key(config.seed)
  # A known field of view is used even when the pose is unknown.
  intr = recording.intrinsics or physsim.Intrinsics(width=w, height=h)
  if recording.pose is not None:
    poses = jax.tree.map(lambda a: jnp.asarray(a)[None], recording.pose)  # (1, ...)
  else:
    poses = physsim.sample_poses(jax.random.fold_in(key, 1), config.cameras)
  render = _renderer(
    config.garment, config.garment_spacing, config.cloth_resolution, intr
  )
  gust_key = jax.random.fold_in(key, 2)  # common random numbers for all candidates
  noise_key = jax.random.fold_in(key, 3)  # likewise: every candidate, the same noise
  backend = _backend(config.backend)

  @jax.jit
  def embed(frames):  # (..., H, W) -> (N, 2)
    x = model_lib.depth_input(frames.reshape(-1, h, w), input_mode)
    return network.apply(net_params, x)

  rec_points = embed(jnp.asarray(recording.depth))

  @jax.jit
  def distances(frames):  # (q, C, T, H, W) -> (q,)
    q = frames.shape[0]
    pts = embed(frames).reshape(q, -1, rec_points.shape[-1])
    return jax.vmap(lambda p: model_lib.psd.psd(p, rec_points, config.distance))(pts)

  def simulate(u):  # (q, 3) -> ((q, T, V, 3) positions, (q,) valid)
    out = physsim.simulate(
      cloth,
      physsim.from_unit(np.asarray(u), space),
      frames=recording.depth.shape[0],
      fps=config.fps,
      warmup=config.warmup,
      wind=physsim.Wind(gust_intensity=config.gusts),
      key=jnp.broadcast_to(gust_key, np.shape(u)[:1]),  # the same for every world
      backend=backend,
      space=space,
      workers=config.workers or None,
    )
    return out.positions, out.valid

  def render_frames(positions, valid):
    q = positions.shape[0]
    pos = np.where(valid[:, None, None, None], positions, mesh.vertices)
    batch_poses = jax.tree.map(
      lambda a: jnp.broadcast_to(a, (q, *a.shape)), poses
    )  # (q, C, ...)
    frames = render(jnp.asarray(pos), batch_poses)  # (q, C, T, H, W)
    if config.sensor_noise:
      frames = _sensor(intr)(frames, noise_key)
    return frames

  def simulate_frames(u):
    positions, valid = simulate(u)
    return render_frames(positions, valid), valid

  def evaluate(u):
    positions, valid = simulate(u)
    d = np.asarray(distances(render_frames(positions, valid)), np.float64)
    return np.where(valid & np.isfinite(d), d, np.nan), positions, valid

  def fun(u):
    return evaluate(u)[0]

  return Objective(fun, simulate_frames, space, cloth, mesh, evaluate)


# ------------------------------------------------------------------- estimate


def _atomic_write(path: str, write) -> None:
  d = os.path.dirname(os.path.abspath(path))
  fd, tmp = tempfile.mkstemp(dir=d, suffix='.tmp' + os.path.splitext(path)[1])
  os.close(fd)
  try:
    write(tmp)
    os.replace(tmp, path)
  except BaseException:
    if os.path.exists(tmp):
      os.remove(tmp)
    raise


def _write_json(path: str, obj) -> None:
  def write(p):
    with open(p, 'w') as f:
      json.dump(obj, f, indent=1)

  _atomic_write(path, write)


RUN_FILE = 'run.json'
# Config fields that do not change what an estimate computes.
_RESUMABLE_FIELDS = ('workers',)


def _check_run(workdir: str, config, recording: Recording, model_dir: str) -> None:
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
  _write_json(path, run)


def _summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  names = physsim.Params._fields
  out = {}
  for i, n in enumerate(names):
    s = samples_phys[:, i]
    out[n] = {
      'value': float(np.asarray(best[i]).ravel()[0]),
      'posterior_median': float(np.median(s)),
      'interval_90': [float(np.quantile(s, 0.05)), float(np.quantile(s, 0.95))],
      'std': float(s.std()),
    }
  return out


def estimate(
  config: EstimateConfig,
  recording: Recording,
  model_dir: str,
  workdir: str,
  *,
  progress: bool = True,
) -> dict:
  """Runs (or resumes) one estimate; returns and writes ``estimate.json``.

  Args:
    config: settings.
    recording: the depth video (``load_recording``).
    model_dir: a ``model.fit`` workdir of this material's network.
    workdir: where state, JSON and pictures go.
    progress: print one line per iteration.

  Returns:
    The result dict written to ``estimate.json``.

  Raises:
    ValueError: ``model_dir`` is not a trained PhySNet run or takes another
      frame size, ``workdir`` holds an estimate of another recording, model or
      config, or every candidate simulation blew up (naming the recording).
  """
  if train_lib.modality(model_dir) != 'depth':
    raise ValueError(
      f'{model_dir}: trained on {train_lib.modality(model_dir)} frames; the '
      'estimate compares depth videos, so it needs a depth network'
    )
  network, net_params, net_config = model_lib.load_network(model_dir)
  if net_config.network != 'physnet':
    raise ValueError(
      f'{model_dir}: a {net_config.network!r} run; the estimate embeds single '
      'frames with a PhySNet run'
    )
  size = tuple(net_config.physnet.image_size)
  if tuple(recording.depth.shape[1:]) != size:
    raise ValueError(
      f'{recording.source}: frames of {recording.depth.shape[1:]} but the network '
      f'in {model_dir} takes {size}; load the recording at that size'
    )
  input_mode = train_lib.input_mode(model_dir)
  os.makedirs(workdir, exist_ok=True)
  _check_run(workdir, config, recording, model_dir)
  t_start = time.time()
  obj = make_objective(config, network, net_params, input_mode, recording)
  sim_seconds = []

  def fun(u):
    t0 = time.time()
    y = obj.fun(u)
    sim_seconds.append(time.time() - t0)
    return y

  def callback(info: bo.IterationInfo):
    if progress and not np.isfinite(info.y_best):
      print(f'iter {info.iteration:3d}: every simulation so far blew up', flush=True)
    elif progress:
      p = physsim.from_unit(info.x_best, obj.space)
      print(
        f'iter {info.iteration:3d}: best PSD {info.y_best:.4g} at bending '
        f'x{float(p.bending_scale):.3g}, wind {float(p.wind_speed):.2f} m/s, '
        f'area weight {float(p.area_weight):.3f} kg/m^2',
        flush=True,
      )

  bounds = np.array([[-1.0, 1.0]] * 3)
  res = bo.minimize(
    fun,
    bounds,
    n_init=config.n_init,
    n_iter=config.max_iter,
    q=config.q,
    x0=np.zeros(3),  # the paper starts from the range centre
    seed=config.seed,
    acquisition='logei',
    callback=callback,
    stop_rel_change=config.stop_rel_change,
    stop_window=config.stop_window,
    stop_min_iter=config.min_iter,
    state_path=os.path.join(workdir, 'bo_state.npz'),
  )
  if not np.isfinite(res.y_best):
    raise ValueError(f'{recording.source}: every candidate simulation blew up')
  best = physsim.from_unit(res.x_best, obj.space)
  post = bo.minimizer_samples(res.X, res.Y, bounds, jax.random.key(config.seed))
  samples = np.stack(list(physsim.from_unit(post.samples, obj.space)), axis=1)
  seconds = time.time() - t_start
  material = physsim.load_material(physsim.fabric(config.material).material)
  result = {
    'recording': recording.source,
    'material': config.material,
    'garment': config.garment,
    'estimate': _summary(samples, best),
    'bending_matrix_Nm': (float(best.bending_scale) * material.bending).tolist(),
    'psd_best': float(res.y_best),
    'evaluations': int(res.n_evals),
    'failed_evaluations': int(np.sum(~np.isfinite(res.Y))),
    'iterations': int(res.n_iter),
    'stopped_by_rule': bool(res.stopped_early),
    'seconds': seconds,
    'seconds_in_objective': float(np.sum(sim_seconds)),
    'config': dataclasses.asdict(config),
  }
  if recording.truth is not None:
    result['truth'] = recording.truth
    result['errors'] = errors(best, recording.truth, obj.space)
  _write_json(os.path.join(workdir, 'estimate.json'), result)
  plot_trace(res, obj.space, recording.truth, os.path.join(workdir, 'trace.png'))
  frames, _ = obj.simulate_frames(res.x_best[None])
  plot_montage(
    recording.depth, np.asarray(frames[0, 0]), os.path.join(workdir, 'montage.png')
  )
  return result


def errors(best: physsim.Params, truth: dict, space: physsim.SearchSpace) -> dict:
  """Percent errors of wind and area weight, the bending factor, and the same
  for the trivial estimate (the centre of the search range)."""
  centre = space.center()

  def one(p):
    b = float(np.asarray(p.bending_scale).ravel()[0])
    return {
      'wind_speed_pct': 100
      * abs(float(p.wind_speed) - truth['wind_speed'])
      / truth['wind_speed'],
      'area_weight_pct': 100
      * abs(float(p.area_weight) - truth['area_weight'])
      / truth['area_weight'],
      'bending_factor': float(np.exp(abs(np.log(b / truth['bending_scale'])))),  # >= 1
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
  _atomic_write(path, lambda p: fig.savefig(p, dpi=90))
  plt.close(fig)


def plot_montage(recorded: np.ndarray, simulated: np.ndarray, path: str, n=6) -> None:
  """Rows: the recording and the best simulation, ``n`` frames each."""
  idx = np.linspace(0, min(len(recorded), len(simulated)) - 1, n).astype(int)
  valid = recorded[recorded > 0]
  lo, hi = np.quantile(valid, [0.01, 0.99]) if valid.size else (0, 1)
  fig, axes = plt.subplots(2, n, figsize=(2 * n, 4.3))
  for r, (frames, name) in enumerate(
    ((recorded, 'recording'), (simulated, 'best sim'))
  ):
    for c, t in enumerate(idx):
      ax = axes[r, c]
      ax.imshow(
        np.where(frames[t] > 0, frames[t], np.nan), cmap='turbo', vmin=lo, vmax=hi
      )
      ax.set_xticks([])
      ax.set_yticks([])
      if c == 0:
        ax.set_ylabel(name)
  fig.tight_layout()
  _atomic_write(path, lambda p: fig.savefig(p, dpi=80))
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
  network_config = model_lib.load_network(f.model)[2]
  size = tuple(network_config.physnet.image_size)
  rec = load_recording(
    f.recording,
    fps=config.fps,
    size=size,
    frames=config.frames,
    camera_json=f.camera_json,
  )
  result = estimate(config, rec, f.model, f.workdir)
  est = result['estimate']
  print(json.dumps({k: v['value'] for k, v in est.items()}, indent=1))
  if 'errors' in result:
    print(json.dumps(result['errors'], indent=1))


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
