"""A trained embedding network as the estimate uses it, and what it sees.

Training (``experiments.pipeline.training``) records in each run folder how
frames were turned into inputs (``inputs.json``: the modality and the depth
input mode); the estimate repeats exactly that for the recording and for every
candidate simulation, so both land in the same embedding space.

An ensemble is several runs of one architecture named together
(``'run_a,run_b,run_c'``, see ``members``): every video is embedded by each
member, each member's PSD is taken in its own space, and the ensemble's PSD is
their geometric mean (``model.psd.geometric_mean``). Networks of one recipe
differ a lot by the seed alone; an ensemble averages out errors that are one
network's own, not those the video itself leaves (which, at paper size, were
the larger: docs/studies/calibration.md).
"""

from __future__ import annotations

import json
import os
from typing import NamedTuple

import jax
import numpy as np

import model as model_lib
import physsim
from physsim import dataset

INPUTS_FILE = 'inputs.json'
MODALITIES = ('depth', 'rgb')
CHANNELS = {'depth': 1, 'rgb': 3}


class EmbeddingNet(NamedTuple):
  """A trained run as the estimate uses it.

  Attributes:
    network, params: the ``model.Network`` and its params.
    modality: 'depth' or 'rgb'.
    input_mode: its ``model.depth_input`` mode.
    clip_frames: 0 for PhySNet (frames), the clip length for SDN.
    image_size: (H, W) its inputs have.
    materials: the fabrics it was trained on (empty when unrecorded).
    architecture: what its ``apply`` computes apart from the params (the
      network's config as text): runs of one architecture share compiles.
    members: 0 for one network; K for an ensemble of K runs, whose params
      are stacked on a leading axis of size K.
  """

  network: object
  params: object
  modality: str
  input_mode: str
  clip_frames: int
  image_size: tuple[int, int]
  materials: tuple[str, ...] = ()
  architecture: str = ''
  members: int = 0


def no_network(image_size: tuple[int, int]) -> EmbeddingNet:
  """What the estimate holds in place of a network when none is needed.

  The shape distance (``--distance=shape``) reads the sheet's place in the
  world from the depth frames themselves, so an estimate with it needs no
  trained run: frames are compared at ``image_size`` (H, W), the size the
  recording was loaded at. ``network`` is None and there are no params; the
  objective refuses any distance that would embed with it.
  """
  h, w = (int(s) for s in image_size)
  if h < 1 or w < 1:
    raise ValueError(f'image size {image_size}: need positive height and width')
  return EmbeddingNet(None, {}, 'depth', 'metric', 0, (h, w), (), 'none', 0)


IMAGE_SIZES = (16, 1024)  # pixels a side the frames may have without a network


def for_distance(model_dir: str, distance: str, image_size: int) -> EmbeddingNet:
  """The network an estimate with ``distance`` compares frames through.

  One rule for every command line: a trained run (``model_dir``) when one is
  named; otherwise the shape distance, which reads depth frames directly, gets
  ``no_network`` at ``image_size`` pixels a side, and any other distance is
  refused: it would embed frames with a network there is none of.

  Raises:
    ValueError: no ``model_dir`` for a distance that embeds, or an
      ``image_size`` outside ``IMAGE_SIZES``.
  """
  if model_dir:
    return load_embedding(model_dir)
  if distance != 'shape':
    raise ValueError(
      f'missing --model: --distance={distance} embeds frames with a trained '
      'network (--distance=shape needs none)'
    )
  lo, hi = IMAGE_SIZES
  if not lo <= image_size <= hi:
    raise ValueError(f'--image_size={image_size}: need {lo}-{hi} pixels a side')
  return no_network((image_size, image_size))


def resize_rgb(rgb: np.ndarray, size: tuple[int, int]) -> np.ndarray:
  """Nearest-neighbour resize of (..., H, W, 3), as ``dataset.resize_depth`` does depth."""
  chw = np.moveaxis(rgb, -1, -3)  # (..., 3, H, W)
  return np.moveaxis(dataset.resize_depth(chw, size), -3, -1)


def rgb_color(material: str) -> tuple[float, float, float]:
  """The colour (RGB in [0, 1]) a material's cloth is rendered in."""
  return physsim.FABRIC_COLORS.get(material, physsim.FABRIC_COLORS['default'])


def _recorded(run_dir: str) -> dict:
  path = os.path.join(run_dir, INPUTS_FILE)
  if not os.path.isfile(path):
    return {}
  try:
    with open(path) as f:
      return json.load(f)
  except (OSError, ValueError) as e:
    raise ValueError(f'{path}: cannot read JSON ({e})') from e


def input_mode(run_dir: str) -> str:
  """The input mode a run was trained with (``relative`` if unrecorded)."""
  return _recorded(run_dir).get('input_mode', 'relative')


def modality(run_dir: str) -> str:
  """The modality a run was trained on (``depth`` if unrecorded: older runs)."""
  return _recorded(run_dir).get('modality', 'depth')


def members(model_dir: str) -> list[str]:
  """The run folders a model names: one, or an ensemble's, comma-separated
  (a folder whose own name holds a comma is one run)."""
  if ',' in model_dir and os.path.isdir(model_dir):
    return [model_dir]
  dirs = [d.strip() for d in model_dir.split(',')]
  if not all(dirs):
    raise ValueError(f'{model_dir!r}: an empty run folder in the list')
  return dirs


def load_embedding(model_dir: str) -> EmbeddingNet:
  """Loads any trained run (PhySNet or SDN, depth or RGB), or an ensemble of
  runs of one architecture (``'a,b,c'``), its parameters on one device
  (``physsim.devices.place``): a data-parallel training's checkpoint restores
  them replicated over its devices, which would spread every inference
  program over all of them. Programs that split worlds over a mesh place them
  there themselves.

  Raises:
    ValueError: not a trained run, an unknown modality, or ensemble members
      that see or compute differently, naming the run folder.
  """
  dirs = members(model_dir)
  nets = [_load_one(d) for d in dirs]
  if len(nets) == 1:
    return nets[0]
  first = nets[0]
  for d, n in zip(dirs[1:], nets[1:], strict=True):
    for field in (
      'modality',
      'input_mode',
      'clip_frames',
      'image_size',
      'architecture',
    ):
      if getattr(n, field) != getattr(first, field):
        raise ValueError(
          f'{d}: an ensemble member with {field} {getattr(n, field)!r}, but '
          f'{dirs[0]} has {getattr(first, field)!r}; members must share it'
        )
  params = jax.tree.map(lambda *a: jax.numpy.stack(a), *(n.params for n in nets))
  # The fabrics every member saw (none recorded by one of them: unchecked).
  materials = tuple(sorted(set.intersection(*(set(n.materials) for n in nets))))
  return first._replace(params=params, materials=materials, members=len(nets))


def _load_one(model_dir: str) -> EmbeddingNet:
  mod = modality(model_dir)
  if mod not in MODALITIES:
    raise ValueError(
      f'{model_dir}/{INPUTS_FILE}: modality {mod!r} is none of {MODALITIES}'
    )
  network, params, cfg = model_lib.load_network(model_dir)
  params = physsim.devices.place(params, None)
  sdn = cfg.network == 'sdn'
  trunk = cfg.sdn.trunk if sdn else cfg.physnet
  return EmbeddingNet(
    network,
    params,
    mod,
    input_mode(model_dir),
    cfg.sdn.num_frames if sdn else 0,
    tuple(trunk.image_size),
    tuple(_recorded(model_dir).get('materials', ())),
    repr((cfg.network, cfg.sdn if sdn else cfg.physnet)),
  )


def network_inputs(frames, modality: str, input_mode: str = 'relative') -> jax.Array:
  """Frames to network inputs, as training makes them.

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
  raise ValueError(f'modality must be one of {MODALITIES}, got {modality!r}')


def embed_video(network, params, inputs, clip_frames: int = 0) -> jax.Array:
  """Embeds videos frame by frame (PhySNet) or clip by clip (SDN).

  Args:
    network: a ``model.Network``.
    params: its params.
    inputs: (S, T, H, W, ch) network inputs of S videos.
    clip_frames: 0: every frame is one point; else every non-overlapping clip
      of this many frames is one point (the last ``T % clip_frames`` frames
      are dropped, as training clips sequences).

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


def embed_videos(
  network, params, inputs, clip_frames: int = 0, members: int = 0
) -> jax.Array:
  """``embed_video`` for one network or an ensemble: (S, N, D) points of S
  videos, or with ``members`` = K (params stacked on a leading axis of K)
  (K, S, N, D), each in its member's space. Pass an ``EmbeddingNet``'s
  ``network``, ``params``, ``clip_frames`` and ``members``."""

  def one(p):
    return embed_video(network, p, inputs, clip_frames)

  return jax.vmap(one)(params) if members else one(params)


def video_distance(net: EmbeddingNet, points, rec_points, kind: str) -> jax.Array:
  """The PSD (``model.psd.psd`` of ``kind``) of one video's points to the
  recording's: (N, D) and (M, D) for one network; for an ensemble (K, N, D)
  and (K, M, D), each member's PSD in its own space, combined by their
  geometric mean. Returns ()."""
  if not net.members:
    return model_lib.psd.psd(points, rec_points, kind)
  d = jax.vmap(lambda a, b: model_lib.psd.psd(a, b, kind))(points, rec_points)
  return model_lib.psd.geometric_mean(d)


def network_retrieval(model_dir: str) -> dict[str, float] | None:
  """How well the network tells each parameter apart between held-out
  simulations: its logged parameter retrieval (``model.retrieval``) at the
  epoch it ships, over chance (1: the PSD does not constrain that parameter,
  so neither can the estimate). None for runs that did not log it. For an
  ensemble, its members' mean (None unless every member logged it): a guide,
  not the ensemble's own retrieval, which nobody measured.
  """
  if not model_dir:  # no network (the shape distance)
    return None
  out = []
  for d in members(model_dir):
    r = model_lib.selected_eval(model_lib.read_evals(d)).get('test_retrieval')
    if not r:
      return None
    out.append(model_lib.retrieval.vs_chance(r))
  return {k: float(np.mean([o[k] for o in out])) for k in out[0]}


# What a run's seeds and bookkeeping change: not part of how it was made.
_NOT_RECIPE = {
  'training': ('seed', 'log_every', 'max_to_keep', 'eval_batch_size'),
  'data': ('seed', 'backend', 'batch_size', 'batching'),
}


def network_accuracy(model_dir: str) -> float | None:
  """A trained run's held-out triplet accuracy at its selected epoch (None if
  it was not evaluated on held-out simulations); for an ensemble, its
  weakest member's (what a calibration of single networks compares); None
  without a network (``model_dir`` empty)."""
  if not model_dir:
    return None
  accs = [
    model_lib.selected_eval(model_lib.read_evals(d)).get('test_triplet_accuracy')
    for d in members(model_dir)
  ]
  return None if None in accs else min(accs)


def network_recipe(model_dir: str) -> dict | None:
  """How a trained run was made, apart from its seeds: its training config
  (``config.json``), what it saw (modality, input mode, fabrics) and the
  config of the simulations it was trained on (their ``dataset.json``, with
  the pose ranges; None where that folder is gone). Two networks of one
  recipe differ only by chance, which a calibration over several of them
  measures (``experiments.studies.calibration``). An ensemble's recipe is its
  first member's with an ``'ensemble'`` part: how many members, and which
  fields of the others' recipes differ from the first's (a calibration of
  single networks has no such part, so it does not match an ensemble).
  None without a network (``model_dir`` empty).

  Raises:
    ValueError: not a trained run, naming ``model_dir``.
  """
  if not model_dir:
    return None
  dirs = members(model_dir)
  recipe = _recipe(dirs[0])
  if len(dirs) > 1:
    differ = sorted(
      {f for d in dirs[1:] for f in recipe_differences(recipe, _recipe(d))}
    )
    recipe['ensemble'] = {'members': len(dirs), 'differ': differ}
  return recipe


def _recipe(model_dir: str) -> dict:
  path = os.path.join(model_dir, model_lib.train.CONFIG_FILE)
  if not os.path.isfile(path):
    raise ValueError(
      f'{model_dir}: not a trained run (no {model_lib.train.CONFIG_FILE})'
    )
  training = model_lib.config_io.read_json(path)
  rec = _recorded(model_dir)
  data = None
  info_path = os.path.join(rec.get('dataset', ''), 'dataset.json')
  if rec.get('dataset') and os.path.isfile(info_path):
    info = dataset.read_json(info_path)
    data = {**info.get('config', {}), 'pose_ranges': info.get('pose_ranges')}
    data = {k: v for k, v in data.items() if k not in _NOT_RECIPE['data']}
  return {
    'training': {k: v for k, v in training.items() if k not in _NOT_RECIPE['training']},
    'inputs': {k: rec.get(k) for k in ('modality', 'input_mode', 'materials')},
    'data': data,
  }


def recipe_differences(mine: dict, theirs: dict) -> list[str]:
  """Where two ``network_recipe`` s differ, as ``'part.field'`` names (a part
  that one of them lacks: ``'part'``); [] for one recipe."""
  out = []
  for part in sorted(set(mine) | set(theirs)):
    a, b = mine.get(part), theirs.get(part)
    if a is None or b is None:
      if a != b:
        out.append(part)
      continue
    out += [f'{part}.{k}' for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
  return out
