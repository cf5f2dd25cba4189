"""experiments.pipeline.training (experiments.train): depth and RGB runs, inputs.json, restore, resume, bad input."""

import json
import os
import shutil

import cv2
import jax
import numpy as np
import pytest

import model as model_lib
from experiments.pipeline import embedding
from experiments.pipeline import training as train
from experiments.studies import table1
from physsim import dataset

pytestmark = pytest.mark.slow  # trains PhySNet on depth and RGB

MATERIAL = 'gray_interlock'
# Table 1's smoke runs (half the simulations held out: two labels on each side).
_SMOKE = train.replace(table1.PRESETS['smoke'].train, materials=(MATERIAL,))
# 8-bit colour over 255 in float32 against the same in float64.
_RGB_TOLERANCE = 1e-6


def _snapshot(run_dir):
  """Checkpoint steps and the metrics log's content: what a retrain would change."""
  steps = sorted(os.listdir(os.path.join(run_dir, 'checkpoints')))
  with open(os.path.join(run_dir, model_lib.train.METRICS_FILE)) as f:
    return steps, f.read()


@pytest.fixture(scope='module')
def runs(rgb_dataset, table1_workdir):
  """{modality: (workdir, run result)} of PhySNet trained on depth and on RGB."""
  out = {}
  for modality in train.MODALITIES:
    # Where table1 keeps these runs, so its test reuses them instead of retraining.
    run_dir = table1.run_dir(
      table1_workdir, 'physnet', modality, 'simulation', MATERIAL
    )
    workdir = os.path.dirname(run_dir)
    cfg = train.replace(_SMOKE, modality=modality)
    out[modality] = (workdir, train.run(cfg, rgb_dataset, workdir, progress=False))
  return out


@pytest.mark.parametrize('modality', train.MODALITIES)
def test_run_records_inputs_and_restores(runs, rgb_dataset, modality):
  workdir, result = runs[modality]
  run_dir = os.path.join(workdir, MATERIAL)
  with open(os.path.join(run_dir, embedding.INPUTS_FILE)) as f:
    rec = json.load(f)
  assert rec['modality'] == modality and rec['input_mode'] == _SMOKE.input_mode
  assert rec['materials'] == [MATERIAL] and rec['dataset'] == rgb_dataset
  assert embedding.modality(run_dir) == modality
  assert embedding.input_mode(run_dir) == _SMOKE.input_mode
  assert 0.0 <= result[MATERIAL]['test_triplet_accuracy'] <= 1.0

  network, params, tconfig = model_lib.load_network(run_dir)
  assert tconfig.physnet.in_channels == train.CHANNELS[modality]
  cfg = train.replace(_SMOKE, modality=modality)
  x, y, _ = train.load_inputs(cfg, rgb_dataset, [MATERIAL])
  assert x.shape == (4 * 2 * 4, 32, 32, train.CHANNELS[modality])
  emb = np.asarray(jax.jit(network.apply)(params, x[:5]))
  assert emb.shape == (5, 2) and np.all(np.isfinite(emb))
  # the restored net is the trained one: its embedding differs from a fresh init's
  fresh = network.init(jax.random.PRNGKey(123))
  assert not np.allclose(emb, np.asarray(network.apply(fresh, x[:5])))
  # Trained data-parallel over both test devices; loaded for inference, its
  # parameters sit on one (over two, every program using them would run on
  # each device, host callbacks on one only).
  net = embedding.load_embedding(run_dir)
  for leaf in jax.tree.leaves(net.params):
    assert leaf.devices() == {jax.local_devices()[0]}


@pytest.mark.parametrize('modality', train.MODALITIES)
def test_rerun_does_not_retrain(runs, rgb_dataset, modality):
  workdir, result = runs[modality]
  run_dir = os.path.join(workdir, MATERIAL)
  before = _snapshot(run_dir)
  cfg = train.replace(_SMOKE, modality=modality)
  again = train.run(cfg, rgb_dataset, workdir, progress=False)
  assert _snapshot(run_dir) == before
  assert again == result
  assert train.finished_eval(cfg, rgb_dataset, run_dir, [MATERIAL]) == result[MATERIAL]
  # another config is not this run
  other = train.replace(cfg, seed=cfg.fit.seed + 1)
  assert train.finished_eval(other, rgb_dataset, run_dir, [MATERIAL]) is None


def test_rgb_inputs_match_the_png_files(rgb_dataset):
  cfg = train.replace(_SMOKE, modality='rgb', image_size=0)
  x, y, _ = train.load_inputs(cfg, rgb_dataset, [MATERIAL])
  index = dataset.open_dataset(rgb_dataset)
  rows = index.filter(material=MATERIAL, valid=True).rows
  # items run over sequence, camera, frame: item 1 * 8 + 1 * 4 + 2 = seq 1, cam 1, t 2
  path = os.path.join(index.path(rows[1]), 'cam1', 'rgb_0002.png')
  ref = cv2.imread(path, cv2.IMREAD_COLOR)[..., ::-1].astype(np.float64) / 255.0
  np.testing.assert_allclose(x[8 + 4 + 2], ref, atol=_RGB_TOLERANCE)
  assert y[8 + 4 + 2] == rows[1]['label']
  # resizing is the depth's nearest-neighbour resize, channel by channel
  small = train.load_inputs(train.replace(cfg, image_size=16), rgb_dataset, [MATERIAL])[
    0
  ]
  for c in range(3):
    np.testing.assert_array_equal(
      small[..., c], dataset.resize_depth(x[..., c], (16, 16))
    )


def test_threaded_reading_matches_one_thread(rgb_dataset, tmp_path):
  # Sequences are read by a thread pool; order and values do not depend on it.
  cfg = train.replace(_SMOKE, image_size=0)
  one = train.load_inputs(cfg, rgb_dataset, [MATERIAL], workers=1)
  many = train.load_inputs(cfg, rgb_dataset, [MATERIAL], workers=3)
  for a, b in zip(one, many, strict=True):
    np.testing.assert_array_equal(a, b)
  # a corrupt frame in a later sequence is still named
  root = str(tmp_path / 'ds')
  shutil.copytree(rgb_dataset, root)
  index = dataset.open_dataset(root)
  bad = os.path.join(
    index.path(index.filter(material=MATERIAL, valid=True).rows[-1]), 'cam0'
  )
  name = sorted(f for f in os.listdir(bad) if not f.startswith('rgb'))[0]
  with open(os.path.join(bad, name), 'wb') as f:
    f.write(b'not a png')
  with pytest.raises(ValueError, match=name):
    train.load_inputs(cfg, root, [MATERIAL], workers=3)


def test_sdn_rgb_clips(rgb_dataset):
  cfg = train.replace(_SMOKE, modality='rgb', network='sdn')
  x, y, _ = train.load_inputs(cfg, rgb_dataset, [MATERIAL])
  frames = train.load_inputs(
    train.replace(cfg, network='physnet'), rgb_dataset, [MATERIAL]
  )[0]
  # 4 frames per camera make one 4-frame clip per camera and sequence
  assert x.shape == (4 * 2, cfg.sdn.num_frames, 32, 32, 3)
  np.testing.assert_array_equal(x[3], frames[12:16])  # seq 1, cam 1
  tconfig = train.train_config(cfg, x.shape[-3:-1])
  assert tconfig.sdn.in_channels == 3
  net = model_lib.make_network(tconfig)
  emb = net.apply(net.init(jax.random.PRNGKey(0)), x[:2])
  assert emb.shape == (2, 2)


def test_rgb_of_a_depth_only_dataset_is_a_clear_error(depth_only_dataset, tmp_path):
  cfg = train.replace(_SMOKE, modality='rgb')
  with pytest.raises(ValueError, match='no RGB frames') as err:
    train.run(cfg, depth_only_dataset, str(tmp_path), progress=False)
  assert depth_only_dataset in str(err.value)
  with pytest.raises(ValueError, match='modality'):
    train.load_inputs(
      train.replace(cfg, modality='infrared'), depth_only_dataset, [MATERIAL]
    )


def test_unrecorded_run_defaults(tmp_path):
  assert embedding.modality(str(tmp_path)) == 'depth'
  assert embedding.input_mode(str(tmp_path)) == 'relative'


def test_choose_lr_validates_on_the_training_simulations_only(
  rgb_dataset, tmp_path, monkeypatch
):
  seen = {}

  def fake_select(x, y, g, config, workdir, candidates, progress=True):
    seen.update(groups=set(np.asarray(g).tolist()), lrs=tuple(candidates))
    return 1e-3, {1e-2: 0.6, 1e-3: 0.7}

  monkeypatch.setattr(model_lib, 'select_lr', fake_select)
  out = train.choose_lr(_SMOKE, rgb_dataset, str(tmp_path), [1e-2, 1e-3])
  x, y, g = train.load_inputs(_SMOKE, rgb_dataset, [MATERIAL])
  tc = train.train_config(_SMOKE, x.shape[-3:-1])
  train_idx, test_idx = model_lib.split_indices(tc, y, g)
  assert seen['groups'] == set(g[train_idx].tolist())  # held-out sims stay unseen
  assert not seen['groups'] & set(g[test_idx].tolist())
  assert seen['lrs'] == (1e-2, 1e-3)
  with open(tmp_path / MATERIAL / 'lr_selection.json') as f:
    assert json.load(f) == out[MATERIAL]
  assert out[MATERIAL]['best'] == 1e-3


def test_model_selection_run_reports_the_shipped_epoch(rgb_dataset, tmp_path):
  # The smoke set has four simulations: the per-image split leaves all four
  # labels on every side, so validation works there.
  cfg = train.replace(_SMOKE, split='random', epochs=4, val_fraction=0.25, patience=1)
  workdir = str(tmp_path)
  row = train.run(cfg, rgb_dataset, workdir, progress=False)[MATERIAL]
  run_dir = os.path.join(workdir, MATERIAL)
  with open(os.path.join(run_dir, model_lib.train.METRICS_FILE)) as f:
    evals = [r for r in map(json.loads, f) if r.get('eval')]
  best = model_lib.best_epoch(evals)
  assert row == best and 'test_knn_accuracy' in row
  assert evals[-1]['epoch'] == min(cfg.fit.epochs, best['epoch'] + cfg.fit.patience)
  assert os.path.isdir(os.path.join(run_dir, model_lib.train.BEST_DIR))
  before = _snapshot(run_dir)
  assert train.finished_eval(cfg, rgb_dataset, run_dir, [MATERIAL]) == best
  assert train.run(cfg, rgb_dataset, workdir, progress=False)[MATERIAL] == best
  assert _snapshot(run_dir) == before
  # A larger patience is the same run resumed, and it is no longer finished.
  longer = train.replace(cfg, patience=10)
  if evals[-1]['epoch'] < cfg.fit.epochs:
    assert train.finished_eval(longer, rgb_dataset, run_dir, [MATERIAL]) is None


@pytest.mark.parametrize('network', ['physnet', 'sdn'])
def test_video_info_lines_up_with_the_loaded_items(rgb_dataset, network):
  cfg = train.replace(_SMOKE, network=network)
  x, y, _ = train.load_inputs(cfg, rgb_dataset, [MATERIAL])
  videos = model_lib.retrieval.check_videos(
    train.video_info(cfg, rgb_dataset, [MATERIAL]), len(x)
  )
  rows = dataset.open_dataset(rgb_dataset).filter(material=MATERIAL, valid=True).rows
  cams = rows[0]['n_cameras']
  assert len(np.unique(videos.video)) == len(rows) * cams
  for r in rows:  # each label's items carry its index row's parameters
    got = videos.params[y == r['label']]
    want = [r[f] for f in videos.names]
    np.testing.assert_array_equal(got, np.tile(want, (len(got), 1)))
    assert sorted(set(videos.camera[y == r['label']].tolist())) == list(range(cams))
  # A clip never spans two simulations.
  for v in np.unique(videos.video):
    assert len(set(y[videos.video == v].tolist())) == 1


def test_simulation_split_runs_log_parameter_retrieval(runs, rgb_dataset):
  workdir, _ = runs['depth']
  evals = model_lib.read_evals(os.path.join(workdir, MATERIAL))
  rows = dataset.open_dataset(rgb_dataset).filter(material=MATERIAL, valid=True).rows
  held_out = round(len(rows) * _SMOKE.fit.test_fraction)
  for r in evals:  # every held-out simulation, from every camera
    assert r['test_retrieval']['queries'] == held_out * rows[0]['n_cameras']
    assert set(r['test_retrieval']) >= {'error', 'wind_speed', 'area_weight'}


def test_embed_dim_reaches_both_networks():
  for network in ('physnet', 'sdn'):
    tc = train.train_config(
      train.replace(_SMOKE, network=network, embed_dim=8), (32, 32)
    )
    trunk = tc.physnet if network == 'physnet' else tc.sdn.trunk
    assert trunk.embed_dim == 8
    net = model_lib.train.make_network(tc)
    shapes = jax.eval_shape(net.init, jax.random.PRNGKey(0))
    item = model_lib.train.item_shape(tc)
    out = jax.eval_shape(net.apply, shapes, jax.ShapeDtypeStruct((2, *item), 'float32'))
    assert out.shape == (2, 8)


def test_a_network_near_chance_is_warned_about():
  warn = train.weak_network_warning
  assert '55.0%' in warn({'epoch': 3, 'test_triplet_accuracy': 0.55})
  assert warn({'epoch': 3, 'test_triplet_accuracy': train.WEAK_ACCURACY}) is None
  assert warn({'epoch': 3, 'test_triplet_accuracy': 0.8}) is None
  assert warn({}) is None and warn({'epoch': 1}) is None  # not evaluated
