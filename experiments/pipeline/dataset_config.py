"""A dataset sweep's settings: the config, its presets, the camera pose ranges,
the mesh and each material's seeded parameter draw (``experiments.pipeline.
datasets`` runs it)."""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np

import physsim
from experiments.pipeline import cli


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
POSES = {'train': physsim.PoseRanges(), 'evaluation': physsim.PoseRanges.evaluation()}


def cloth_mesh(config: Config) -> physsim.Mesh:
  if config.garment:
    return physsim.garment(config.garment, config.garment_spacing)
  return physsim.square(config.cloth_resolution, config.cloth_size)


def material_stream(seed: int, material: str) -> int:
  # Stable across runs and material lists (Python's hash() is salted).
  return zlib.crc32(f'{seed}/{material}'.encode())


def material_params(config: Config, material: str) -> physsim.Params:
  """The material's ``sequences`` parameter sets (a prefix-stable draw)."""
  rng = np.random.default_rng([config.seed, material_stream(config.seed, material)])
  return physsim.params.sample(rng, config.sequences, physsim.search_space(material))


def check_config(config: Config) -> None:
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


def check_params(config: Config, params: dict | None) -> dict | None:
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
