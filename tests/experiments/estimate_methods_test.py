"""Tests for the estimate's four methods: PhySNet / SDN on depth / RGB frames.

The networks are untrained tiny ones (``estimate_fixtures.write_random_model``)
and the recording the fixtures' simulated one with colour frames: these tests
check that each method runs end to end and that SDN clips and RGB inputs are
made as in training, not what an untrained network recovers.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import model as model_lib
import physsim
from experiments.pipeline import embedding, estimation
from experiments.pipeline import objective as obj_lib
from experiments.pipeline import recording as recording_lib
from experiments.pipeline import training as train
from physsim import dataset
from tests.experiments.estimate_fixtures import (
  CLIP_FRAMES,
  CONFIG,
  SIZE,
  TRUTH,
  load,
  write_random_model,
  write_recording,
)

pytestmark = pytest.mark.slow  # whole searches per method

# The initial design only: every stage runs (simulate, render, embed, PSD, GP
# posterior, figures) without compiling the BO proposal step.
_SHORT = CONFIG.replace(max_iter=0, min_iter=0)
# Embedding clips in one batch or one by one: the same float32 program up to
# XLA's batch-dependent summation order.
_CLIP_TOLERANCE = 1e-5
# rgb_input is uint8 / 255 on both paths: bit-exact.
_RGB_INPUT_TOLERANCE = 0.0
# uint8 levels by which tinted white shading (datasets and estimate) may differ
# from shading in the fabric colour (one float32 rounding before x255).
_SHADE_LEVELS = 1
# The fixture recording is rendered by the estimate's own RGB renderer at the
# truth, so the truth's PSD vanishes up to float32 embedding noise.
_TRUTH_RGB_PSD_TOLERANCE = 1e-6
MATERIAL = 'gray_interlock'


@pytest.fixture(scope='module')
def env(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('methods'))
  seq = write_recording(root, TRUTH, rgb=True)
  models = {
    (net, mod): write_random_model(os.path.join(root, f'{net}_{mod}'), net, mod)
    for net in ('physnet', 'sdn')
    for mod in ('depth', 'rgb')
  }
  return dict(root=root, seq=seq, rec=load(seq, rgb=True), models=models)


@pytest.mark.parametrize(
  'method', [('physnet', 'rgb'), ('sdn', 'depth'), ('sdn', 'rgb')], ids='_'.join
)
def test_method_runs_end_to_end(env, method):
  workdir = os.path.join(env['root'], 'run_' + '_'.join(method))
  result = estimation.estimate(
    _SHORT, env['rec'], env['models'][method], workdir, progress=False
  )
  assert (
    result['evaluations']
    == _SHORT.search.n_init + _SHORT.search.q * _SHORT.search.max_iter
  )
  assert result['failed_evaluations'] == 0
  assert np.isfinite(result['psd_best'])
  for e in result['errors']['estimate'].values():
    assert np.isfinite(e)
  assert os.path.isfile(os.path.join(workdir, 'montage.png'))


def test_rgb_truth_scores_zero(env):
  net = embedding.load_embedding(env['models'][('physnet', 'rgb')])
  problem = obj_lib.make_problem(CONFIG, net, env['rec'])
  u_truth = physsim.to_unit(physsim.params.make(**TRUTH), problem.space)
  u = np.stack([u_truth, np.zeros(3)])[None]
  gust, noise = obj_lib.candidate_keys(CONFIG.seed, CONFIG.search, 0, 2)
  s = obj_lib.Objective(problem)(
    obj_lib.stack([problem.data]), u, gust[None], noise[None], frames=True
  )
  psd_truth, psd_centre = s.psd[0]
  assert psd_truth < _TRUTH_RGB_PSD_TOLERANCE < psd_centre
  assert s.frames.dtype == np.uint8 and s.frames.shape[-1] == 3
  np.testing.assert_array_equal(s.frames[0], env['rec'].rgb)  # the best: the truth


def test_sdn_clip_embedding_equals_clip_by_clip(env):
  net = embedding.load_embedding(env['models'][('sdn', 'depth')])
  assert net.clip_frames == CLIP_FRAMES
  depth = np.stack([env['rec'].depth, env['rec'].depth[::-1]])  # (2, 8, H, W)
  depth = np.concatenate([depth, depth[:, :1]], axis=1)  # 9 frames: one left over
  x = embedding.network_inputs(jnp.asarray(depth), 'depth', net.input_mode)
  got = np.asarray(embedding.embed_video(net.network, net.params, x, CLIP_FRAMES))
  assert got.shape == (2, 2, 2)
  for s in range(2):
    for k in range(2):
      clip = x[s : s + 1, k * CLIP_FRAMES : (k + 1) * CLIP_FRAMES]
      want = np.asarray(net.network.apply(net.params, clip))[0]
      np.testing.assert_allclose(got[s, k], want, atol=_CLIP_TOLERANCE)


def test_rgb_recording_input_equals_training_input(rgb_dataset):
  cfg = train.Config(
    materials=(MATERIAL,), modality='rgb', image_size=16, network='physnet'
  )
  x, _, _ = train.load_inputs(cfg, rgb_dataset, [MATERIAL])
  index = dataset.open_dataset(rgb_dataset)
  row = index.filter(material=MATERIAL, valid=True).rows[0]
  meta = dataset.read_sequence(index.path(row), rgb=False).meta
  n = int(meta['n_frames'])
  cam0 = np.asarray(x[:n])  # ordered by sequence, camera, frame
  for step in (1, 2):  # the source rate, and half of it (every second frame)
    rec = recording_lib.load_recording(
      index.path(row), fps=meta['fps'] / step, size=(16, 16), rgb=True
    )
    got = np.asarray(embedding.network_inputs(rec.rgb, 'rgb'))
    assert len(got) == len(rec.depth) == len(range(0, n, step))
    np.testing.assert_allclose(got, cam0[::step], atol=_RGB_INPUT_TOLERANCE, rtol=0)


def test_tinted_shading_matches_shading_in_the_colour():
  # Datasets and the estimate shade in white and tint each world
  # (physsim.render_rgb8); shading directly in the colour agrees to a level.
  mesh = physsim.square(CONFIG.simulation.cloth_resolution)
  intr = physsim.Intrinsics(width=SIZE, height=SIZE)
  # A crumpled cloth, so the faces' shading differs.
  bumps = 0.05 * jax.random.normal(jax.random.key(1), mesh.vertices.shape)
  pos = (jnp.asarray(mesh.vertices, jnp.float32) + bumps)[None, None]  # (1, 1, V, 3)
  poses = physsim.sample_poses(jax.random.key(3), 1)
  poses = jax.tree.map(lambda a: a[None], poses)  # (1, 1, ...)
  colour = embedding.rgb_color('pink_nylon')  # a colour whose channels differ
  tinted = physsim.render_rgb8(pos, mesh.faces, intr, poses, jnp.asarray([colour]))
  direct = physsim.render_rgb(pos, mesh.faces, intr, poses, color=colour)
  direct = jnp.round(direct * 255).astype(jnp.uint8)
  assert np.asarray(tinted).max() > 0
  diff = np.abs(np.asarray(tinted, int) - np.asarray(direct, int))
  assert diff.max() <= _SHADE_LEVELS


def test_rgb_method_without_rgb_frames_is_named(env, tmp_path):
  depth_only = write_recording(str(tmp_path), TRUTH)
  with pytest.raises(ValueError, match=f'{depth_only}.*no RGB frames'):
    load(depth_only, rgb=True)
  rec = load(depth_only)
  with pytest.raises(ValueError, match=f'{depth_only}.*no RGB frames'):
    estimation.estimate(_SHORT, rec, env['models'][('sdn', 'rgb')], str(tmp_path / 'w'))


def test_recording_shorter_than_a_clip_is_named(env, tmp_path):
  short = env['rec']._replace(depth=env['rec'].depth[: CLIP_FRAMES - 1])
  with pytest.raises(ValueError, match=f'{env["seq"]}.*shorter than one SDN clip'):
    estimation.estimate(
      _SHORT, short, env['models'][('sdn', 'depth')], str(tmp_path / 'w')
    )
  assert not os.path.exists(tmp_path / 'w')  # nothing written


def test_network_inputs_rejects_unknown_modality():
  with pytest.raises(ValueError, match='thermal'):
    embedding.network_inputs(np.zeros((1, 4, 4)), 'thermal')
  assert model_lib.rgb_input(np.full((1, 2, 2, 3), 255, np.uint8)).max() == 1.0
