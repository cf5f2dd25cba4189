"""The main job on a small built-in default: an end-to-end estimate in minutes on a CPU.

1. simulate and render a small training set of one fabric (``generate_dataset``);
2. train a small PhySNet on it (``experiments.train``);
3. make one real-like recording with known parameters (finer mesh, sensor
   noise, 24 fps, an unseen camera pose, gustier wind: ``make_eval_set``'s
   settings, small);
4. estimate bending, wind and area weight from that recording alone
   (``estimation.estimate``) with the estimate's default, the sheet's shape
   (``--distance=shape``, no network), and print them beside the truth and
   beside the trivial guess (the centre of the search range);
5. estimate them again through the PhySNet of step 2 (the PSD between
   embeddings, ``--distance=energy``) and print both side by side: the
   default is the distance that reads more (README, BENCHMARKS.md).

Every stage resumes from what ``workdir`` already holds. ``experiments/demo.py``
is its command line.
"""

from __future__ import annotations

import dataclasses
import os
import time

import physsim
from experiments.pipeline import datasets as gen
from experiments.pipeline import estimation, report
from experiments.pipeline import recording as recording_lib
from experiments.pipeline import training as train_lib
from experiments.pipeline.objective import NETWORK_DISTANCE, EstimateConfig

_RES = 32  # image size
_FRAMES = 16  # at 20 Hz: 0.8 s clips
_CLOTH = 10  # vertices per side
IMAGE_SIZE = (_RES, _RES)


def configs(
  material: str, sequences: int, seed: int, backend: str, network_seed: int = 0
):
  """(training set, recording, training, estimate) configs of the demo.

  ``seed`` draws the recording and seeds the search; ``network_seed`` the
  training simulations and the network's training (the demo's network: 0).
  """
  data = dataclasses.replace(
    gen.PRESETS['paper'],
    materials=(material,),
    sequences=sequences,
    frames=_FRAMES,
    warmup=0.5,
    cameras=3,
    resolution=_RES,
    cloth_resolution=_CLOTH,
    backend=backend,
    # A few batches, so that the bar shows progress (MuJoCo C runs them at the
    # same speed per world; MJX pays a step per batch, still seconds).
    batch_size=8 if physsim.resolve_backend(backend) == 'c' else sequences,
    seed=network_seed,
  )
  recording = dataclasses.replace(
    gen.PRESETS['eval'],
    materials=(material,),
    sequences=1,
    batch_size=1,
    frames=20,  # 24 fps -> 16 frames at 20 Hz
    warmup=0.5,
    cloth_resolution=_CLOTH + 3,
    resolution=_RES,
    backend=backend,
    seed=1000 + seed,
  )
  training = train_lib.replace(
    train_lib.PRESETS['smoke'],
    conv_features=(16, 32),
    dense_features=(64,),
    epochs=10,
    lr_step_epochs=6,
    batch_size=32,
    seed=network_seed,
  )
  est = EstimateConfig.preset('demo', material=material, backend=backend, seed=seed)
  return data, recording, training, est


def run(workdir: str, material: str, sequences: int, seed: int, backend: str):
  """The demo's five stages (each resumes); returns the default estimate's
  result, with the network's under ``'physnet'``."""
  data_cfg, rec_cfg, train_cfg, est_cfg = configs(material, sequences, seed, backend)
  t0 = time.time()
  print('== 1/5 training set', flush=True)
  gen.run(data_cfg, os.path.join(workdir, 'data'))
  print('== 2/5 training PhySNet', flush=True)
  train_lib.run(
    train_cfg, os.path.join(workdir, 'data'), os.path.join(workdir, 'model')
  )
  print('== 3/5 a real-like recording', flush=True)
  rec_root = os.path.join(workdir, 'recording')
  gen.run(rec_cfg, rec_root)
  rec_dir = physsim.dataset.sequence_dir(rec_root, material, '0000')
  rec = recording_lib.load_recording(
    rec_dir, fps=est_cfg.simulation.fps, size=IMAGE_SIZE, frames=_FRAMES
  )
  print("== 4/5 estimate (the default: the sheet's shape, no network)", flush=True)
  result = estimation.estimate(est_cfg, rec, '', workdir + '/estimate')
  print(report.report_table(result))
  print('== 5/5 the same recording through the PhySNet of step 2', flush=True)
  physnet = estimation.estimate(
    est_cfg.replace(distance=NETWORK_DISTANCE), rec,
    os.path.join(workdir, 'model', material), workdir + '/estimate_physnet',
  )  # fmt: skip
  print(report.distances_table({'shape (default)': result, 'PhySNet PSD': physnet}))
  print(f'total {time.time() - t0:.0f} s; pictures in {workdir}/estimate')
  return {**result, 'physnet': physnet}
