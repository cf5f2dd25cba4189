"""Tests for model.sdn (FFT features vs numpy.fft) and model.contrastive."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

from model import contrastive, physnet, sdn

_FFT_TOLERANCE = 1e-4  # float32 rFFT of O(1) signals vs float64 numpy.fft
_TOLERANCE = 1e-6
_TRUNK = physnet.PhySNetConfig(
  image_size=(16, 16), conv_features=(4,), dense_features=(8,)
)


def _clip(seed=0, t=12, h=6, w=5, c=2):
  """Random clip plus two pixel-wide sinusoids so the strongest bins are known."""
  rng = np.random.default_rng(seed)
  tt = np.arange(t)[:, None, None, None]
  x = 0.1 * rng.normal(size=(t, h, w, c)) + 0.5
  x = (
    x
    + 1.0 * np.cos(2 * np.pi * 3 * tt / t + 0.4)
    + 0.6 * np.sin(2 * np.pi * 5 * tt / t)
  )
  return x.astype(np.float32)


def _np_features(clip, bins, use_phase):
  spec = np.fft.rfft(clip.astype(np.float64), axis=0)[bins]  # (K, H, W, C)
  spec = np.moveaxis(spec, 0, 2).reshape(clip.shape[1], clip.shape[2], -1)
  feats = [np.abs(spec) / clip.shape[0]]
  if use_phase:
    feats.append(np.angle(spec))
  return np.concatenate(feats, -1)


class SpectralFeaturesTest(absltest.TestCase):
  def test_strongest_bins_match_numpy(self):
    clip = _clip()
    cfg = sdn.SDNConfig(in_channels=2, num_frames=12, num_components=3, trunk=_TRUNK)
    power = np.mean(
      np.abs(np.fft.rfft(clip.astype(np.float64), axis=0)) ** 2, axis=(1, 2, 3)
    )
    power[0] = -np.inf  # drop_dc
    bins = np.argsort(-power)[:3]
    self.assertEqual(list(bins[:2]), [3, 5])
    got = sdn.spectral_features(jnp.asarray(clip), cfg)
    self.assertEqual(got.shape, (6, 5, 3 * 2))
    np.testing.assert_allclose(
      got, _np_features(clip, bins, False), atol=_FFT_TOLERANCE
    )

  def test_lowest_bins_with_phase_match_numpy(self):
    clip = _clip(1)
    cfg = sdn.SDNConfig(
      in_channels=2,
      num_frames=12,
      num_components=4,
      selection='lowest',
      use_phase=True,
      trunk=_TRUNK,
    )
    got = np.asarray(sdn.spectral_features(jnp.asarray(clip), cfg))
    want = _np_features(clip, np.arange(1, 5), True)
    self.assertEqual(got.shape, (6, 5, 4 * 2 * 2))
    np.testing.assert_allclose(got[..., :8], want[..., :8], atol=_FFT_TOLERANCE)
    # Phase wraps at +-pi: compare on the circle.
    np.testing.assert_allclose(
      np.cos(got[..., 8:]), np.cos(want[..., 8:]), atol=10 * _FFT_TOLERANCE
    )
    np.testing.assert_allclose(
      np.sin(got[..., 8:]), np.sin(want[..., 8:]), atol=10 * _FFT_TOLERANCE
    )

  def test_config_validation(self):
    with self.assertRaisesRegex(ValueError, 'num_components'):
      sdn.SDNConfig(num_frames=8, num_components=5)
    with self.assertRaisesRegex(ValueError, 'selection'):
      sdn.SDNConfig(selection='median')


class SDNNetworkTest(absltest.TestCase):
  def test_shapes_and_channels(self):
    cfg = sdn.SDNConfig(
      in_channels=3, num_frames=8, num_components=2, use_phase=True, trunk=_TRUNK
    )
    self.assertEqual(cfg.trunk_config.in_channels, 12)
    net = sdn.make_sdn(cfg)
    params = jax.jit(net.init)(jax.random.PRNGKey(0))
    self.assertEqual(params['net']['Conv_0']['kernel'].shape, (5, 5, 12, 4))
    clips = jax.random.normal(jax.random.PRNGKey(1), (2, 8, 16, 16, 3))
    out = jax.jit(net.apply)(params, clips)
    self.assertEqual(out.shape, (2, 2))
    self.assertTrue(np.all(np.isfinite(out)))
    with self.assertRaisesRegex(ValueError, 'clips must have shape'):
      jax.eval_shape(
        net.apply, params, jax.ShapeDtypeStruct((2, 9, 16, 16, 3), jnp.float32)
      )

  def test_static_clip_has_no_motion_features(self):
    # A clip that does not move has all its energy in the (dropped) DC bin.
    cfg = dataclasses.replace(
      sdn.SDNConfig(num_frames=8, num_components=2, trunk=_TRUNK)
    )
    clip = jnp.broadcast_to(
      jax.random.normal(jax.random.PRNGKey(2), (1, 16, 16, 1)), (8, 16, 16, 1)
    )
    np.testing.assert_allclose(sdn.spectral_features(clip, cfg), 0.0, atol=1e-5)


class ContrastiveTest(absltest.TestCase):
  def test_hand_computed_loss(self):
    e1 = jnp.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    e2 = jnp.array([[0.6, 0.8], [0.3, 0.4], [3.0, 4.0]])
    same = jnp.array([True, False, False])
    # same: d^2 = 1; different d = 0.5 < 1: (1 - 0.5)^2 = 0.25; different d = 5: 0.
    loss, active = contrastive.contrastive_loss(e1, e2, same, margin=1.0)
    np.testing.assert_allclose(loss, (1.0 + 0.25 + 0.0) / 3, atol=_TOLERANCE)
    np.testing.assert_allclose(active, 2 / 3, atol=_TOLERANCE)

  def test_pairs_flag_is_label_equality(self):
    labels = jnp.array([0, 0, 1, 1, 2, 2, 2])
    p = contrastive.random_pairs(
      jax.random.PRNGKey(0), labels, jnp.tile(jnp.arange(7), 50)
    )
    lab = np.asarray(labels)
    np.testing.assert_array_equal(
      np.asarray(p.same), lab[np.asarray(p.first)] == lab[np.asarray(p.second)]
    )
    self.assertTrue(0.3 < float(np.mean(p.same)) < 0.7)


class SDNTrainStepTest(absltest.TestCase):
  def test_contrastive_step_on_clips(self):
    from model import train

    cfg = train.TrainConfig(
      network='sdn',
      sdn=sdn.SDNConfig(num_frames=8, num_components=2, trunk=_TRUNK),
      loss='contrastive',
      batch_size=4,
    )
    network = train.make_network(cfg)
    optimizer, schedule = train.make_optimizer(cfg, 5)
    state = jax.jit(lambda k: train.init_state(network, optimizer, k))(
      jax.random.PRNGKey(0)
    )
    clips = np.asarray(jax.random.normal(jax.random.PRNGKey(1), (6, 8, 16, 16, 1)))
    labels = np.array([0, 0, 1, 1, 2, 2])
    idx = train.make_sampler(cfg, labels, 1)(state.key, 0)
    new, m = jax.jit(train.make_train_step(network, optimizer, schedule, cfg))(
      state, train._gather(clips, labels, idx)
    )
    self.assertTrue(np.isfinite(float(m['loss'])))
    self.assertEqual(int(new.step), 1)


if __name__ == '__main__':
  absltest.main()
