"""PhySNet: the convolutional embedding network of Duan et al., as a pure pair.

The default config reproduces the original PyTorch network exactly (layer
sizes, VALID 5x5 convolutions, one learnable PReLU slope per layer initialised
at 0.25, 2-D output):

  Conv(C->32, 5x5) -> PReLU -> MaxPool 2 -> Conv(32->64, 5x5) -> PReLU ->
  MaxPool 2 -> flatten (61x61x64 at 256x256) -> Dense 256 -> PReLU ->
  Dense 256 -> PReLU -> Dense 2.

Layout is NHWC (JAX's native one); the flatten order therefore differs from
PyTorch's NCHW, which matters only when importing PyTorch weights (permute the
first dense kernel's rows), not for training.

``make_physnet(config)`` returns ``Network(init, apply)``; ``params`` is a dict
``{'net': flax params, 'stats': InputStats}``. The dataset mean/std live in the
params so that checkpoints carry them; they are not trained (``apply`` stops
their gradient and ``model.train`` differentiates ``params['net']`` only).
"""

import dataclasses
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

Params = dict[str, Any]

# PyTorch's nn.PReLU default slope.
PRELU_INIT = 0.25
INITS = ('torch', 'flax')
POOL_IMPLS = ('blocks', 'window')
# Variance scale 1/3 with a uniform law gives PyTorch's bound 1/sqrt(fan_in).
_TORCH_KERNEL_INIT = nn.initializers.variance_scaling(1.0 / 3.0, 'fan_in', 'uniform')
_MIN_STD = 1e-6


@dataclasses.dataclass(frozen=True)
class PhySNetConfig:
  """Architecture of PhySNet (defaults: the original network).

  Attributes:
    in_channels: input channels C (1 for depth, 3 for RGB).
    image_size: (H, W) used by ``init`` to build parameter shapes.
    conv_features: output channels of each conv block (its length is the depth).
    kernel_size: square conv kernel size (VALID padding, stride 1).
    pool: max-pool window and stride after each conv block.
    dense_features: widths of the hidden dense layers (each followed by PReLU).
    embed_dim: size of the output embedding (2 = the paper's similarity map).
    compute_dtype: dtype of activations and matmuls ('float32' or 'bfloat16');
      parameters stay float32.
    init: 'torch' (PyTorch's default: weights and biases uniform in
      +-1/sqrt(fan_in), as the original network was initialised) or 'flax'
      (LeCun normal weights, zero biases).
    pool_impl: how the max-pool is computed; both give the same forward pass.
      'blocks' reshapes into non-overlapping p x p blocks and reduces them: its
      gradient is an elementwise mask that XLA fuses (where several entries of a
      block tie for the maximum it is shared among them). 'window' is
      ``flax.linen.max_pool``, whose gradient is XLA's select-and-scatter (the
      whole gradient to one of the tied entries), a slow memory-bound kernel on
      GPUs (``benchmarks/train_throughput.py --pool_impls`` times both).
  """

  in_channels: int = 1
  image_size: tuple[int, int] = (256, 256)
  conv_features: tuple[int, ...] = (32, 64)
  kernel_size: int = 5
  pool: int = 2
  dense_features: tuple[int, ...] = (256, 256)
  embed_dim: int = 2
  compute_dtype: str = 'float32'
  init: str = 'torch'
  pool_impl: str = 'blocks'

  def __post_init__(self):
    if self.init not in INITS:
      raise ValueError(f'PhySNetConfig.init must be one of {INITS}, got {self.init!r}')
    if self.pool_impl not in POOL_IMPLS:
      raise ValueError(
        f'PhySNetConfig.pool_impl must be one of {POOL_IMPLS}, got {self.pool_impl!r}'
      )
    for name in ('in_channels', 'kernel_size', 'pool', 'embed_dim'):
      if int(getattr(self, name)) < 1:
        raise ValueError(
          f'PhySNetConfig.{name} must be >= 1, got {getattr(self, name)}'
        )
    if self.compute_dtype not in ('float32', 'bfloat16'):
      raise ValueError(
        f"PhySNetConfig.compute_dtype must be 'float32' or 'bfloat16', got "
        f'{self.compute_dtype!r}'
      )
    h, w = feature_map_size(self)
    if h < 1 or w < 1:
      raise ValueError(
        f'PhySNetConfig.image_size {self.image_size} is too small for '
        f'{len(self.conv_features)} conv blocks of kernel {self.kernel_size}.'
      )


def feature_map_size(config: PhySNetConfig) -> tuple[int, int]:
  """Spatial size (h, w) of the last conv block's output (before flatten)."""
  h, w = config.image_size
  for _ in config.conv_features:
    h = (h - config.kernel_size + 1) // config.pool
    w = (w - config.kernel_size + 1) // config.pool
  return h, w


class InputStats(NamedTuple):
  """Per-channel dataset statistics used to normalise inputs.

  Attributes:
    mean: ``(C,)`` float32.
    std: ``(C,)`` float32.
  """

  mean: jax.Array
  std: jax.Array


class Network(NamedTuple):
  """A pure network pair.

  Attributes:
    init: ``init(key) -> params``.
    apply: ``apply(params, x) -> (N, embed_dim)`` embeddings; ``x`` is
      ``(N, H, W, C)`` for PhySNet and ``(N, T, H, W, C)`` for SDN.
  """

  init: Callable[[jax.Array], Params]
  apply: Callable[[Params, jax.Array], jax.Array]


class PhySNet(nn.Module):
  """The PhySNet trunk on already normalised ``(N, H, W, C)`` inputs."""

  config: PhySNetConfig

  @nn.compact
  def __call__(self, x):
    cfg = self.config
    dtype = jnp.dtype(cfg.compute_dtype)
    k, p = cfg.kernel_size, cfg.pool
    x = x.astype(dtype)
    for feats in cfg.conv_features:
      init = self._inits(k * k * x.shape[-1])
      x = nn.Conv(feats, (k, k), padding='VALID', dtype=dtype, **init)(x)
      x = nn.PReLU(negative_slope_init=PRELU_INIT)(x)
      x = max_pool(x, p, cfg.pool_impl)
    x = x.reshape(x.shape[0], -1)
    for feats in cfg.dense_features:
      x = nn.Dense(feats, dtype=dtype, **self._inits(x.shape[-1]))(x)
      x = nn.PReLU(negative_slope_init=PRELU_INIT)(x)
    x = nn.Dense(cfg.embed_dim, dtype=dtype, **self._inits(x.shape[-1]))(x)
    return x.astype(jnp.float32)

  def _inits(self, fan_in: int) -> dict:
    """Kernel and bias initialisers for a layer with ``fan_in`` inputs."""
    if self.config.init == 'flax':
      return {}
    bound = 1.0 / math.sqrt(fan_in)

    def bias_init(key, shape, dtype=jnp.float32):
      return jax.random.uniform(key, shape, dtype, -bound, bound)

    return {'kernel_init': _TORCH_KERNEL_INIT, 'bias_init': bias_init}


def max_pool(x: jax.Array, p: int, impl: str = 'blocks') -> jax.Array:
  """Non-overlapping p x p max-pool of ``(N, H, W, C)``, VALID (trailing rows dropped).

  ``impl`` is ``PhySNetConfig.pool_impl``: same values either way; only the
  gradient at tied maxima and the speed differ.
  """
  if impl == 'window':
    return nn.max_pool(x, (p, p), strides=(p, p))
  n, h, w, c = x.shape
  h, w = h // p, w // p
  blocks = x[:, : h * p, : w * p].reshape(n, h, p, w, p, c)
  return jnp.max(blocks, axis=(2, 4))


def identity_stats(channels: int) -> InputStats:
  """Stats that leave inputs unchanged (mean 0, std 1), ``(C,)`` each."""
  return InputStats(
    jnp.zeros((channels,), jnp.float32), jnp.ones((channels,), jnp.float32)
  )


def compute_stats(images, channel_axis: int = -1) -> InputStats:
  """Per-channel mean and std over every other axis (float64 on the host).

  Args:
    images: array with channels on ``channel_axis``, e.g. ``(N, H, W, C)``.
    channel_axis: the channel axis.

  Returns:
    ``InputStats`` with ``(C,)`` float32 arrays; std is floored at 1e-6.
  """
  x = np.moveaxis(np.asarray(images), channel_axis, -1)
  x = x.reshape(-1, x.shape[-1]).astype(np.float64)
  mean, std = x.mean(0), np.maximum(x.std(0), _MIN_STD)
  return InputStats(jnp.asarray(mean, jnp.float32), jnp.asarray(std, jnp.float32))


def normalise(stats: InputStats, x: jax.Array) -> jax.Array:
  """``(x - mean) / std`` over the last (channel) axis, no gradient to stats."""
  stats = jax.lax.stop_gradient(stats)
  return (x - stats.mean) / stats.std


def with_stats(params: Params, stats: InputStats) -> Params:
  """Returns ``params`` with its input statistics replaced."""
  return {**params, 'stats': InputStats(*(jnp.asarray(s, jnp.float32) for s in stats))}


def make_physnet(config: PhySNetConfig = PhySNetConfig()) -> Network:
  """Builds PhySNet as a pure pair.

  Args:
    config: the architecture.

  Returns:
    ``Network``: ``init(key) -> params`` and ``apply(params, x (N, H, W, C)) ->
    (N, embed_dim)`` float32. ``apply`` normalises ``x`` by ``params['stats']``.
  """
  module = PhySNet(config)

  def init(key):
    x = jnp.zeros((1, *config.image_size, config.in_channels), jnp.float32)
    return {
      'net': module.init(key, x)['params'],
      'stats': identity_stats(config.in_channels),
    }

  def apply(params, x):
    check_images(x, config)
    return module.apply({'params': params['net']}, normalise(params['stats'], x))

  return Network(init, apply)


def check_images(x, config: PhySNetConfig, name: str = 'images') -> None:
  """Raises ValueError unless ``x`` is ``(N, *image_size, in_channels)`` (static shapes)."""
  want = (*config.image_size, config.in_channels)
  if x.ndim != 4 or tuple(x.shape[1:]) != want:
    raise ValueError(
      f'{name} must have shape (N, {", ".join(map(str, want))}), got {tuple(x.shape)}.'
    )


def param_count(params: Any) -> int:
  """Number of scalars in a pytree of arrays or ShapeDtypeStructs."""
  return sum(math.prod(x.shape) for x in jax.tree.leaves(params))
