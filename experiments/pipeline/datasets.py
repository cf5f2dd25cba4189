"""The fabric dataset sweep, simulated and rendered into the ``physsim.dataset`` format.

For each material: parameter sets drawn uniformly in its normalised search box
(seeded per material), simulated in fixed batches (``physsim.simulate``), each
world seen by random cameras (``physsim.sample_poses``) through the JAX
ray-caster in one jitted call per batch, and written sequence by sequence,
atomically. A rerun resumes: finished sequences are kept as they are.
``experiments/generate_dataset.py`` is its command line.

Invalid (blown-up) worlds are written with ``valid=False`` and no frames; they
are rendered with the rest mesh in their place only to keep the batch shape
fixed, and those frames are discarded.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import functools
import json
import os
import time
import zlib

import jax
import jax.numpy as jnp
import numpy as np
from absl import logging

import physsim
from experiments.pipeline import (
  cli,
  deadline,
  distributed,
  embedding,
  files,
  progress,
)
from physsim import dataset


@dataclasses.dataclass(frozen=True)
class Config:
  """One dataset sweep (each field is also a flag of generate_dataset).

  Attributes:
    materials: fabric names (``physsim.FABRICS``).
    sequences: parameter sets (simulations) per material.
    frames: frames per sequence.
    fps: frame rate, Hz.
    warmup: seconds simulated before the first frame.
    cameras: cameras per sequence.
    resolution: image width = height, pixels.
    cloth_resolution: cloth vertices per side.
    cloth_size: the square cloth's side, metres (the cameras' distances and
      target scale with it: ``PoseRanges.for_cloth``).
    seed: the only seed.
    backend: ``'auto'`` (MuJoCo Warp a frame at a time on a GPU, else MuJoCo
      C), ``'warp'``, ``'mjx'`` or ``'c'`` (``physsim.rollout``).
    batch_size: worlds whose gusts and sensor noise are drawn from one
      key: the sequences of all materials, in order, are grouped in fixed
      chunks of this size (one compiled model serves every material), so a
      resume must use the same batch size (checked). A device call simulates
      one chunk per local device, split over them (``physsim.devices``), each
      world with its chunk's keys: every world gets the same inputs on any
      number of devices (on MuJoCo C the same recordings to the bit). MuJoCo
      Warp on a GPU is not bit-reproducible from run to run (its kernels sum
      with atomics and a gusty sheet drifts apart): two runs of one sweep on
      one GPU differ as much as one GPU against two (BENCHMARKS.md).
      Rendering goes in chunks that fit free device memory.
    workers: threads for the C backend (0: all cores).
    gust_intensity: RMS relative wind fluctuation.
    rgb: also write shaded colour frames, each material in its
      physsim.FABRIC_COLORS colour (as the estimate renders RGB candidates).
    noise: apply ``physsim.sensor`` depth-camera noise to the depth frames.
    render_method: ``'raster'`` or ``'brute'`` (``physsim.render``).
    garment: '' for the square cloth, else a ``physsim.GARMENTS`` name.
    garment_spacing: garment grid spacing, metres.
    poses: ``'train'`` (``PoseRanges()``) or ``'evaluation'`` (the disjoint
      ``PoseRanges.evaluation()``).
    timestep: simulation step, seconds; 1/fps must be a multiple of it.
    min_coverage: share of a frame's pixels the cloth must cover in every
      frame of a camera, as someone filming it would frame it; a camera below
      it gets a new pose, up to ``pose_draws`` draws in all (0: off).
    pose_draws: most poses drawn per camera when ``min_coverage`` is on.
    physics: ``'own'`` (the estimator's simulator) or ``'mismatched'``
      (``physsim.MISMATCHES``: a fan off the cloth's normal, another gust
      spectrum, drag, damped bending, stretchier edges): recordings unlike the
      estimator's simulator, as a real rig is, to measure coverage on.
    scaled_edges: the edges' time constant shrinks with a mesh finer than
      ``physsim.EDGE_SOLREF_SPACING`` (``physsim.config_for_mesh``: the same
      stretch stiffness on every mesh); off: the fixed one of datasets made
      before (only meshes finer than that differ).
    hem_mass: kg of known mass along the square cloth's free edge in every
      sequence (``physsim.hem_mass``: coins taped along the hem; 0: none),
      for recordings of a protocol's hemmed sheet (``benchmarks.joint_pairs
      --hem_mass``).
  """

  materials: tuple[str, ...] = tuple(physsim.FABRICS)
  sequences: int = 30
  frames: int = 60
  fps: float = 20.0
  warmup: float = 1.0
  cameras: int = 6
  resolution: int = 256
  cloth_resolution: int = 25
  cloth_size: float = 1.0
  seed: int = 0
  backend: str = cli.choice('auto', physsim.BACKENDS)
  batch_size: int = 30
  workers: int = 0
  gust_intensity: float = 0.2
  rgb: bool = False
  noise: bool = False
  render_method: str = cli.choice('raster', ('raster', 'brute'))
  garment: str = ''
  garment_spacing: float = 0.04
  poses: str = cli.choice('train', ('train', 'evaluation'))
  timestep: float = 0.002
  min_coverage: float = 0.0
  pose_draws: int = 8
  scaled_edges: bool = True
  physics: str = cli.choice('own', tuple(physsim.MISMATCHES))
  hem_mass: float = 0.0


PRESETS = {
  'paper': Config(),
  'smoke': Config(
    materials=('gray_interlock', 'black_denim'),
    sequences=2,
    frames=4,
    warmup=0.25,
    cameras=2,
    resolution=32,
    cloth_resolution=8,
    backend='c',
    batch_size=2,
    workers=1,
  ),
  # Real-like evaluation recordings, unlike the training data the way reality
  # is: finer mesh, sensor noise, 24 fps for 2.5 s, unseen camera poses, gustier
  # wind, one camera. Garments: the same with --garment (experiments.make_eval_set).
  'eval': Config(
    sequences=3,
    frames=60,
    fps=24.0,
    cameras=1,
    cloth_resolution=33,
    noise=True,
    poses='evaluation',
    gust_intensity=0.3,
    batch_size=3,
    timestep=1 / 480,
    seed=1000,  # parameter draws and gusts unlike the training set's (seed 0)
    # Unseen poses can catch a wind-lifted sheet edge-on or leave it out of view
    # (empty frames at 32x32); nobody keeps such a recording.
    min_coverage=0.01,
  ),
}
# Fields that do not change what is generated, so a resume may differ in them.
_FREE_FIELDS = ('workers',)


# PNG encoding releases the GIL: sequences of a batch are written in parallel.
_WRITERS = 8

POSES = {'train': physsim.PoseRanges(), 'evaluation': physsim.PoseRanges.evaluation()}


def _draw_poses(config: Config, keys, seq_idx, attempt: int) -> physsim.Pose:
  """(B, C) camera poses of sequences ``seq_idx``; draw 0 is the one a sweep
  without ``min_coverage`` uses, so turning it on changes only the re-drawn."""

  def one(key, i):
    key = jax.random.fold_in(key, i)
    if attempt:
      key = jax.random.fold_in(key, attempt)
    ranges = POSES[config.poses]
    if not config.garment:
      ranges = ranges.for_cloth(config.cloth_size)
    return physsim.sample_poses(key, config.cameras, ranges)

  return jax.vmap(one)(keys, seq_idx)


def _coverage(depth: np.ndarray) -> np.ndarray:
  """(B, C, T, H, W) depth -> (B, C): the least share of cloth pixels in a frame."""
  return (depth > 0).mean(axis=(-1, -2)).min(axis=-1)


def _where_cameras(low: np.ndarray, new, old) -> np.ndarray:
  """Per (world, camera): ``new`` where ``low``, else ``old``."""
  return np.where(low.reshape(low.shape + (1,) * (np.ndim(old) - 2)), new, old)


def _frame_cameras(config: Config, draw, render, poses, frames, valid):
  """Draws new poses for the cameras of valid worlds whose cloth covers less
  than ``config.min_coverage`` of some frame, until none does or a camera has
  had ``config.pose_draws`` poses, and keeps each camera's best-covered pose
  (a sheet blown flat can stay grazing from every pose); only those cameras'
  frames change. ``render(worlds, poses)`` renders those worlds alone: a few
  worlds of a call are redrawn, and rendering the call's every world for
  each draw cost more than its simulation on a GPU.

  Returns:
    (poses, depth, rgb or None, (B, C) poses drawn per camera, (B, C) coverage,
    or None when ``min_coverage`` is off: the sweep's hot path skips it).
  """
  depth, rgb = frames
  if not config.min_coverage:
    return poses, depth, rgb, None, None
  poses = jax.tree.map(np.array, poses)  # host copies, updated in place
  cover = _coverage(depth)
  draws = np.ones(cover.shape, np.int64)
  for attempt in range(1, config.pose_draws):
    low = (cover < config.min_coverage) & np.asarray(valid)[:, None]
    if not low.any():
      break
    worlds = np.flatnonzero(low.any(axis=1))
    some = low[worlds]
    old = jax.tree.map(lambda a: a[worlds], poses)  # noqa: B023 - used at once
    new_poses = jax.tree.map(
      lambda a, o: _where_cameras(some, np.asarray(a)[worlds], o),  # noqa: B023
      draw(attempt),
      old,
    )
    new_depth, new_rgb = render(worlds, new_poses)
    new_cover = _coverage(new_depth)
    pick = functools.partial(_where_cameras, some & (new_cover > cover[worlds]))
    for a, new in zip(poses, jax.tree.map(pick, new_poses, old), strict=True):
      a[worlds] = new
    depth[worlds] = pick(new_depth, depth[worlds])
    cover[worlds] = pick(new_cover, cover[worlds])
    if rgb is not None:
      rgb[worlds] = pick(new_rgb, rgb[worlds])
    draws += low
  return poses, depth, rgb, draws, cover


def _mesh(config: Config) -> physsim.Mesh:
  if config.garment:
    return physsim.garment(config.garment, config.garment_spacing)
  return physsim.square(config.cloth_resolution, config.cloth_size)


def _material_stream(seed: int, material: str) -> int:
  # Stable across runs and material lists (Python's hash() is salted).
  return zlib.crc32(f'{seed}/{material}'.encode())


def material_params(config: Config, material: str) -> physsim.Params:
  """The material's ``sequences`` parameter sets (a prefix-stable draw)."""
  rng = np.random.default_rng([config.seed, _material_stream(config.seed, material)])
  return physsim.params.sample(rng, config.sequences, physsim.search_space(material))


def _check_config(config: Config) -> None:
  unknown = [m for m in config.materials if m not in physsim.FABRICS]
  if unknown or not config.materials:
    raise ValueError(f'materials {unknown} not in {sorted(physsim.FABRICS)}')
  if len(set(config.materials)) != len(config.materials):
    raise ValueError(f'materials repeat: {config.materials}')
  for name in ('sequences', 'frames', 'cameras', 'resolution', 'batch_size'):
    if getattr(config, name) < 1:
      raise ValueError(f'{name} must be >= 1, got {getattr(config, name)}')
  if config.garment and config.garment not in physsim.GARMENTS:
    raise ValueError(
      f'garment must be one of {physsim.GARMENTS}, got {config.garment!r}'
    )
  if config.poses not in POSES:
    raise ValueError(f'poses must be one of {tuple(POSES)}, got {config.poses!r}')
  if config.cloth_resolution < 2:
    raise ValueError(f'cloth_resolution must be >= 2, got {config.cloth_resolution}')
  if not 0.05 <= config.cloth_size <= 3.0:
    raise ValueError(f'cloth_size must be in [0.05, 3] m, got {config.cloth_size}')
  if config.physics not in physsim.MISMATCHES:
    raise ValueError(
      f'physics must be one of {tuple(physsim.MISMATCHES)}, got {config.physics!r}'
    )
  if not 0.0 <= config.hem_mass <= 1.0 or (config.garment and config.hem_mass):
    raise ValueError(
      f'hem_mass must be in [0, 1] kg on the square cloth, got {config.hem_mass}'
      + (f' on garment {config.garment!r}' if config.garment else '')
    )
  if not 0.0 <= config.min_coverage < 1.0 or config.pose_draws < 1:
    raise ValueError(
      f'need 0 <= min_coverage < 1 and pose_draws >= 1, got {config.min_coverage} '
      f'and {config.pose_draws}'
    )


def _identity(config: Config, backend: str) -> dict:
  d = dataclasses.asdict(config)
  d['materials'] = list(config.materials)
  d['backend'] = backend
  d['batching'] = 'across-materials'  # how gust keys map to sequences
  if config.rgb:  # older RGB datasets were all one grey
    d['rgb_colors'] = 'fabric'
  for k in _FREE_FIELDS:
    d.pop(k)
  if not config.min_coverage:  # datasets made before the re-draw match
    d.pop('min_coverage'), d.pop('pose_draws')
  if config.cloth_size == 1.0:  # ... and before the size was a setting
    d.pop('cloth_size')
  if config.physics == 'own':  # ... and before recordings of another physics
    d.pop('physics')
  if not config.hem_mass:  # ... and before a hem could be added
    d.pop('hem_mass')
  if physsim.scaled_edge_solref(_mesh(config).shortest_edge, 1.0) == 1.0:
    d.pop('scaled_edges')  # the same edges either way, as before the setting
  return d


def _check_params(config: Config, params: dict | None) -> dict | None:
  """Validated explicit parameter sets (``run``'s ``params``), or None."""
  if params is None:
    return None
  out = {}
  for m in config.materials:
    if m not in params:
      raise ValueError(f'params has no parameter sets for material {m!r}')
    p = physsim.params.validate(params[m], physsim.search_space(m))
    if p.bending_scale.shape != (config.sequences,):
      raise ValueError(
        f'params[{m!r}] holds {p.bending_scale.shape} sets, want ({config.sequences},)'
      )
    out[m] = p
  return out


def _open_workdir(workdir: str, config: Config, backend: str, params=None) -> dict:
  """Creates or checks ``dataset.json``; a resume must match the config."""
  os.makedirs(workdir, exist_ok=True)
  dataset.clean_tmp(workdir)
  ident = _identity(config, backend)
  if params is not None:
    ident['params'] = {
      m: np.stack(list(p), 1).round(12).tolist() for m, p in params.items()
    }
  info_path = os.path.join(workdir, 'dataset.json')
  if os.path.isfile(info_path):
    info = dataset.read_json(info_path)
    old = info.get('config', {})
    diff = sorted(k for k in set(old) | set(ident) if old.get(k) != ident.get(k))
    if diff:
      raise ValueError(
        f'{info_path}: this folder holds a dataset made with a different config '
        f'({", ".join(f"{k}: {old.get(k)!r} -> {ident.get(k)!r}" for k in diff)}); '
        'use another --out or the same settings'
      )
    return info
  return dataset.write_dataset_info(
    workdir,
    seed=config.seed,
    config=ident,
    jax_backend=jax.default_backend(),
    pose_ranges=POSES[config.poses].to_dict(),
  )


def _check_workdir(workdir: str, config: Config, backend: str, params=None) -> None:
  """What ``_open_workdir`` checks, read-only (processes other than 0)."""
  info = dataset.read_json(os.path.join(workdir, 'dataset.json'))
  ident = _identity(config, backend)
  if params is not None:
    ident['params'] = {
      m: np.stack(list(p), 1).round(12).tolist() for m, p in params.items()
    }
  if info.get('config') != json.loads(json.dumps(ident)):
    raise ValueError(f"{workdir}/dataset.json: another config than this process's")


def _gathered_counts(workdir: str, materials) -> dict:
  """Every process's counts summed (``.counts.<i>.json``)."""
  total = {
    m: {'existing': 0, 'written': 0, 'valid': 0, 'invalid': 0} for m in materials
  }
  for i in range(jax.process_count()):
    part = dataset.read_json(os.path.join(workdir, f'.counts.{i}.json'))
    for m, c in part.items():
      for k, v in c.items():
        total[m][k] += v
  return total


def _renderer(faces, intrinsics, config: Config, mesh=None):
  """The jitted per-batch render stage: (positions, poses, (B,) keys, (B, 3)
  colours) -> depth[, rgb], its worlds split over ``mesh``'s devices."""
  noise = None
  if config.noise:
    try:
      from physsim import sensor  # imported only when used
    except ImportError as e:
      raise ValueError(f'--noise needs physsim.sensor, which is missing ({e})') from e
    noise = sensor.SensorNoise()
  faces = jnp.asarray(faces, jnp.int32)

  def render(positions, poses, keys, colors):
    depth = physsim.render_depth(
      positions, faces, intrinsics, poses, method=config.render_method
    )  # (B, C, T, H, W)
    if noise is not None:  # each world's own key: the same noise on any devices
      depth = jax.vmap(lambda k, d: sensor.apply_noise_frames(k, d, intrinsics, noise))(
        keys, depth
      )
    rgb = None
    if config.rgb:  # a batch mixes materials: one colour per world
      rgb = physsim.render_rgb8(
        positions, faces, intrinsics, poses, colors, method=config.render_method
      )  # (B, C, T, H, W, 3)
    return depth, rgb

  return jax.jit(physsim.devices.shard_worlds(render, mesh))


def _render_chunk(config: Config, batch: int, n_devices: int) -> int:
  """Worlds rendered per call: what fits in free device memory (each world's
  frames, colour too, with room for the renderer's buffers), a multiple of
  the device count, at most the batch."""
  pixels = config.cameras * config.frames * config.resolution**2
  per_world = 3 * pixels * (4 + (3 if config.rgb else 0))
  n = physsim.devices.chunk_size(per_world, cap=batch)
  return max(n_devices, n // n_devices * n_devices)


def _some_worlds(render, positions, keys, colors):
  """``(worlds, poses) -> render`` of those worlds of a call (indices), seen
  from ``poses``, each with its own noise key and colour."""
  return lambda w, poses: render(positions[w], poses, keys[w], colors[w])


def _chunked(render, chunk: int):
  """``render(positions, poses, keys, colors)`` over the worlds in chunks of
  ``chunk`` (the last one padded with its last world, so one compile serves
  every call); its arguments are host arrays, the keys as their key data
  (gathered on the host: a device gather compiles for every count of worlds),
  and depth and colour come back as host arrays."""

  def run(positions, poses, keys, colors):
    b = positions.shape[0]
    depth, rgb = [], []
    for start in range(0, b, chunk):
      idx = np.minimum(np.arange(start, start + chunk), b - 1)
      take = lambda a: np.asarray(a)[idx]  # noqa: B023 - used at once
      d, c = render(
        take(positions),
        jax.tree.map(take, poses),
        jax.random.wrap_key_data(take(keys)),
        take(colors),
      )
      n = min(chunk, b - start)
      depth.append(np.asarray(d)[:n])
      rgb.append(None if c is None else np.asarray(c)[:n])
    return np.concatenate(depth), None if rgb[0] is None else np.concatenate(rgb)

  return run


def _sequence_meta(config: Config, row: dict, intrinsics, mesh_name: str,
                   backend: str, poses, depth) -> dict:  # fmt: skip
  """A written sequence's ``meta.json``: its index row, the sweep's settings,
  its (C,) camera ``poses`` and, for a valid world (``depth`` (C, T, H, W);
  None for one that blew up), how many of its frames show no cloth."""
  return {
    **row,
    'fps': config.fps,
    'warmup_s': config.warmup,
    'intrinsics': intrinsics.to_dict(),
    'extrinsics': [
      physsim.pose_to_dict(physsim.Pose(poses.rotation[c], poses.position[c]))
      for c in range(config.cameras)
    ],
    'mesh': mesh_name,
    'garment': config.garment,
    'seed': config.seed,
    'backend': backend,
    'gust_intensity': config.gust_intensity,
    **({'physics': config.physics} if config.physics != 'own' else {}),
    **({'hem_mass': config.hem_mass} if config.hem_mass else {}),
    'noise': config.noise,
    **({'rgb_color': list(embedding.rgb_color(row['material']))} if config.rgb else {}),
    'empty_frames': None
    if depth is None
    else int(np.sum(~(depth > 0).any(axis=(-1, -2)))),
  }


def _batches_per_call(backend: str, n_devices: int) -> int:
  """Batches a simulation call takes: one per local device on a device
  backend, so that a batch under a GPU step's fixed cost (``physsim.devices.
  FLAT_WORLDS``) still splits over the devices (each world keeps its batch's
  keys: its inputs do not depend on the device count); one on MuJoCo C,
  which simulates world after world (a padded call would cost its padding)."""
  return 1 if backend == 'c' else n_devices


def _call_worlds(jobs: list, batches: list[int], bs: int, per_call: int):
  """A device call's worlds: each of ``batches``' chunk of ``jobs`` padded to
  ``bs`` with its last, then the call to ``per_call`` chunks with the last
  world (so one program shape serves every call); and each batch's first
  world in the call."""
  worlds, first = [], {}
  for b in batches:
    chunk = jobs[b * bs : (b + 1) * bs]
    first[b] = len(worlds)
    worlds += chunk + [chunk[-1]] * (bs - len(chunk))
  return worlds + [worlds[-1]] * (per_call * bs - len(worlds)), first


def _call_keys(root_key, batches: list[int], bs: int, n: int):
  """(gust keys, sensor-noise key data), each for n worlds, of a call: batch
  ``b``'s two keys from ``fold_in(root_key, 2 + b)``, split over its ``bs``
  worlds, the call's padding repeating the last (``_call_worlds``)."""
  wind, noise = [], []
  for b in batches:
    k_wind, k_noise = jax.random.split(jax.random.fold_in(root_key, 2 + b))
    wind.append(jax.random.split(k_wind, bs))
    noise.append(jax.random.split(k_noise, bs))
  idx = np.minimum(np.arange(n), len(batches) * bs - 1)
  noise = np.asarray(jax.random.key_data(jnp.concatenate(noise)))
  return jnp.concatenate(wind)[idx], noise[idx]


def _montage_path(workdir: str, material: str) -> str:
  return os.path.join(workdir, f'montage_{material}.png')


def _montage(workdir: str, material: str, rows: list[dict], n: int = 6) -> str | None:
  """A grid of camera-0 frames (rows: sequences, columns: time), read from disk."""
  rows = [r for r in rows if r['valid']][:n]
  if not rows:
    return None
  seqs = [
    dataset.read_sequence(
      dataset.sequence_dir(workdir, material, r['seq_id']), cameras=[0], rgb=False
    )
    for r in rows
  ]
  t = seqs[0].depth.shape[1]
  cols = np.unique(np.linspace(0, t - 1, min(n, t)).round().astype(int))
  valid = np.concatenate([s.depth[0][cols][s.depth[0][cols] > 0] for s in seqs])
  lo, hi = np.percentile(valid, [1, 99]) if valid.size else (0.0, 1.0)
  plt = files.pyplot()
  cmap = plt.get_cmap('viridis').with_extremes(bad='white')
  fig, axes = plt.subplots(
    len(seqs), len(cols), figsize=(1.6 * len(cols) + 1.0, 1.6 * len(seqs) + 0.4),
    squeeze=False, layout='constrained',  # labels and colour bar inside the canvas
  )  # fmt: skip
  for i, (s, r) in enumerate(zip(seqs, rows, strict=True)):
    for j, c in enumerate(cols):
      ax = axes[i, j]
      d = s.depth[0, c]
      im = ax.imshow(np.ma.masked_equal(d, 0.0), cmap=cmap, vmin=lo, vmax=hi)
      ax.set(xticks=[], yticks=[])
      if i == 0:
        ax.set_title(f't={c / s.meta["fps"]:.2f} s', fontsize=7)
      if j == 0:
        ax.set_ylabel(
          f'{r["seq_id"]}\nb{r["bending_scale"]:.2g} w{r["wind_speed"]:.2g}\n'
          f'a{r["area_weight"]:.3g}',
          fontsize=6,
        )
  fig.colorbar(im, ax=axes, shrink=0.6, label='depth, m (white: invalid)')
  fig.suptitle(f'{material}, camera 0', fontsize=9)
  path = _montage_path(workdir, material)
  files.savefig(fig, path, dpi=110)
  plt.close(fig)
  return path


def run(config: Config, workdir: str, params: dict | None = None) -> dict:
  """Generates (or resumes) the dataset in ``workdir``; returns the summary.

  Args:
    config: the sweep.
    workdir: dataset root (``physsim.dataset`` layout).
    params: optional ``{material: physsim.Params}`` with ``sequences``
      parameter sets each, instead of the seeded uniform draw (a study that
      needs recordings sharing some parameters); recorded in dataset.json.

  Returns:
    The summary also written to ``<workdir>/summary.json``: counts per
    material, seconds simulating / rendering / writing, frames per second.
  """
  _check_config(config)
  backend = physsim.resolve_backend(config.backend)
  given = _check_params(config, params)
  # Several processes (jax.distributed) share the batches: process 0 opens
  # (or checks) the folder first, each writes its batches' sequences, and
  # process 0 indexes them all once every process is done.
  many = jax.process_count() > 1
  if distributed.is_main():
    _open_workdir(workdir, config, backend, given)
  distributed.barrier(f'dataset {workdir}: opened')
  if not distributed.is_main():
    _check_workdir(workdir, config, backend, given)
  intrinsics = physsim.Intrinsics(width=config.resolution, height=config.resolution)
  mesh = _mesh(config)
  # A fine mesh needs a shorter step; MuJoCo's stiffest safe constraint time
  # constant is two steps.
  physics = physsim.MISMATCHES[config.physics]
  sim_config = physsim.config_for_mesh(
    mesh, config.fps, config.timestep, scaled_edges=config.scaled_edges,
    **physics.sim_fields(),
  )  # fmt: skip
  world_mesh = physsim.devices.world_mesh()
  bs = config.batch_size
  n_dev = world_mesh.devices.size
  # Every process groups the batches alike (they share the calls by index):
  # by the fewest devices any process has.
  fewest = min(collections.Counter(d.process_index for d in jax.devices()).values())
  per_call = _batches_per_call(backend, min(n_dev, fewest))
  renderer = _renderer(mesh.faces, intrinsics, config, world_mesh)
  chunk = _render_chunk(config, bs * per_call, n_dev)
  render = _chunked(renderer, chunk)
  # Cameras drawn again (min_coverage) are few: their worlds go in chunks of
  # an eighth, one more program shape, where that is at least a world a device.
  redraw = _chunked(renderer, chunk // 8 // n_dev * n_dev or chunk)
  wind = physics.wind(config.gust_intensity)
  root_key = jax.random.key(config.seed)
  # One compiled model for every material (bending is scaled per world), so
  # batches run across materials: jobs are (material index, sequence index).
  hem = (
    physsim.hem_mass(mesh, config.cloth_resolution, config.hem_mass)
    if config.hem_mass
    else None
  )
  model = physsim.build(mesh, config.materials[0], sim_config, extra_mass=hem)
  params = {m: given[m] if given else material_params(config, m)
            for m in config.materials}  # fmt: skip
  cam_keys = {
    m: jax.random.fold_in(
      jax.random.fold_in(root_key, _material_stream(config.seed, m)), 1
    )
    for m in config.materials
  }
  jobs = [(k, i) for k in range(len(config.materials)) for i in range(config.sequences)]
  n_batches = -(-len(jobs) // bs)
  calls = [
    list(range(c, min(c + per_call, n_batches))) for c in range(0, n_batches, per_call)
  ]
  # The first call includes compiles (the simulator and the renderer).
  seconds = {
    'simulate': 0.0,
    'simulate_first_batches': 0.0,
    'render': 0.0,
    'first_render_call': None,
    'write': 0.0,
    'redraw': 0.0,
  }
  frames_simulated = 0
  n_sim_calls = 0
  counts = {
    m: {'existing': 0, 'written': 0, 'valid': 0, 'invalid': 0} for m in config.materials
  }
  frames_rendered = 0
  cameras_redrawn = 0
  mine = distributed.share(list(range(len(calls))))
  bar = progress.Bar(
    sum(len(jobs[b * bs : (b + 1) * bs]) for c in mine for b in calls[c]),
    'simulate + render',
    'seq',
  )
  # --time_limit's forecast of the next call: the last one's time, less its
  # compile and set-up (the calls of a sweep run one program shape)
  last_call_s, one_off = 0.0, physsim.one_off.Meter()
  with concurrent.futures.ThreadPoolExecutor(_WRITERS) as writers:
    for c in mine:
      todo = {}  # batch -> its sequences not yet written
      for b in calls[c]:
        chunk = jobs[b * bs : (b + 1) * bs]
        left = [
          (k, i)
          for k, i in chunk
          if not dataset.is_complete(workdir, config.materials[k], f'{i:04d}')
        ]
        for k, _ in set(chunk) - set(left):
          counts[config.materials[k]]['existing'] += 1
        bar.skip(len(chunk) - len(left))
        if left:
          todo[b] = left
      if not todo:
        continue
      first, last = calls[c][0] + 1, calls[c][-1] + 1
      deadline.check(
        last_call_s,
        f'batch {first} of {n_batches}'
        if first == last
        else f'batches {first}-{last} of {n_batches}',
      )
      t_call = time.perf_counter()
      one_off.mark()
      world_jobs, first_world = _call_worlds(jobs, list(todo), bs, per_call)
      names = [config.materials[k] for k, _ in world_jobs]
      p = physsim.Params(
        *(
          np.array(
            [
              getattr(params[n], f)[i]
              for n, (_, i) in zip(names, world_jobs, strict=True)
            ]
          )
          for f in physsim.Params._fields
        )
      )
      wind_keys, noise_keys = _call_keys(root_key, list(todo), bs, len(world_jobs))
      t0 = time.perf_counter()
      out = physsim.simulate(
        model,
        p,
        frames=config.frames,
        fps=config.fps,
        warmup=config.warmup,
        wind=wind,
        key=wind_keys,
        backend=backend,
        workers=config.workers or None,
        material=names,
      )
      dt = time.perf_counter() - t0
      n_sim_calls += 1
      if c == 0:
        seconds['simulate_first_batches'] += dt
      else:
        seconds['simulate'] += dt
        frames_simulated += len(world_jobs) * config.frames
      # Cameras per sequence, independent of batching.
      draw = functools.partial(
        _draw_poses,
        config,
        jnp.stack([cam_keys[n] for n in names]),
        jnp.asarray([i for _, i in world_jobs]),
      )
      poses = draw(0)  # (B, C)
      # Blown-up worlds render the rest mesh: same shapes, frames discarded.
      positions = np.where(
        out.valid[:, None, None, None], out.positions, mesh.vertices.astype(np.float32)
      )
      t0 = time.perf_counter()
      colors = np.array([embedding.rgb_color(n) for n in names], np.float32)
      depth, rgb = render(positions, poses, noise_keys, colors)
      dt = time.perf_counter() - t0
      if seconds['first_render_call'] is None:
        seconds['first_render_call'] = dt  # includes the compile
      else:
        seconds['render'] += dt
        frames_rendered += depth.size // (config.resolution**2)
      t0 = time.perf_counter()
      poses, depth, rgb, draws, coverage = _frame_cameras(
        config,
        draw,
        _some_worlds(redraw, positions, noise_keys, colors),
        poses,
        (depth, rgb),
        out.valid,
      )
      poses = jax.tree.map(np.asarray, poses)  # on the host (min_coverage off)
      seconds['redraw'] += time.perf_counter() - t0
      t0 = time.perf_counter()
      pending = []
      for b, left in todo.items():
        for j, (k, i) in enumerate(jobs[b * bs : (b + 1) * bs]):
          if (k, i) not in left:
            continue
          w = first_world[b] + j  # its world in the call
          material = config.materials[k]
          valid = bool(out.valid[w])
          row = dataset.make_row(
            f'{i:04d}',
            material,
            k * config.sequences + int(i),
            physsim.Params(*(f[i] for f in params[material])),
            physsim.search_space(material),
            valid=valid,
            n_cameras=config.cameras,
            n_frames=config.frames,
          )
          meta = _sequence_meta(
            config, row, intrinsics, mesh.name, backend,
            jax.tree.map(lambda a: a[w], poses),  # noqa: B023 - used at once
            depth[w] if valid else None,
          )  # fmt: skip
          if coverage is not None and valid:  # min_coverage is on
            meta['pose_draws'] = draws[w].tolist()
            meta['coverage_min'] = [round(float(x), 5) for x in coverage[w]]
            cameras_redrawn += int((draws[w] > 1).sum())
            if coverage[w].min() < config.min_coverage:
              logging.warning(
                '%s/%04d: the best of %d camera poses sees the cloth on %.4f of a frame',
                material, i, config.pose_draws, coverage[w].min(),
              )  # fmt: skip
          pending.append(
            writers.submit(
              dataset.write_sequence,
              workdir,
              meta,
              depth[w] if valid else None,
              rgb[w] if valid and rgb is not None else None,
            )
          )
          counts[material]['written'] += 1
      for f in concurrent.futures.as_completed(pending):
        f.result()  # re-raises a failed write
      bar.done(len(pending))
      if not many:  # one process: the index follows every call
        dataset.rebuild_index(workdir)
      seconds['write'] += time.perf_counter() - t0
      last_call_s = max(time.perf_counter() - t_call - one_off.seconds(), 0.0)
  bar.close()
  if many:  # each process's counts, for process 0's summary
    dataset.write_json_atomic(
      os.path.join(workdir, f'.counts.{jax.process_index()}.json'), counts
    )
  distributed.barrier(f'dataset {workdir}: written')
  if many:
    counts = _gathered_counts(workdir, config.materials)
  main = distributed.is_main()
  rows = dataset.rebuild_index(workdir) if main else []
  montages = {}
  for material in config.materials:
    mrows = [r for r in rows if r['material'] == material]
    counts[material]['valid'] = sum(r['valid'] for r in mrows)
    counts[material]['invalid'] = sum(not r['valid'] for r in mrows)
    drawn = _montage_path(workdir, material)
    if not main:
      montages[material] = None
    elif counts[material]['written'] == 0 and os.path.isfile(drawn):
      montages[material] = drawn  # a resumed sweep: the same sequences as drawn
    else:
      montages[material] = _montage(workdir, material, mrows)
  total = sum(c['written'] for c in counts.values())
  sim_total = seconds['simulate'] + seconds['simulate_first_batches']
  summary = {
    'backend': backend,
    'device': jax.default_backend(),
    'counts': counts,
    'sequences_written': total,
    'seconds': seconds,
    'frames_rendered_after_compile': frames_rendered,
    'cameras_redrawn': cameras_redrawn,  # min_coverage: poses drawn again
    'render_frames_per_s': frames_rendered / seconds['render']
    if seconds['render']
    else None,
    'frames_simulated_after_first_batches': frames_simulated,
    'simulated_world_frames_per_s_with_compile': (
      n_sim_calls * per_call * bs * config.frames / sim_total if sim_total else None
    ),
    'simulated_world_frames_per_s': (
      frames_simulated / seconds['simulate'] if seconds['simulate'] else None
    ),
    'montages': montages,
    'processes': jax.process_count(),
  }
  if main:
    dataset.write_json_atomic(os.path.join(workdir, 'summary.json'), summary)
  distributed.barrier(f'dataset {workdir}: indexed')  # the index is whole for all
  return summary


def describe(s: dict, out: str) -> str:
  """A summary from ``run`` as a short report: counts per material and timings."""
  lines = [
    f'{out}: {s["sequences_written"]} sequences written ({s["backend"]} backend, '
    f'{s["device"]})',
    '| material | existing | written | valid | invalid |',
    '|---|---:|---:|---:|---:|',
  ]
  for m, c in s['counts'].items():
    lines.append(
      f'| {m} | {c["existing"]} | {c["written"]} | {c["valid"]} | {c["invalid"]} |'
    )
  sec = s['seconds']
  nan = float('nan')
  lines.append(
    f'simulate: first batch (with compile) {sec["simulate_first_batches"]:.1f} s, '
    f'later batches {sec["simulate"]:.1f} s '
    f'({s["simulated_world_frames_per_s"] or nan:.1f} world-frames/s); render: first '
    f'call (with compile) {sec["first_render_call"] or 0:.1f} s, later '
    f'{sec["render"]:.1f} s ({s["render_frames_per_s"] or nan:.0f} frames/s); '
    f'write {sec["write"]:.1f} s'
  )
  return '\n'.join(lines)
