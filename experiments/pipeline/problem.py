"""One recording as the objective scores it: its arrays and the structure they share.

A ``Problem`` is what ``make_problem`` reads once from a recording and its
settings (cameras, the recording's frames or mean shape, its embedding, the
search box); recordings of one ``structure`` are stacked (``stack``) and
scored in one call of one compiled ``objective.Objective``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline import embedding, measurements
from experiments.pipeline.config import (
  EMBEDDING_DISTANCES,
  SHAPE_DISTANCES,
  EstimateConfig,
)
from experiments.pipeline.recording import Recording
from experiments.pipeline.simulation import Simulation, cloth

# A recording's shape summary as one program, compiled once per frame shape and
# camera model (``Intrinsics`` is hashable) for every recording a process reads.
_shape_summary = jax.jit(physsim.shape.summary, static_argnums=1)


class ProblemData(NamedTuple):
  """One recording's arrays (stack several on a leading axis to score them together).

  Attributes:
    lo, hi: (3,) the search box in the optimiser's coordinates
      (``physsim.params.unit_map``: bending as logs).
    log: (3,) which fields map log-uniformly.
    rigidity_ratio: () the fabric's reference bending over the cloth model's.
    poses: ``physsim.Pose`` of its C cameras, rotation (C, 3, 3), position (C, 3).
    color: (3,) the fabric's RGB colour (RGB networks; unused for depth).
    params: its network's params (an ensemble's stacked, leading axis K).
    rec_points: (N, D) the recording's embedding ((K, N, D) for an ensemble).
    rec_shape: (2,) the recording's ``physsim.shape.summary`` (zeros when the
      distance does not use it).
    camera_sd: (2,) the camera error its estimate carries (``camera_sd_m``,
      ``camera_sd_deg``): data, not structure, so recordings carrying
      different errors (a calibration study's, drawn over a range) are scored
      in one call of one program.
  """

  lo: jax.Array
  hi: jax.Array
  log: jax.Array
  rigidity_ratio: jax.Array
  poses: physsim.Pose
  color: jax.Array
  params: object
  rec_points: jax.Array
  rec_shape: jax.Array
  camera_sd: jax.Array


class Problem(NamedTuple):
  """One recording's objective: host-side description plus its arrays.

  Attributes:
    config: its settings.
    source: the recording's path (for messages).
    space: the material's search space.
    n_frames: frames simulated (the recording's, at ``config.simulation.fps``).
    intr: camera intrinsics (the recording's or a default field of view).
    net: its embedding network.
    data: its ``ProblemData``.
  """

  config: EstimateConfig
  source: str
  space: physsim.SearchSpace
  n_frames: int
  intr: physsim.Intrinsics
  net: embedding.EmbeddingNet
  data: ProblemData

  def structure(self) -> tuple:
    """What the fused program is compiled for: problems with equal structure
    share one ``Objective`` and are scored in one call."""
    c, n = self.config, self.net
    s, h = c.simulation, c.hardware
    return (
      s.garment, s.garment_spacing if s.garment else 0.0,
      0 if s.garment else s.cloth_resolution, 0.0 if s.garment else s.cloth_size,
      s.hem_mass,
      self.n_frames, s.fps, s.warmup,
      s.gusts, physsim.resolve_backend(h.backend), h.workers, self.intr,
      self.data.poses.position.shape[0], s.sensor_noise, c.scoring.distance,
      bool(c.scoring.camera_sd_m or c.scoring.camera_sd_deg),  # its size is data
      n.modality, n.input_mode, n.clip_frames, n.architecture, n.members,
      jax.tree.structure(n.params),
    )  # fmt: skip


def make_problem(
  config: EstimateConfig, net: embedding.EmbeddingNet, recording: Recording
) -> Problem:
  """Sets up one recording's objective: checks it against the network, picks
  its cameras and embeds it.

  Raises:
    ValueError: a bad config, a recording whose frames do not fit the network
      (size, modality, shorter than an SDN clip), naming the recording.
  """
  config.check()
  sim, distance = config.simulation, config.scoring.distance
  if net.network is None and distance in EMBEDDING_DISTANCES:
    raise ValueError(
      f'{recording.source}: distance {distance!r} embeds frames with a '
      "trained network, and none was given; only 'shape' needs none (--model)"
    )
  size = tuple(net.image_size)
  if tuple(recording.depth.shape[1:]) != size:
    raise ValueError(
      f'{recording.source}: frames of {recording.depth.shape[1:]} but the '
      f'network takes {size}; load the recording at that size'
    )
  rec_frames = recording.rgb if net.modality == 'rgb' else recording.depth
  if rec_frames is None:
    raise ValueError(
      f'{recording.source}: no RGB frames, but the network embeds colour frames '
      '(load_recording(..., rgb=True) of a sequence with cam0/rgb_*.png)'
    )
  n_frames = rec_frames.shape[0]
  if net.clip_frames and n_frames < net.clip_frames:
    raise ValueError(
      f'{recording.source}: {n_frames} frames at {recording.fps} fps, shorter '
      f'than one SDN clip of {net.clip_frames} frames; use a longer recording '
      '(and --frames >= the clip)'
    )
  shaped = distance in SHAPE_DISTANCES
  if shaped and (recording.pose is None or net.modality != 'depth'):
    raise ValueError(
      f"{recording.source}: distance {distance!r} compares the sheet's "
      "shape in the world, so it needs the recording's camera pose "
      '(--camera_json) and a depth network'
    )
  rec_points = jnp.zeros((1, 1), jnp.float32)  # no network: nothing embedded
  if net.network is not None:  # on the network's device
    inputs = embedding.network_inputs(
      jnp.asarray(rec_frames)[None], net.modality, net.input_mode
    )
    # (N, D), or (K, N, D) for an ensemble of K: each member's own embedding.
    rec_points = jax.jit(embedding.embed_videos, static_argnums=(0, 3, 4))(
      net.network, net.params, inputs, net.clip_frames, net.members
    )[..., 0, :, :]
  with physsim.devices.on_host():  # small arrays: placed by each call
    space = measurements.search_box(sim.material, config.measured, config.search.box)[0]
    intr, poses, rec_shape = _recording_view(sim, config.seed, recording, shaped)
    lo, hi, log = physsim.params.unit_map(space)
    model = cloth(sim)
    data = ProblemData(
      jnp.asarray(lo, jnp.float32), jnp.asarray(hi, jnp.float32), jnp.asarray(log),
      jnp.float32(physsim.reference_rigidity(sim.material) / model.rigidity),
      poses, jnp.asarray(embedding.rgb_color(sim.material), jnp.float32),
      net.params, rec_points, rec_shape,
      jnp.asarray([config.scoring.camera_sd_m, config.scoring.camera_sd_deg], jnp.float32),
    )  # fmt: skip
  return Problem(config, recording.source, space, n_frames, intr, net, data)


def _recording_view(sim: Simulation, seed: int, recording: Recording, shaped: bool):
  """The recording's camera model, camera poses (drawn from ``seed`` where it
  has none, for ``sim``'s cloth) and (for a shape distance) its sheet's shape
  summary (``physsim.shape.summary``, one jitted program rather than an eager
  operation at a time)."""
  h, w = recording.depth.shape[1:]
  key = jax.random.key(seed)
  # A known field of view is used even when the pose is unknown.
  intr = recording.intrinsics or physsim.Intrinsics(width=w, height=h)
  if recording.pose is not None:
    poses = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32)[None], recording.pose)
  else:
    ranges = physsim.PoseRanges()
    if not sim.garment:
      ranges = ranges.for_cloth(sim.cloth_size)
    poses = physsim.sample_poses(jax.random.fold_in(key, 1), sim.cameras, ranges)
  rec_shape = jnp.zeros(len(physsim.shape.SUMMARY), jnp.float32)
  if shaped:
    rec_shape = _shape_summary(
      jnp.asarray(recording.depth), intr, jax.tree.map(lambda a: a[0], poses)
    )
    if not np.all(np.isfinite(np.asarray(rec_shape))):
      raise ValueError(f'{recording.source}: no frame has a valid depth pixel')
  return intr, poses, rec_shape


def stack(datas: list[ProblemData]) -> ProblemData:
  """ProblemData of several problems (same structure) on a leading axis."""
  return jax.tree.map(lambda *a: jnp.stack(a), *datas)
