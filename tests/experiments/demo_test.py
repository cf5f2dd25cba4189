"""Tests for experiments.demo's settings (the run itself is README's first
command: two minutes, too long for a unit test)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from experiments import demo
from experiments import generate_dataset as gen
from experiments import train as train_lib


def test_import_beside_another_scripts_flags():
  # The demo defines its flags only as a script, so a user's script (or a
  # test) that already defined generate_dataset's --sequences can import it.
  gen.define_flags()
  assert demo.run is not None


def test_recording_differs_from_training_like_reality_and_search_matches_training():
  data, rec, training, est = demo.configs('black_denim', 8, 3, 'c')
  assert data.materials == rec.materials == ('black_denim',)
  assert est.material == 'black_denim'
  # Real-like: a finer mesh, the sensor model, unseen poses, 24 fps, gustier
  # wind, framing checked; the same frame size.
  assert rec.cloth_resolution > data.cloth_resolution
  assert rec.noise and not data.noise
  assert (rec.poses, data.poses) == ('evaluation', 'train')
  assert rec.fps == 24 and data.fps == 20
  assert rec.gust_intensity > data.gust_intensity
  assert rec.min_coverage > 0
  assert rec.resolution == data.resolution
  # The search simulates what the network was trained on.
  assert (est.cloth_resolution, est.frames) == (data.cloth_resolution, data.frames)
  assert est.seed == 3 and rec.seed != data.seed
  assert training.epochs <= train_lib.PRESETS['paper'].epochs


@pytest.mark.parametrize('script', ['retrieval_ablation.py', 'selection_study.py'])
def test_scripts_built_on_the_demo_have_its_flags(script):
  # These benchmarks take --workdir, --material, --sequences and --backend
  # from the demo, which defines them only on request.
  root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
  out = subprocess.run(
    [sys.executable, os.path.join(root, 'benchmarks', script), '--helpfull'],
    capture_output=True,
    text=True,
    cwd=root,
    timeout=300,
  )
  text = out.stdout + out.stderr  # absl's --helpfull prints usage and exits 1
  assert 'Traceback' not in text, text[-2000:]
  for flag in ('--workdir', '--material', '--sequences', '--backend', '--epochs'):
    assert f'{flag}:' in text, flag
