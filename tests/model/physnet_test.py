"""Tests for model.physnet: exact original shapes and parameter count, init, normalisation."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import absltest

from model import physnet

# Parameter count of the original PyTorch PhySNet (1-channel 256x256 input):
#   conv1  1*32*5*5 + 32                 =        832
#   prelu1                               =          1
#   conv2  32*64*5*5 + 64                =     51,264
#   prelu2                               =          1
#   fc1    (64*61*61)*256 + 256 = 238,144*256 + 256 = 60,965,120
#   prelu3                               =          1
#   fc2    256*256 + 256                 =     65,792
#   prelu4                               =          1
#   fc3    256*2 + 2                     =        514
#   total                                = 61,083,526
_ORIGINAL_PARAM_COUNT = 832 + 1 + 51_264 + 1 + 60_965_120 + 1 + 65_792 + 1 + 514
_FLATTEN = 64 * 61 * 61
_TOLERANCE = 1e-5
_SMALL = physnet.PhySNetConfig(
  image_size=(32, 32), conv_features=(4, 8), dense_features=(16,)
)


class PhySNetTest(absltest.TestCase):
  def test_original_shapes_and_param_count_without_allocation(self):
    net = physnet.make_physnet()
    shapes = jax.eval_shape(net.init, jax.random.PRNGKey(0))
    self.assertEqual(_ORIGINAL_PARAM_COUNT, 61_083_526)
    self.assertEqual(physnet.param_count(shapes['net']), _ORIGINAL_PARAM_COUNT)
    self.assertEqual(shapes['net']['Dense_0']['kernel'].shape, (_FLATTEN, 256))
    self.assertEqual(physnet.feature_map_size(physnet.PhySNetConfig()), (61, 61))
    out = jax.eval_shape(
      net.apply, shapes, jax.ShapeDtypeStruct((3, 256, 256, 1), jnp.float32)
    )
    self.assertEqual(out.shape, (3, 2))

  def test_rgb_and_config_fields(self):
    cfg = physnet.PhySNetConfig(
      in_channels=3,
      image_size=(64, 48),
      conv_features=(4, 8, 8),
      kernel_size=3,
      dense_features=(16, 16, 16),
      embed_dim=5,
    )
    net = physnet.make_physnet(cfg)
    params = jax.jit(net.init)(jax.random.PRNGKey(1))
    out = jax.jit(net.apply)(params, jnp.ones((2, 64, 48, 3)))
    self.assertEqual(out.shape, (2, 5))
    self.assertTrue(np.all(np.isfinite(out)))
    # 3 conv + 4 dense layers, one PReLU after each except the last dense.
    self.assertEqual(sum(k.startswith('PReLU') for k in params['net']), 6)

  def test_prelu_slopes_and_torch_init_bounds(self):
    params = physnet.make_physnet(_SMALL).init(jax.random.PRNGKey(2))['net']
    for name, leaf in params.items():
      if name.startswith('PReLU'):
        self.assertEqual(float(leaf['negative_slope']), 0.25)
    # PyTorch default: weights and biases uniform in +-1/sqrt(fan_in).
    fan_in = 5 * 5 * 4
    bound = 1 / np.sqrt(fan_in)
    for leaf in (params['Conv_1']['kernel'], params['Conv_1']['bias']):
      self.assertLessEqual(float(jnp.max(jnp.abs(leaf))), bound)
      self.assertGreater(float(jnp.max(jnp.abs(leaf))), 0.8 * bound)

  def test_prelu_is_leaky_with_learned_slope(self):
    net = physnet.make_physnet(_SMALL)
    params = net.init(jax.random.PRNGKey(3))
    x = jax.random.normal(jax.random.PRNGKey(4), (2, 32, 32, 1))
    y0 = net.apply(params, x)
    params['net']['PReLU_2']['negative_slope'] = jnp.asarray(0.9)
    self.assertGreater(float(jnp.max(jnp.abs(net.apply(params, x) - y0))), 0.0)

  def test_stats_normalise_inputs(self):
    net = physnet.make_physnet(_SMALL)
    params = net.init(jax.random.PRNGKey(5))
    rng = np.random.default_rng(0)
    x = (3.0 + 2.0 * rng.normal(size=(4, 32, 32, 1))).astype(np.float32)
    stats = physnet.compute_stats(x)
    np.testing.assert_allclose(
      stats.mean, [x.astype(np.float64).mean()], rtol=_TOLERANCE
    )
    np.testing.assert_allclose(stats.std, [x.astype(np.float64).std()], rtol=_TOLERANCE)
    got = net.apply(physnet.with_stats(params, stats), jnp.asarray(x))
    want = net.apply(params, jnp.asarray((x - stats.mean) / stats.std))
    np.testing.assert_allclose(got, want, atol=_TOLERANCE)

  def test_bad_input_shape_raises(self):
    net = physnet.make_physnet(_SMALL)
    params = jax.eval_shape(net.init, jax.random.PRNGKey(0))
    with self.assertRaisesRegex(ValueError, 'images must have shape'):
      jax.eval_shape(
        net.apply, params, jax.ShapeDtypeStruct((2, 32, 32, 3), jnp.float32)
      )
    with self.assertRaisesRegex(ValueError, 'image_size'):
      physnet.PhySNetConfig(image_size=(8, 8))

  def test_block_pool_matches_window_pool_and_numpy(self):
    # Odd sizes: VALID pooling drops the trailing row and column.
    x = np.random.default_rng(6).normal(size=(2, 7, 9, 3)).astype(np.float32)
    want = x[:, :6, :8].reshape(2, 3, 2, 4, 2, 3).max(axis=(2, 4))
    for impl in physnet.POOL_IMPLS:
      np.testing.assert_array_equal(physnet.max_pool(jnp.asarray(x), 2, impl), want)

    def grad(impl):
      return jax.grad(lambda v: jnp.sum(physnet.max_pool(v, 2, impl) ** 2))(x)

    # No ties: the gradient is 2*max at each block's argmax, zero elsewhere,
    # and nothing reaches the dropped row and column.
    np.testing.assert_allclose(grad('blocks'), grad('window'), atol=_TOLERANCE)
    self.assertEqual(float(jnp.abs(grad('blocks')[:, 6:, 8:]).max()), 0.0)
    # A tie: 'window' gives the whole gradient to one entry, 'blocks' shares it.
    tie = jnp.ones((1, 2, 2, 1))
    g = jax.grad(lambda v: jnp.sum(physnet.max_pool(v, 2, 'blocks')))(tie)
    np.testing.assert_allclose(g.ravel(), [0.25] * 4)
    g = jax.grad(lambda v: jnp.sum(physnet.max_pool(v, 2, 'window')))(tie)
    self.assertEqual(sorted(np.asarray(g).ravel().tolist()), [0.0, 0.0, 0.0, 1.0])

  def test_networks_with_either_pool_agree(self):
    x = jax.random.normal(jax.random.PRNGKey(7), (3, 32, 32, 1))
    nets = [
      physnet.make_physnet(dataclasses.replace(_SMALL, pool_impl=impl))
      for impl in physnet.POOL_IMPLS
    ]
    params = nets[0].init(jax.random.PRNGKey(8))
    outs = [net.apply(params, x) for net in nets]
    np.testing.assert_allclose(outs[0], outs[1], atol=_TOLERANCE)
    with self.assertRaisesRegex(ValueError, 'pool_impl'):
      physnet.PhySNetConfig(pool_impl='avg')

  def test_bfloat16_compute_keeps_float32_params(self):
    cfg = physnet.PhySNetConfig(
      image_size=(32, 32),
      conv_features=(4,),
      dense_features=(8,),
      compute_dtype='bfloat16',
    )
    net = physnet.make_physnet(cfg)
    params = net.init(jax.random.PRNGKey(0))
    self.assertTrue(all(x.dtype == jnp.float32 for x in jax.tree.leaves(params)))
    self.assertEqual(net.apply(params, jnp.ones((1, 32, 32, 1))).dtype, jnp.float32)


if __name__ == '__main__':
  absltest.main()
