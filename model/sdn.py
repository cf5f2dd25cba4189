"""SDN baseline: spectral decomposition of a clip fed to the PhySNet trunk.

After Runia et al. (CVPR 2020), built from the paper's description (no public
code): each pixel's intensity over a clip of T frames is Fourier transformed
(real FFT over time), K frequency bins are kept and their amplitude (and
optionally phase) become the input channels of a CNN. Here the CNN is the
PhySNet trunk with ``K * C * (1 + use_phase)`` input channels, trained with
``model.contrastive`` pairs.

Choices, made explicit:

- ``selection='strongest'`` (default) keeps, per clip, the K bins of largest
  mean power over pixels and channels, ordered by decreasing power;
  ``'lowest'`` keeps the K lowest bins, the same for every clip, so channel k
  always means the same frequency.
- ``drop_dc=True`` (default) never keeps bin 0 (the mean image): it carries
  the cloth's shape, not its motion.
- Amplitude is ``|X_f| / T``; phase is ``angle(X_f)`` in ``[-pi, pi]`` (it
  wraps, which a CNN must live with; phase is off by default).
- Frames are normalised by the dataset stats before the FFT.
"""

import dataclasses

import jax
import jax.numpy as jnp

from model import physnet

SELECTIONS = ('strongest', 'lowest')


@dataclasses.dataclass(frozen=True)
class SDNConfig:
  """SDN settings.

  Attributes:
    in_channels: channels C of each frame (1 depth, 3 RGB).
    num_frames: clip length T.
    num_components: K frequency bins kept.
    selection: 'strongest' (per clip, the K frequency bins of largest mean
      power) or 'lowest' (the K lowest bins, the same for every clip).
    use_phase: also feed the phase of each kept bin.
    drop_dc: never keep the zero-frequency bin.
    trunk: the PhySNet trunk; its ``in_channels`` is overwritten by
      ``K * C * (1 + use_phase)``.
  """

  in_channels: int = 1
  num_frames: int = 60
  num_components: int = 8
  selection: str = 'strongest'
  use_phase: bool = False
  drop_dc: bool = True
  trunk: physnet.PhySNetConfig = physnet.PhySNetConfig()

  def __post_init__(self):
    if self.selection not in SELECTIONS:
      raise ValueError(
        f'SDNConfig.selection must be one of {SELECTIONS}, got {self.selection!r}'
      )
    available = self.num_frames // 2 + 1 - int(self.drop_dc)
    if not 1 <= self.num_components <= available:
      raise ValueError(
        f'SDNConfig.num_components must be in [1, {available}] for num_frames='
        f'{self.num_frames} (drop_dc={self.drop_dc}), got {self.num_components}.'
      )

  @property
  def feature_channels(self) -> int:
    """Channels of the spectral feature map: ``K * C * (1 + use_phase)``."""
    return self.num_components * self.in_channels * (1 + int(self.use_phase))

  @property
  def trunk_config(self) -> physnet.PhySNetConfig:
    """The trunk config with its input channels set to ``feature_channels``."""
    return dataclasses.replace(self.trunk, in_channels=self.feature_channels)


def select_bins(power: jax.Array, config: SDNConfig) -> jax.Array:
  """Indices ``(K,)`` of the kept frequency bins given mean power ``(F,)``."""
  k = config.num_components
  first = int(config.drop_dc)
  if config.selection == 'lowest':
    return jnp.arange(first, first + k)
  if config.drop_dc:
    power = power.at[0].set(-jnp.inf)
  return jax.lax.top_k(power, k)[1]


def spectral_features(clip: jax.Array, config: SDNConfig) -> jax.Array:
  """Spectral feature map of one clip.

  Args:
    clip: ``(T, H, W, C)`` float frames (already normalised).
    config: SDN settings.

  Returns:
    ``(H, W, K * C * (1 + use_phase))`` float32: channel ``k * C + c`` is the
    amplitude of kept bin k in image channel c, followed (if ``use_phase``) by
    the phases in the same order.
  """
  t, h, w, c = clip.shape
  spec = jnp.fft.rfft(clip.astype(jnp.float32), axis=0)  # (T//2+1, H, W, C)
  power = jnp.mean(jnp.abs(spec) ** 2, axis=(1, 2, 3))  # (T//2+1,)
  kept = spec[select_bins(power, config)]  # (K, H, W, C)
  kept = jnp.moveaxis(kept, 0, 2).reshape(h, w, -1)  # (H, W, K*C)
  feats = [jnp.abs(kept) / t]
  if config.use_phase:
    feats.append(jnp.angle(kept))
  return jnp.concatenate(feats, axis=-1).astype(jnp.float32)


def make_sdn(config: SDNConfig = SDNConfig()) -> physnet.Network:
  """Builds the SDN as a pure pair.

  Args:
    config: SDN settings.

  Returns:
    ``Network``: ``init(key) -> params`` and ``apply(params, clips (N, T, H, W,
    C)) -> (N, embed_dim)``. ``params['stats']`` normalise the raw frames.
  """
  trunk_cfg = config.trunk_config
  trunk = physnet.PhySNet(trunk_cfg)

  def init(key):
    x = jnp.zeros((1, *trunk_cfg.image_size, trunk_cfg.in_channels), jnp.float32)
    return {
      'net': trunk.init(key, x)['params'],
      'stats': physnet.identity_stats(config.in_channels),
    }

  def apply(params, clips):
    want = (config.num_frames, *trunk_cfg.image_size, config.in_channels)
    if clips.ndim != 5 or tuple(clips.shape[1:]) != want:
      raise ValueError(
        f'clips must have shape (N, {", ".join(map(str, want))}), got {tuple(clips.shape)}.'
      )
    clips = physnet.normalise(params['stats'], clips)
    feats = jax.vmap(spectral_features, in_axes=(0, None))(clips, config)
    return trunk.apply({'params': params['net']}, feats)

  return physnet.Network(init, apply)
