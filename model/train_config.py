"""Training's settings and state: ``TrainConfig`` (written to a run's
``config.json``), the checkpointed ``TrainState``, what ``fit`` returns, the
run folder's file names, and the network and item shape a config names."""

import dataclasses
from typing import Any, NamedTuple

import flax.struct
import jax
import numpy as np

from model import physnet, sdn, splits
from model.physnet import PhySNetConfig
from model.sdn import SDNConfig

NETWORKS = ('physnet', 'sdn')
LOSSES = ('triplet', 'batch_hard', 'contrastive')
SELECT_BY = ('triplet', 'retrieval')
CONFIG_FILE = 'config.json'
METRICS_FILE = 'metrics.jsonl'
# Fields that may change when resuming a run (they do not change what has been done).
RESUMABLE_FIELDS = ('epochs', 'log_every', 'max_to_keep', 'patience')
BEST_DIR = 'best'


@dataclasses.dataclass(frozen=True)
class TrainConfig:
  """Everything ``fit`` needs; written to ``workdir/config.json``.

  Attributes:
    network: 'physnet' (items ``(H, W, C)``) or 'sdn' (items ``(T, H, W, C)``).
    physnet: PhySNet architecture (used when ``network == 'physnet'``).
    sdn: SDN settings (used when ``network == 'sdn'``).
    loss: 'triplet' (random triplets), 'batch_hard' or 'contrastive' (pairs).
    margin: loss margin.
    learning_rate: Adam's initial learning rate.
    lr_step_epochs: StepLR step size in epochs.
    lr_gamma: StepLR decay factor.
    batch_size: triplets (or pairs, or P*K images) per step.
    per_label: K images per label for 'batch_hard' (P = batch_size // K).
    epochs: number of epochs.
    split: 'simulation' (held-out groups), 'random' (per image) or 'none'.
    test_fraction: held-out fraction for the split.
    seed: the only seed.
    eval_triplets: triplets sampled for the test triplet accuracy.
    knn_k: neighbours for the k-NN accuracy (random split only).
    eval_batch_size: batch size when embedding for evaluation.
    log_every: steps between training-metric log rows.
    max_to_keep: checkpoints kept.
    val_fraction: share of the training part held out for validation (whole
      simulations unless ``split == 'random'``); 0 = no validation.
    patience: with validation, stop after this many epochs without a better
      validation score; 0 = run every epoch.
    select_by: the validation score that picks the epoch (and stops early):
      'triplet' (triplet accuracy) or 'retrieval' (least parameter-retrieval
      error of the validation simulations, ``model.retrieval``; needs
      ``fit(videos=...)``, the 'simulation' split and ``val_fraction``).
  """

  network: str = 'physnet'
  physnet: PhySNetConfig = PhySNetConfig()
  sdn: SDNConfig = SDNConfig()
  loss: str = 'triplet'
  margin: float = 1.0
  learning_rate: float = 1e-3
  lr_step_epochs: int = 8
  lr_gamma: float = 0.1
  batch_size: int = 32
  per_label: int = 4
  epochs: int = 30
  split: str = 'simulation'
  test_fraction: float = 0.2
  seed: int = 0
  eval_triplets: int = 10_000
  knn_k: int = 5
  eval_batch_size: int = 256
  log_every: int = 50
  max_to_keep: int = 2
  val_fraction: float = 0.0
  patience: int = 0
  select_by: str = 'triplet'

  def __post_init__(self):
    for name, allowed in (
      ('network', NETWORKS),
      ('loss', LOSSES),
      ('split', splits.SPLITS),
      ('select_by', SELECT_BY),
    ):
      if getattr(self, name) not in allowed:
        raise ValueError(
          f'TrainConfig.{name} must be one of {allowed}, got {getattr(self, name)!r}'
        )
    for name in ('batch_size', 'epochs', 'lr_step_epochs', 'per_label', 'log_every'):
      if int(getattr(self, name)) < 1:
        raise ValueError(f'TrainConfig.{name} must be >= 1, got {getattr(self, name)}')
    if self.loss == 'batch_hard' and (
      self.batch_size % self.per_label or self.batch_size // self.per_label < 2
    ):
      raise ValueError(
        f'TrainConfig.batch_size ({self.batch_size}) must be a multiple of per_label '
        f'({self.per_label}) with at least two labels per batch for batch_hard.'
      )
    if not 0.0 <= self.val_fraction < 1.0:
      raise ValueError(
        f'TrainConfig.val_fraction must be in [0, 1), got {self.val_fraction}'
      )
    if self.patience < 0 or (self.patience and not self.val_fraction):
      raise ValueError(
        f'TrainConfig.patience ({self.patience}) must be >= 0, and needs '
        'val_fraction > 0 (it counts epochs without a better validation score)'
      )
    if self.learning_rate <= 0:
      raise ValueError(
        f'TrainConfig.learning_rate must be > 0, got {self.learning_rate}'
      )
    if self.select_by == 'retrieval' and (
      self.split != 'simulation' or not self.val_fraction
    ):
      raise ValueError(
        "TrainConfig.select_by='retrieval' needs split='simulation' and "
        f'val_fraction > 0 (got split={self.split!r}, val_fraction={self.val_fraction}): '
        'it retrieves held-out simulations'
      )


@flax.struct.dataclass
class TrainState:
  """Training state (a pytree; checkpointed whole).

  Attributes:
    params: ``{'net': flax params, 'stats': InputStats}``.
    opt_state: optax state of ``params['net']``.
    step: ``()`` int32 number of steps taken.
    key: ``(2,)`` uint32 base key; batches use ``fold_in`` of it.
  """

  params: Any
  opt_state: Any
  step: jax.Array
  key: jax.Array


class FitResult(NamedTuple):
  """What ``fit`` returns.

  Attributes:
    state: the final TrainState.
    network: the network pair.
    train_idx: ``(N_train,)`` indices of the images trained on.
    test_idx: ``(N_test,)`` indices of the held-out images.
    history: the rows written to ``metrics.jsonl`` (all of them, resumed ones too).
    val_idx: ``(N_val,)`` indices of the validation images (empty without).
  """

  state: TrainState
  network: physnet.Network
  train_idx: np.ndarray
  test_idx: np.ndarray
  history: list[dict]
  val_idx: np.ndarray = np.zeros((0,), np.int64)


def make_network(config: TrainConfig) -> physnet.Network:
  """The network named by ``config.network``."""
  if config.network == 'sdn':
    return sdn.make_sdn(config.sdn)
  return physnet.make_physnet(config.physnet)


def item_shape(config: TrainConfig) -> tuple[int, ...]:
  """Shape of one dataset item: ``(H, W, C)`` or ``(T, H, W, C)`` for SDN."""
  if config.network == 'sdn':
    c = config.sdn
    return (c.num_frames, *c.trunk.image_size, c.in_channels)
  return (*config.physnet.image_size, config.physnet.in_channels)


def steps_per_epoch(config: TrainConfig, n_train: int) -> int:
  """Steps in one epoch: ``n_train // batch_size`` (at least one)."""
  return max(1, n_train // config.batch_size)
