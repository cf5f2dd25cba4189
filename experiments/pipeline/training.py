"""Training PhySNet (or SDN) per material on a dataset made by ``datasets.run``.

One network per material (the paper's setting) under ``<workdir>/<material>``,
or one for all materials (``all_materials``) under ``<workdir>/all``. Each
run folder holds the model's ``config.json``, orbax checkpoints, a
``metrics.jsonl`` log and ``inputs.json`` (the modality and how depth frames
were turned into inputs, which the estimate must repeat); an interrupted run
resumes and a finished one is not retrained.

Inputs: 'depth' frames go through ``model.depth_input`` (one channel); 'rgb'
frames (the dataset's ``rgb_*.png``) through ``model.rgb_input`` (three
channels in [0, 1]). Both are resized nearest-neighbour when ``image_size``
is set. PhySNet items are single frames, SDN items non-overlapping clips of
``sdn.num_frames`` frames of one camera.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import os

import numpy as np

import model as model_lib
from experiments.pipeline import cli, deadline
from experiments.pipeline.embedding import CHANNELS, INPUTS_FILE, MODALITIES, resize_rgb
from physsim import dataset
from physsim import params as params_lib


@dataclasses.dataclass(frozen=True)
class Config:
  """A training run over materials.

  The model's own configs are nested here, not copied: ``fit`` (optimisation,
  split, model selection), ``physnet`` (the architecture) and ``sdn``; what
  the data decide (input channels, image size) and what the run's network
  needs (which network, SDN's loss) is filled in by ``train_config``.

  Attributes:
    materials: fabric names; empty = every material in the dataset.
    all_materials: one network for all materials instead of one each.
    network: 'physnet' or 'sdn' (SDN trains with the contrastive loss).
    modality: 'depth' or 'rgb' frames (rgb needs a dataset made with --rgb).
    input_mode: depth -> input mapping (model.inputs.MODES; unused for rgb).
    image_size: train at this (square) size; 0 = the dataset's.
    fit: optimisation, split and model selection (model.TrainConfig; the
      paper's code: 30 epochs, lr 1e-3, batch 32, StepLR 8).
    physnet: the PhySNet architecture, or SDN's trunk (model.PhySNetConfig;
      the original: conv 32,64, dense 256,256, a 2-D embedding).
    sdn: SDN's clip length and frequency bins (model.SDNConfig).
  """

  materials: tuple[str, ...] = ()
  all_materials: bool = False
  network: str = cli.choice('physnet', model_lib.train.NETWORKS)
  modality: str = cli.choice('depth', MODALITIES)
  input_mode: str = cli.choice('relative', model_lib.inputs.MODES)
  image_size: int = 0
  fit: model_lib.TrainConfig = cli.nested(
    model_lib.TrainConfig(), skip=('network', 'physnet', 'sdn')
  )
  physnet: model_lib.PhySNetConfig = cli.nested(
    model_lib.PhySNetConfig(), skip=('in_channels', 'image_size')
  )
  sdn: model_lib.SDNConfig = cli.nested(
    model_lib.SDNConfig(num_frames=16, num_components=4), skip=('in_channels', 'trunk')
  )


PRESETS = {
  'paper': Config(),
  'smoke': Config(
    image_size=32,
    fit=model_lib.TrainConfig(epochs=3, lr_step_epochs=2, batch_size=16),
    physnet=model_lib.PhySNetConfig(conv_features=(8, 16), dense_features=(32,)),
    sdn=model_lib.SDNConfig(num_frames=4, num_components=2),
  ),
}


def _clips(depth_seq: np.ndarray, frames: int) -> np.ndarray:
  """(C, T, H, W, ...) -> (C * (T // frames), frames, H, W, ...) non-overlapping clips."""
  c, t = depth_seq.shape[:2]
  n = t // frames
  if n < 1:
    raise ValueError(f'sequences have {t} frames, fewer than a clip of {frames}')
  return depth_seq[:, : n * frames].reshape(c * n, frames, *depth_seq.shape[2:])


def _frames(config: Config, path: str) -> np.ndarray:
  """One sequence's network inputs, (C, T, H, W, channels) float32."""
  size = (config.image_size,) * 2 if config.image_size else None
  seq = dataset.read_sequence(path, rgb=config.modality == 'rgb')
  if config.modality == 'depth':
    d = dataset.resize_depth(seq.depth, size) if size else seq.depth
    return np.asarray(model_lib.depth_input(d, config.input_mode))
  if seq.rgb is None:
    raise ValueError(
      f'{path}: modality=rgb but the sequence has no RGB frames (cam*/rgb_*.png); '
      'generate the dataset with --rgb'
    )
  rgb = resize_rgb(seq.rgb, size) if size else seq.rgb
  return np.asarray(model_lib.rgb_input(rgb))


def check_config(config: Config) -> None:
  """Raises ValueError on a field outside its allowed values."""
  for name, allowed in (
    ('modality', MODALITIES),
    ('network', model_lib.train.NETWORKS),
    ('input_mode', model_lib.inputs.MODES),
  ):
    if getattr(config, name) not in allowed:
      raise ValueError(
        f'Config.{name} must be one of {allowed}, got {getattr(config, name)!r}'
      )


def load_inputs(config: Config, root: str, materials, *, workers: int = 0) -> tuple:
  """Network inputs of ``materials`` from the dataset at ``root``.

  Sequences are read by a pool of threads (PNG decoding releases the GIL): on
  the GPU machines one core decoding a fabric's frames left the GPU idle.

  Args:
    config: run config (network, modality, input_mode, image_size, sdn).
    root: dataset root.
    materials: material names.
    workers: reader threads (0: one per core, at most 16); the result does not
      depend on it.

  Returns:
    (inputs, labels, groups): inputs ``(N, H, W, ch)`` float32 frames ordered by
    sequence, camera, frame (PhySNet) or ``(N, sdn.num_frames, H, W, ch)`` clips
    (SDN), ``ch`` = 1 for depth, 3 for rgb; labels ``(N,)`` int64; groups =
    labels (a simulation is held out whole).

  Raises:
    ValueError: a material without valid sequences, rgb asked of a dataset
      without colour frames, or a bad file (named).
  """
  check_config(config)
  index = dataset.open_dataset(root)
  rows = []
  for m in materials:
    found = index.filter(material=m, valid=True).rows
    if not found:
      raise ValueError(
        f'{root}: no valid sequences of material {m!r} '
        f'(materials: {list(index.materials)})'
      )
    rows += found

  def items(r):
    x = _frames(config, index.path(r))  # (C, T, H, W, ch)
    if config.network == 'physnet':
      return x.reshape(-1, *x.shape[2:])
    return _clips(x, config.sdn.num_frames)

  workers = workers or min(16, os.cpu_count() or 1)
  with concurrent.futures.ThreadPoolExecutor(workers) as pool:
    xs = list(pool.map(items, rows))  # in order; re-raises the first error
  labels = [
    np.full(len(x), r['label'], np.int64) for x, r in zip(xs, rows, strict=True)
  ]
  shapes = {x.shape[1:] for x in xs}
  if len(shapes) > 1:
    raise ValueError(
      f'{root}: sequences of {list(materials)} differ in frame size {shapes}; '
      'set image_size'
    )
  x, y = np.concatenate(xs), np.concatenate(labels)
  return x, y, y


def video_info(config: Config, root: str, materials) -> model_lib.Videos:
  """Clip id, camera and true parameters of each item ``load_inputs`` returns.

  Read from the dataset index alone (no frames): items come in the same order,
  sequence by sequence, camera by camera. A clip is one sequence seen by one
  camera; the parameters are ``physsim.params.FIELDS`` (bending scale, wind
  speed, area weight).
  """
  index = dataset.open_dataset(root)
  video, camera, params = [], [], []
  clips = 0  # clips so far: the next clip's id
  for m in materials:
    for r in index.filter(material=m, valid=True).rows:
      c, t = r['n_cameras'], r['n_frames']
      per_camera = t if config.network == 'physnet' else t // config.sdn.num_frames
      cams = np.repeat(np.arange(c), per_camera)
      video.append(clips + cams)
      camera.append(cams)
      clips += c
      params.append(np.tile([r[f] for f in params_lib.FIELDS], (c * per_camera, 1)))
  if not video:
    raise ValueError(f'{root}: no valid sequences of {list(materials)}')
  return model_lib.Videos(
    np.concatenate(video),
    np.concatenate(camera),
    np.concatenate(params).astype(np.float64),
    tuple(params_lib.FIELDS),
  )


def replace(config: Config, **fields) -> Config:
  """``config`` with fields replaced wherever they live: its own first, then
  those of its nested ``fit``, ``physnet`` or ``sdn`` config (a name of the
  run's own, e.g. ``image_size``, is never the nested one's)."""
  own = {k: v for k, v in fields.items() if k in Config.__dataclass_fields__}
  for name in ('fit', 'physnet', 'sdn'):
    sub = getattr(config, name)
    mine = {
      k: v for k, v in fields.items()
      if k in type(sub).__dataclass_fields__ and k not in own
    }  # fmt: skip
    if mine:
      own[name] = dataclasses.replace(sub, **mine)
  unknown = set(fields) - set(own) - {
    k for n in ('fit', 'physnet', 'sdn')
    for k in type(getattr(config, n)).__dataclass_fields__
  }  # fmt: skip
  if unknown:
    raise ValueError(f'no training setting named {sorted(unknown)}')
  return dataclasses.replace(config, **own)


def train_config(config: Config, image_size) -> model_lib.TrainConfig:
  """The ``model.TrainConfig`` of a run at ``image_size`` (H, W): ``config.fit``
  with the network, its architecture and (for SDN) the contrastive loss."""
  check_config(config)
  channels = CHANNELS[config.modality]
  trunk = dataclasses.replace(
    config.physnet, in_channels=channels, image_size=tuple(image_size)
  )
  if config.network == 'physnet':
    return dataclasses.replace(config.fit, network='physnet', physnet=trunk)
  sdn = dataclasses.replace(config.sdn, in_channels=channels, trunk=trunk)
  return dataclasses.replace(config.fit, network='sdn', sdn=sdn, loss='contrastive')


def _inputs_record(config: Config, root: str, materials) -> dict:
  return {
    'modality': config.modality,
    'input_mode': config.input_mode,
    'materials': list(materials),
    'dataset': root,
  }


def finished_eval(config: Config, root: str, run_dir: str, materials) -> dict | None:
  """The selected eval row (``model.selected_eval``) of a finished run of
  this config, else None.

  A run is finished when ``metrics.jsonl`` holds an eval row of epoch
  ``config.fit.epochs`` (or later), or it stopped early, and its ``inputs.json`` and ``config.json``
  match this config (the image size is taken from ``config.json``, as only the
  data decides it). Lets callers skip loading data for finished runs.

  Args:
    config: run config.
    root: dataset root.
    run_dir: the run folder.
    materials: the run's materials.

  Returns:
    The eval row dict, or None if the run is missing, unfinished or differs.
  """
  paths = [
    os.path.join(run_dir, f)
    for f in (INPUTS_FILE, model_lib.train.CONFIG_FILE, model_lib.train.METRICS_FILE)
  ]
  if not all(os.path.isfile(p) for p in paths):
    return None
  with open(paths[0]) as f:
    if json.load(f) != _inputs_record(config, root, materials):
      return None
  saved = model_lib.config_io.from_dict(
    model_lib.TrainConfig, model_lib.config_io.read_json(paths[1]), paths[1]
  )
  trunk = saved.physnet if saved.network == 'physnet' else saved.sdn.trunk
  want = train_config(config, trunk.image_size)
  # Fields a resume may change (model.train's) do not make it another run.
  free = {k: getattr(saved, k) for k in model_lib.train.RESUMABLE_FIELDS}
  if dataclasses.replace(want, **free) != saved:
    return None
  evals = model_lib.read_evals(run_dir)
  if not model_lib.ended(evals, config.fit.epochs, config.fit.patience):
    return None
  return model_lib.selected_eval(evals)


def fit_run(
  config: Config,
  root: str,
  run_dir: str,
  materials,
  data,
  *,
  progress: bool = True,
  max_to_keep: int | None = model_lib.TrainConfig.max_to_keep,
) -> tuple[model_lib.FitResult, dict]:
  """Trains (or resumes, or just restores) one run on ``data`` from ``load_inputs``.

  Args:
    config: run config.
    root: dataset root (recorded in ``inputs.json``).
    run_dir: the run folder.
    materials: the run's materials (recorded).
    data: (inputs, labels, groups).
    progress: show a tqdm bar.
    max_to_keep: checkpoints kept (None: every epoch's, for studies of epochs).

  Returns:
    (the ``model.fit`` result, its selected eval row (``model.selected_eval``:
    the best validation epoch's, else the last) or {}).
  """
  x, y, g = data
  os.makedirs(run_dir, exist_ok=True)
  dataset.write_json_atomic(
    os.path.join(run_dir, INPUTS_FILE), _inputs_record(config, root, materials)
  )
  tc = dataclasses.replace(
    train_config(config, x.shape[-3:-1]), max_to_keep=max_to_keep
  )
  videos = video_info(config, root, materials)
  if len(videos.video) != len(x):
    raise ValueError(
      f'{root}: the index lists {len(videos.video)} items of {list(materials)} '
      f'but {len(x)} were loaded (was a sequence rewritten?)'
    )
  result = model_lib.fit(
    x, y, g, tc, run_dir, progress=progress, videos=videos,
    after_epoch=lambda s: deadline.check(s, f'the next epoch of {run_dir}'),
  )  # fmt: skip
  return result, model_lib.selected_eval(result.history)


def run(config: Config, root: str, workdir: str, *, progress: bool = True) -> dict:
  """Trains every requested network; returns ``{run name: selected eval row}``."""
  check_config(config)
  index = dataset.open_dataset(root)
  materials = config.materials or index.materials
  groups = (
    [('all', materials)] if config.all_materials else [(m, [m]) for m in materials]
  )
  out = {}
  for name, mats in groups:
    x, y, g = load_inputs(config, root, mats)
    print(f'{name}: {len(x)} inputs of shape {x.shape[1:]}, {len(set(y))} labels')
    run_dir = os.path.join(workdir, name)
    _, out[name] = fit_run(config, root, run_dir, mats, (x, y, g), progress=progress)
    print(f'{name}: {describe_eval(out[name])}')
    if warning := weak_network_warning(out[name]):
      print(f'{name}: {warning}')
  return out


# Held-out triplet accuracy below which a network is called barely trained:
# chance is 50%; the demo's and the paper's recipes gave 71-88% in our studies
# (BENCHMARKS.md), and one failed run 58%.
WEAK_ACCURACY = 0.6


def weak_network_warning(row: dict) -> str | None:
  """A warning for a selected eval row whose held-out triplet accuracy is
  below ``WEAK_ACCURACY``: such a network hardly tells simulations apart, so
  estimates with it say little beyond the prior (their intervals were not
  checked for it). None otherwise or when not evaluated."""
  acc = (row or {}).get('test_triplet_accuracy')
  if acc is None or acc >= WEAK_ACCURACY:
    return None
  return (
    f'warning: held-out triplet accuracy {100 * acc:.1f}% is close to chance (50%); '
    'estimates with this network will say little beyond the prior. Train on more '
    'sequences or for more epochs, or estimate with --distance=shape where the '
    "camera's place in the simulator's world is known"
  )


def describe_eval(row: dict) -> str:
  """A selected eval row in one line: epoch, held-out triplet accuracy and,
  when logged, each parameter's retrieval over chance (``model.retrieval``)."""
  if not row:
    return 'not evaluated'
  parts = [f'epoch {row["epoch"]}']
  if (acc := row.get('test_triplet_accuracy')) is not None:
    parts.append(f'held-out triplet accuracy {100 * acc:.1f}%')
  if r := row.get('test_retrieval'):
    parts.append(
      'retrieval over chance '
      + model_lib.retrieval.describe(model_lib.retrieval.vs_chance(r))
    )
  return '; '.join(parts)


def choose_lr(
  config: Config, root: str, workdir: str, candidates, *, progress: bool = True
) -> dict:
  """Picks the learning rate per material by validation (``model.select_lr``).

  Only the training portion of the simulation split is used: the held-out
  simulations that ``run`` tests on stay unseen. Writes
  ``<workdir>/<material>/lr_selection.json``.

  Returns:
    ``{material: {'best': lr, 'validation_triplet_accuracy': {lr: acc}}}``.
  """
  check_config(config)
  index = dataset.open_dataset(root)
  out = {}
  for m in config.materials or index.materials:
    x, y, g = load_inputs(config, root, [m])
    fit = dataclasses.replace(config.fit, split='simulation')
    tc = train_config(dataclasses.replace(config, fit=fit), x.shape[-3:-1])
    train_idx, _ = model_lib.split_indices(tc, y, g)
    best, scores = model_lib.select_lr(
      x[train_idx], y[train_idx], g[train_idx], tc, os.path.join(workdir, m),
      candidates, progress=progress,
    )  # fmt: skip
    out[m] = {
      'best': best,
      'validation_triplet_accuracy': {f'{k:g}': v for k, v in scores.items()},
    }
    dataset.write_json_atomic(os.path.join(workdir, m, 'lr_selection.json'), out[m])
    print(f'{m}: {json.dumps(out[m])}', flush=True)
  return out
