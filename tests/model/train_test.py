"""Tests for model.train: learning on a separable toy set, no recompiles, checkpoints, resume."""

import dataclasses
import os
import tempfile

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

import model
from model import checkpoint, train

_SIZE = 24
_NET = model.PhySNetConfig(
  image_size=(_SIZE, _SIZE), conv_features=(4, 8), dense_features=(16,)
)
_CONFIG = model.TrainConfig(
  physnet=_NET,
  batch_size=8,
  epochs=2,
  split='simulation',
  test_fraction=0.25,
  log_every=4,
  eval_triplets=500,
  max_to_keep=5,
)
# One batch split over two devices vs whole on one: float32 sums in another
# order, through 2 epochs of Adam. Losses agree closely; Adam divides by the
# gradient's own scale, so where a gradient is near zero round-off can move a
# parameter by up to the learning rate (1e-3) per step.
_PARALLEL_RTOL, _PARALLEL_ATOL = 1e-4, 5e-3
# A learnt embedding should order held-out triplets far above chance (0.5).
_MIN_TOY_ACCURACY = 0.9


def toy_set(n_labels=8, per_label=12, seed=0):
  """Blob images whose centre (a 4 x 2 grid) is set by the label, with jitter and noise."""
  rng = np.random.default_rng(seed)
  yy, xx = np.mgrid[:_SIZE, :_SIZE]
  images, labels = [], []
  for label in range(n_labels):
    cy, cx = 5 + 4.5 * (label % 4), 7 + 10 * (label // 4)
    for _ in range(per_label):
      dy, dx = rng.normal(0, 0.7, 2)
      blob = np.exp(-((yy - cy - dy) ** 2 + (xx - cx - dx) ** 2) / 8.0)
      images.append(blob + 0.05 * rng.normal(size=blob.shape))
      labels.append(label)
  return np.asarray(images, np.float32)[..., None], np.asarray(labels)


def _tree_equal(a, b):
  return all(
    jax.tree.leaves(jax.tree.map(lambda x, y: bool(np.array_equal(x, y)), a, b))
  )


class TrainStepTest(absltest.TestCase):
  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.images, cls.labels = toy_set()
    cls.network = train.make_network(_CONFIG)
    stats = model.compute_stats(cls.images)
    optimizer, _ = train.make_optimizer(_CONFIG, 10)
    init = jax.jit(lambda key: train.init_state(cls.network, optimizer, key, stats))
    cls.state0 = init(
      jax.random.PRNGKey(0)
    )  # every loss shares it (Adam's state does not depend on lr)

  def _setup(self, config=_CONFIG):
    optimizer, schedule = train.make_optimizer(config, 10)
    # A copy, because train steps donate their state.
    state = jax.tree.map(jnp.copy, self.state0)
    return self.images, self.labels, self.network, optimizer, schedule, state

  def test_no_recompile_on_second_call(self):
    images, labels, network, optimizer, schedule, state = self._setup()
    traces = []
    step_fn = train.make_train_step(network, optimizer, schedule, _CONFIG)

    def counted(state, batch):
      traces.append(1)
      return step_fn(state, batch)

    jitted = jax.jit(counted, donate_argnums=0)
    sample = jax.jit(train.make_sampler(_CONFIG, labels, 10))
    for step in range(3):
      batch = train._gather(images, labels, sample(state.key, step))
      state, metrics = jitted(state, batch)
    self.assertLen(traces, 1)
    self.assertEqual(int(state.step), 3)
    self.assertTrue(all(np.isfinite(float(v)) for v in metrics.values()))

  def test_training_separates_toy_labels(self):
    images, labels, network, optimizer, schedule, state = self._setup()
    key = jax.random.PRNGKey(1)
    train_idx, test_idx = model.split_random(key, len(labels), 0.25)
    step_fn = jax.jit(
      train.make_train_step(network, optimizer, schedule, _CONFIG), donate_argnums=0
    )
    sample = jax.jit(train.make_sampler(_CONFIG, labels[train_idx], 9))
    losses = []
    for step in range(200):
      batch = train._gather(
        images[train_idx], labels[train_idx], sample(state.key, step)
      )
      state, m = step_fn(state, batch)
      losses.append(float(m['loss']))
    self.assertLess(np.mean(losses[-20:]), 0.3 * np.mean(losses[:20]))
    emb = model.embed(network.apply, state.params, images, 64)
    acc = model.triplet_accuracy(key, emb[test_idx], labels[test_idx], 2000)
    self.assertGreater(acc, _MIN_TOY_ACCURACY)
    knn = model.knn_accuracy(
      emb[train_idx], labels[train_idx], emb[test_idx], labels[test_idx], 3
    )
    self.assertGreater(knn, _MIN_TOY_ACCURACY)

  def test_batch_hard_and_contrastive_steps_run(self):
    for loss in ('batch_hard', 'contrastive'):
      config = dataclasses.replace(_CONFIG, loss=loss)
      images, labels, network, optimizer, schedule, state = self._setup(config)
      step_fn = jax.jit(train.make_train_step(network, optimizer, schedule, config))
      batch = train._gather(
        images, labels, train.make_sampler(config, labels, 10)(state.key, 0)
      )
      new, m = step_fn(state, batch)
      self.assertTrue(np.isfinite(float(m['loss'])), loss)
      self.assertFalse(_tree_equal(new.params['net'], state.params['net']), loss)
      self.assertTrue(_tree_equal(new.params['stats'], state.params['stats']), loss)


class CheckpointTest(absltest.TestCase):
  def test_save_restore_round_trip(self):
    images, _ = toy_set()
    network = train.make_network(_CONFIG)
    optimizer, _ = train.make_optimizer(_CONFIG, 10)
    stats = model.compute_stats(images)
    init = lambda key: train.init_state(network, optimizer, key, stats)
    # A non-trivial state: a random tree of the right shapes, at step 17.
    target = jax.eval_shape(init, jax.random.PRNGKey(0))
    leaves, treedef = jax.tree.flatten(target)
    rng = np.random.default_rng(0)
    state = jax.tree.unflatten(
      treedef, [jnp.asarray(rng.normal(size=x.shape).astype(x.dtype)) for x in leaves]
    ).replace(step=jnp.asarray(17, jnp.int32))
    with tempfile.TemporaryDirectory() as wd:
      with checkpoint.manager(wd) as mngr:
        self.assertIsNone(checkpoint.restore(mngr, target))
        checkpoint.save(mngr, 17, state)
      self.assertTrue(os.path.isdir(os.path.join(wd, 'checkpoints', '17')))
      with checkpoint.manager(wd) as mngr:
        restored = checkpoint.restore(mngr, target)
    self.assertIsInstance(restored, train.TrainState)
    self.assertIsInstance(restored.params['stats'], model.InputStats)
    self.assertEqual(jax.tree.structure(restored), jax.tree.structure(state))
    self.assertTrue(_tree_equal(restored, state))

  def test_fit_resumes_exactly(self):
    images, labels = toy_set(per_label=8)
    with tempfile.TemporaryDirectory() as wd:
      full = model.fit(
        images, labels, labels, _CONFIG, os.path.join(wd, 'full'), progress=False
      )
      part = os.path.join(wd, 'part')
      first = model.fit(
        images,
        labels,
        labels,
        dataclasses.replace(_CONFIG, epochs=1),
        part,
        progress=False,
      )
      resumed = model.fit(images, labels, labels, _CONFIG, part, progress=False)
      self.assertTrue(os.path.exists(os.path.join(part, 'config.json')))
      self.assertEqual(int(first.state.step), int(full.state.step) // 2)
      self.assertEqual(int(resumed.state.step), int(full.state.step))
      self.assertTrue(_tree_equal(resumed.state.params, full.state.params))
      self.assertEqual(
        [r['step'] for r in resumed.history], [r['step'] for r in full.history]
      )
      evals = [r for r in full.history if r.get('eval')]
      self.assertLen(evals, 2)
      self.assertIn('test_triplet_accuracy', evals[-1])
      # Held-out simulations: no test label was trained on.
      self.assertEqual(set(labels[full.test_idx]) & set(labels[full.train_idx]), set())
      network, params, config = model.load_network(part)
      self.assertEqual(config, _CONFIG)
      self.assertTrue(_tree_equal(params, full.state.params))
      with self.assertRaisesRegex(ValueError, 'learning_rate'):
        model.fit(
          images,
          labels,
          labels,
          dataclasses.replace(_CONFIG, learning_rate=0.1),
          part,
          progress=False,
        )
      # A hook that stops the fit after its first epoch (a script's time
      # limit): that epoch is checkpointed, and the same call resumes to the
      # uninterrupted run's parameters.
      seen = []

      def stop(seconds):
        seen.append(seconds)
        raise KeyboardInterrupt

      hooked = os.path.join(wd, 'hooked')
      with self.assertRaises(KeyboardInterrupt):
        model.fit(
          images, labels, labels, _CONFIG, hooked, progress=False, after_epoch=stop
        )
      self.assertLen(seen, 1)
      self.assertGreater(seen[0], 0.0)
      again = model.fit(
        images, labels, labels, _CONFIG, hooked, progress=False, after_epoch=stop
      )  # the last epoch calls no hook
      self.assertTrue(_tree_equal(again.state.params, full.state.params))

  def test_a_batch_split_over_devices_trains_as_on_one(self):
    # conftest gives two CPU devices: fit splits each batch of 8 over both by
    # default; the same global batch on one device gives the same update up
    # to the order of float32 sums.
    self.assertLen(jax.local_devices(), 2)
    self.assertIsNotNone(train.data_parallel(_CONFIG.batch_size))
    self.assertIsNone(train.data_parallel(7))  # 2 does not divide 7
    self.assertIsNone(train.data_parallel(8, jax.local_devices()[:1]))
    images, labels = toy_set(per_label=8)
    with tempfile.TemporaryDirectory() as wd:
      kw = dict(progress=False)
      two = model.fit(images, labels, labels, _CONFIG, os.path.join(wd, 'two'), **kw)
      one = model.fit(images, labels, labels, _CONFIG, os.path.join(wd, 'one'),
                      devices=jax.local_devices()[:1], **kw)  # fmt: skip
    loss = lambda r: [h['loss'] for h in r.history if 'loss' in h]
    np.testing.assert_allclose(loss(two), loss(one), rtol=_PARALLEL_RTOL)
    jax.tree.map(
      lambda a, b: np.testing.assert_allclose(a, b, atol=_PARALLEL_ATOL),
      two.state.params, one.state.params,
    )  # fmt: skip

  def test_validation_split_holds_out_training_simulations(self):
    _, labels = toy_set(per_label=2)
    config = dataclasses.replace(_CONFIG, val_fraction=0.34)
    train_idx, test_idx = model.split_indices(config, labels)
    fit_idx, val_idx = model.validation_split(config, labels, None, train_idx)
    # 8 labels: 2 held out for test, then 2 of the other 6 for validation.
    parts = [set(labels[i]) for i in (fit_idx, val_idx, test_idx)]
    self.assertEqual([len(p) for p in parts], [4, 2, 2])
    self.assertEqual(
      parts[0] & parts[1] | parts[0] & parts[2] | parts[1] & parts[2], set()
    )
    np.testing.assert_array_equal(np.sort(np.r_[fit_idx, val_idx]), train_idx)
    none = model.validation_split(_CONFIG, labels, None, train_idx)
    np.testing.assert_array_equal(none[0], train_idx)
    self.assertEqual(none[1].size, 0)
    with self.assertRaisesRegex(ValueError, 'patience'):
      dataclasses.replace(_CONFIG, patience=2)
    with self.assertRaisesRegex(ValueError, 'val_fraction'):
      dataclasses.replace(_CONFIG, val_fraction=1.0)

  def test_selection_rules_on_a_written_history(self):
    rows = [
      {'step': 1, 'epoch': 1, 'eval': True, 'val_triplet_accuracy': 0.7},
      {'step': 2, 'epoch': 2, 'eval': True, 'val_triplet_accuracy': 0.8},
      {'step': 3, 'epoch': 3, 'eval': True, 'val_triplet_accuracy': 0.8},
      {'step': 4, 'epoch': 4, 'eval': True, 'val_triplet_accuracy': 0.6},
    ]
    self.assertEqual(model.best_epoch(rows)['epoch'], 2)  # the first of equals
    self.assertIs(model.selected_eval(rows), rows[1])
    self.assertFalse(model.stopped_early(rows[:3], 2))
    self.assertTrue(model.stopped_early(rows, 2))
    self.assertFalse(model.stopped_early(rows, 0))
    plain = [{k: v for k, v in r.items() if k != 'val_triplet_accuracy'} for r in rows]
    self.assertIsNone(model.best_epoch(plain))
    self.assertEqual(model.selected_eval(plain)['epoch'], 4)

  def test_fit_keeps_the_best_validation_epoch_and_stops_early(self):
    images, labels = toy_set(per_label=6)
    config = dataclasses.replace(
      _CONFIG, epochs=6, val_fraction=0.34, patience=2, max_to_keep=None
    )
    with tempfile.TemporaryDirectory() as wd:
      result = model.fit(images, labels, labels, config, wd, progress=False)
      evals = [r for r in result.history if r.get('eval')]
      self.assertTrue(all('val_triplet_accuracy' in r for r in evals))
      best = model.best_epoch(result.history)
      # It ran until `patience` epochs passed without a better score, or to the end.
      self.assertEqual(evals[-1]['epoch'], min(config.epochs, best['epoch'] + 2))
      # No image of a validation or test simulation was trained on.
      seen = set(labels[result.train_idx])
      self.assertEqual(seen & set(labels[result.val_idx]), set())
      self.assertEqual(seen & set(labels[result.test_idx]), set())
      # load_network returns the best epoch's params, step= the latest.
      _, params, _ = model.load_network(wd)
      with checkpoint.manager(wd, None) as mngr:
        at_best = checkpoint.restore(mngr, result.state, best['step'])
      self.assertTrue(_tree_equal(params, at_best.params))
      _, latest, _ = model.load_network(wd, best=False)
      self.assertTrue(_tree_equal(latest, result.state.params))
      # Called again, a stopped run does not train on.
      again = model.fit(images, labels, labels, config, wd, progress=False)
      self.assertEqual(int(again.state.step), int(result.state.step))
      self.assertLen(again.history, len(result.history))

  def test_fit_logs_retrieval_and_selects_by_it(self):
    images, labels = toy_set(per_label=6)
    # Each label is one simulation seen by two cameras (3 images each); its
    # parameters follow the blob's grid position.
    camera = np.tile(np.repeat([0, 1], 3), 8)
    params = np.stack([1.5 ** (labels % 4), 2.0 ** (labels // 4)], axis=1)
    videos = model.Videos(2 * labels + camera, camera, params, ('x', 'y'))
    config = dataclasses.replace(
      _CONFIG, epochs=3, val_fraction=0.34, select_by='retrieval'
    )
    with tempfile.TemporaryDirectory() as wd:
      result = model.fit(
        images, labels, labels, config, wd, progress=False, videos=videos
      )
      evals = [r for r in result.history if r.get('eval')]
      self.assertLen(evals, 3)
      n_val = len(set(labels[result.val_idx]))
      for r in evals:
        self.assertEqual(r['val_retrieval']['queries'], 2 * n_val)
        self.assertEqual(r['test_retrieval']['queries'], 2 * 2)
        self.assertEqual(r['val_score'], -r['val_retrieval']['error'])
        self.assertGreaterEqual(r['test_retrieval']['error'], 0.0)
        self.assertSameElements(
          r['test_retrieval'], ['queries', 'error', 'x', 'y', 'chance']
        )
      errors = [r['val_retrieval']['error'] for r in evals]
      self.assertEqual(
        model.best_epoch(result.history)['epoch'], 1 + int(np.argmin(errors))
      )
    with self.assertRaisesRegex(ValueError, 'needs fit.videos'):
      with tempfile.TemporaryDirectory() as wd:
        model.fit(images, labels, labels, config, wd, progress=False)
    with self.assertRaisesRegex(ValueError, "needs split='simulation'"):
      dataclasses.replace(config, split='random')

  def test_fit_rejects_bad_data(self):
    images, labels = toy_set(n_labels=2, per_label=2)
    with tempfile.TemporaryDirectory() as wd:
      with self.assertRaisesRegex(ValueError, 'images must have shape'):
        model.fit(images[..., 0], labels, None, _CONFIG, wd, progress=False)
      with self.assertRaisesRegex(ValueError, 'disagree'):
        model.fit(images, labels[:-1], None, _CONFIG, wd, progress=False)


if __name__ == '__main__':
  absltest.main()
