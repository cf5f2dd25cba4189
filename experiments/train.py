"""Train PhySNet (or SDN) per material on a dataset made by ``generate_dataset``.

  python -m experiments.train --dataset=data/sim --workdir=out/train
  python -m experiments.train --dataset=/tmp/ds --workdir=/tmp/tr --preset=smoke

One network per material (the paper's setting) under ``<workdir>/<material>``,
or one for all materials (``--all_materials``) under ``<workdir>/all``. Each
run folder holds the model's ``config.json``, orbax checkpoints, a
``metrics.jsonl`` log and ``inputs.json`` (how depth frames were turned into
inputs, which the estimate must repeat); an interrupted run resumes.
"""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
from absl import app, flags, logging

import model as model_lib
from physsim import dataset

INPUTS_FILE = 'inputs.json'


@dataclasses.dataclass(frozen=True)
class Config:
  """A training run over materials.

  Attributes:
    materials: fabric names; empty = every material in the dataset.
    all_materials: one network for all materials instead of one each.
    network: 'physnet' or 'sdn'.
    input_mode: depth -> input mapping (``model.inputs.MODES``).
    image_size: train at this (square) size; 0 = the dataset's.
    conv_features, dense_features: PhySNet widths (the original: 32,64 / 256,256).
    epochs, learning_rate, batch_size, lr_step_epochs: optimisation (the paper's
      code: 30, 1e-3, 32, 8).
    split: 'simulation' (held-out sequences) or 'random' (the paper's per image).
    test_fraction: held-out share.
    seed: the only seed.
    sdn_frames, sdn_components: SDN clip length and kept frequency bins.
  """

  materials: tuple[str, ...] = ()
  all_materials: bool = False
  network: str = 'physnet'
  input_mode: str = 'relative'
  image_size: int = 0
  conv_features: tuple[int, ...] = (32, 64)
  dense_features: tuple[int, ...] = (256, 256)
  epochs: int = 30
  learning_rate: float = 1e-3
  batch_size: int = 32
  lr_step_epochs: int = 8
  split: str = 'simulation'
  test_fraction: float = 0.2
  seed: int = 0
  sdn_frames: int = 16
  sdn_components: int = 4


PRESETS = {
  'paper': Config(),
  'smoke': Config(
    image_size=32,
    conv_features=(8, 16),
    dense_features=(32,),
    epochs=3,
    lr_step_epochs=2,
    batch_size=16,
    sdn_frames=4,
    sdn_components=2,
  ),
}


def _clips(depth_seq: np.ndarray, frames: int) -> np.ndarray:
  """(C, T, H, W) -> (C * (T // frames), frames, H, W) non-overlapping clips."""
  c, t = depth_seq.shape[:2]
  n = t // frames
  if n < 1:
    raise ValueError(f'sequences have {t} frames, fewer than a clip of {frames}')
  return depth_seq[:, : n * frames].reshape(c * n, frames, *depth_seq.shape[2:])


def load_inputs(config: Config, root: str, materials) -> tuple:
  """(inputs, labels, groups) for ``materials`` from the dataset at ``root``."""
  size = (config.image_size,) * 2 if config.image_size else None
  xs, labels = [], []
  for m in materials:
    if config.network == 'physnet':
      arr = dataset.load_training_arrays(root, m, size=size)
      xs.append(np.asarray(model_lib.depth_input(arr.images, config.input_mode)))
      labels.append(arr.labels)
      continue
    index = dataset.open_dataset(root)
    for r in index.filter(material=m, valid=True).rows:
      d = dataset.read_sequence(index.path(r)).depth
      d = dataset.resize_depth(d, size) if size else d
      clips = _clips(d, config.sdn_frames)  # (N, T, H, W)
      xs.append(np.asarray(model_lib.depth_input(clips, config.input_mode)))
      labels.append(np.full(len(clips), r['label'], np.int64))
  x, y = np.concatenate(xs), np.concatenate(labels)
  return x, y, y  # group = label: a simulation is held out whole


def train_config(config: Config, image_size) -> model_lib.TrainConfig:
  trunk = model_lib.PhySNetConfig(
    image_size=tuple(image_size),
    conv_features=config.conv_features,
    dense_features=config.dense_features,
  )
  common = dict(
    learning_rate=config.learning_rate,
    epochs=config.epochs,
    batch_size=config.batch_size,
    lr_step_epochs=config.lr_step_epochs,
    split=config.split,
    test_fraction=config.test_fraction,
    seed=config.seed,
  )
  if config.network == 'physnet':
    return model_lib.TrainConfig(network='physnet', physnet=trunk, **common)
  sdn = model_lib.SDNConfig(
    num_frames=config.sdn_frames, num_components=config.sdn_components, trunk=trunk
  )
  return model_lib.TrainConfig(network='sdn', sdn=sdn, loss='contrastive', **common)


def run(config: Config, root: str, workdir: str, *, progress: bool = True) -> dict:
  """Trains every requested network; returns ``{run name: last eval row}``."""
  index = dataset.open_dataset(root)
  materials = config.materials or index.materials
  groups = (
    [('all', materials)] if config.all_materials else [(m, [m]) for m in materials]
  )
  out = {}
  for name, mats in groups:
    x, y, g = load_inputs(config, root, mats)
    image_size = x.shape[-3:-1]
    run_dir = os.path.join(workdir, name)
    os.makedirs(run_dir, exist_ok=True)
    dataset.write_json_atomic(
      os.path.join(run_dir, INPUTS_FILE),
      {'input_mode': config.input_mode, 'materials': list(mats), 'dataset': root},
    )
    print(f'{name}: {len(x)} inputs of shape {x.shape[1:]}, {len(set(y))} labels')
    result = model_lib.fit(x, y, g, train_config(config, image_size), run_dir,
                           progress=progress)  # fmt: skip
    evals = [r for r in result.history if r.get('eval')]
    out[name] = evals[-1] if evals else {}
    print(f'{name}: {json.dumps(out[name])}')
  return out


def input_mode(run_dir: str) -> str:
  """The input mode a run was trained with (``relative`` if unrecorded)."""
  path = os.path.join(run_dir, INPUTS_FILE)
  if not os.path.isfile(path):
    return 'relative'
  with open(path) as f:
    return json.load(f)['input_mode']


FLAGS = flags.FLAGS


def define_flags() -> None:
  if 'dataset' in FLAGS:
    return
  flags.DEFINE_string('dataset', None, 'dataset root (generate_dataset --out)')
  flags.DEFINE_string('workdir', 'out/train', 'run folders go here')
  flags.DEFINE_enum('preset', 'paper', list(PRESETS), 'base config')
  flags.DEFINE_list('materials', None, 'materials (default: all in the dataset)')
  flags.DEFINE_bool('all_materials', None, 'one network for all materials')
  flags.DEFINE_enum('network', None, ['physnet', 'sdn'], 'which network')
  flags.DEFINE_integer('epochs', None, 'epochs')
  flags.DEFINE_float('learning_rate', None, 'Adam learning rate')
  flags.DEFINE_enum('split', None, ['simulation', 'random'], 'held-out split')
  flags.DEFINE_integer('image_size', None, 'train at this size (0: dataset)')
  flags.DEFINE_integer('seed', None, 'seed')


def main(argv):
  del argv
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  over = {
    k: getattr(FLAGS, k)
    for k in (
      'materials',
      'all_materials',
      'network',
      'epochs',
      'learning_rate',
      'split',
      'image_size',
      'seed',
    )
    if getattr(FLAGS, k) is not None
  }
  if 'materials' in over:
    over['materials'] = tuple(over['materials'])
  config = dataclasses.replace(PRESETS[FLAGS.preset], **over)
  run(config, FLAGS.dataset, FLAGS.workdir)


if __name__ == '__main__':
  define_flags()
  flags.mark_flags_as_required(['dataset'])
  app.run(main)
