"""Tests of the demo's settings and its command line (the run itself is
README's first command: minutes, too long for a unit test)."""

from __future__ import annotations

import pytest

from experiments.pipeline import demo
from experiments.pipeline import training as train_lib


def test_recording_differs_from_training_like_reality_and_search_matches_training():
  data, rec, training, est = demo.configs('black_denim', 8, 3, 'c')
  assert data.materials == rec.materials == ('black_denim',)
  assert est.simulation.material == 'black_denim'
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
  assert (est.simulation.cloth_resolution, est.simulation.frames) == (
    data.cloth_resolution,
    data.frames,
  )
  assert est.seed == 3 and rec.seed != data.seed
  assert training.fit.epochs <= train_lib.PRESETS['paper'].fit.epochs
  # On the C backend the training set comes in several batches (a bar with
  # progress); MJX takes it in one.
  many = demo.configs('black_denim', 24, 3, 'c')[0]
  assert many.batch_size < many.sequences
  assert demo.configs('black_denim', 24, 3, 'mjx')[0].batch_size == 24
  # The network's seeds are their own: the study's seed changes the
  # recording and the search, not the network; network_seed the network.
  other = demo.configs('black_denim', 8, 4, 'c')
  assert (other[0], other[2]) == (data, training) and other[1].seed != rec.seed
  d1, r1, t1, e1 = demo.configs('black_denim', 8, 3, 'c', network_seed=1)
  assert d1.seed != data.seed and t1.fit.seed != training.fit.seed
  assert (r1, e1) == (rec, est)


def test_command_line_takes_the_demo_settings():
  from experiments import demo as script
  from experiments.pipeline import cli

  args = cli.parse(script.Args, {'default': script.Args()}, ['demo', '--seed=4'])
  assert (args.seed, args.material, args.workdir) == (4, 'gray_interlock', 'out/demo')
  with pytest.raises(Exception, match='backend'):
    cli.parse(script.Args, {'default': script.Args()}, ['demo', '--backend=cuda'])
