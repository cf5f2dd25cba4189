"""A tiny RGB + depth dataset shared by the experiments tests (MuJoCo C backend)."""

import dataclasses
import json
import os
import shutil

import pytest

from experiments.pipeline import datasets as gd
from physsim import dataset

# One material, four simulations (two held out by a 0.5 simulation split).
TINY = dataclasses.replace(
  gd.PRESETS['smoke'],
  materials=('gray_interlock',),
  sequences=4,
  frames=4,
  cameras=2,
  resolution=32,
  cloth_resolution=8,
  backend='c',
  workers=1,
  rgb=True,
)


@pytest.fixture(scope='session')
def rgb_dataset(tmp_path_factory):
  """Root of a dataset with depth and RGB frames."""
  root = str(tmp_path_factory.mktemp('data') / 'rgb')
  gd.run(TINY, root)
  return root


@pytest.fixture(scope='session')
def depth_only_dataset(rgb_dataset, tmp_path_factory):
  """The same dataset as a depth-only one (colour frames gone, ``has_rgb`` false)."""
  root = str(tmp_path_factory.mktemp('data') / 'depth_only')
  shutil.copytree(rgb_dataset, root)
  for seq in dataset.finished_sequences(root):
    path = os.path.join(seq, 'meta.json')
    with open(path) as f:
      meta = json.load(f)
    meta['has_rgb'] = False
    with open(path, 'w') as f:
      json.dump(meta, f)
    for cam in range(meta['n_cameras']):
      folder = os.path.join(seq, f'cam{cam}')
      for name in os.listdir(folder):
        if name.startswith('rgb_'):
          os.remove(os.path.join(folder, name))
  return root


@pytest.fixture(scope='session')
def table1_workdir(tmp_path_factory):
  """Workdir of experiments.table1; training_test trains two of its runs (reused there)."""
  return str(tmp_path_factory.mktemp('table1'))
