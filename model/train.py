"""Training: config, TrainState, the jitted train step and the resumable ``fit`` loop.

Defaults follow the original code: Adam (PyTorch's betas and eps equal
optax's), batch 32 triplets, StepLR (x0.1 every 8 epochs), 30 epochs, margin 1,
and lr 1e-3. The paper's text says lr 1e-2 while its code used 1e-3;
``select_lr`` trains both on a by-simulation validation split of the training
data and keeps the one with the higher validation triplet accuracy.

Model selection (off by default, the paper had none): ``val_fraction`` holds
part of the training simulations out as a validation set (split the way the
test set is); after every epoch the validation triplet accuracy is logged and
the best epoch's params are kept in ``best/``, which ``load_network`` returns.
``patience`` ends the run once that many epochs pass without a better one.
Why: on held-out simulations PhySNet peaks after one or two epochs and then
overfits its two dozen training simulations (BENCHMARKS.md), so "the last of
30 epochs" is the wrong network to ship.

An epoch visits every training image once as an anchor (a permutation drawn
from ``fold_in(key, epoch)``); positives and negatives (or pairs, or the P x K
batch of batch-hard mining) come from ``fold_in(key, step)``. A run therefore
resumed from a checkpoint draws exactly the batches the uninterrupted run
would have drawn.

Workdir layout: ``config.json`` (enough to rebuild the network),
``checkpoints/<step>/`` (orbax, TrainState incl. the input stats),
``best/<step>/`` (params of the best validation epoch, with ``val_fraction``)
and ``metrics.jsonl`` (one JSON object per log or evaluation).
"""

import contextlib
import dataclasses
import json
import os
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np
import optax

from model import (
  checkpoint,
  config_io,
  contrastive,
  metrics,
  physnet,
  retrieval,
  sdn,
  splits,
  triplets,
)
from model import progress as progress_lib
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


def make_optimizer(
  config: TrainConfig, epoch_steps: int
) -> tuple[optax.GradientTransformation, optax.Schedule]:
  """Adam with a StepLR schedule.

  Args:
    config: training config.
    epoch_steps: steps per epoch (the schedule counts steps).

  Returns:
    (optimizer, schedule).
  """
  schedule = optax.exponential_decay(
    config.learning_rate,
    transition_steps=config.lr_step_epochs * epoch_steps,
    decay_rate=config.lr_gamma,
    staircase=True,
  )
  return optax.adam(schedule), schedule


def init_state(
  network: physnet.Network,
  optimizer: optax.GradientTransformation,
  key: jax.Array,
  stats: physnet.InputStats | None = None,
) -> TrainState:
  """A fresh TrainState.

  Args:
    network: the network pair.
    optimizer: the optax optimizer.
    key: ``(2,)`` uint32 key; split into the init key and the batch key.
    stats: input statistics (identity if None).

  Returns:
    The state at step 0.
  """
  k_init, k_train = jax.random.split(key)
  params = network.init(k_init)
  if stats is not None:
    params = physnet.with_stats(params, stats)
  return TrainState(
    params, optimizer.init(params['net']), jnp.zeros((), jnp.int32), k_train
  )


def _loss_fn(network: physnet.Network, config: TrainConfig) -> Callable:
  """``loss(net_params, stats, batch) -> (loss, frac_active)`` for ``config.loss``."""

  def loss(net, stats, batch):
    params = {'net': net, 'stats': stats}
    if config.loss == 'triplet':
      x = jnp.concatenate([batch['anchor'], batch['positive'], batch['negative']])
      a, p, n = jnp.split(network.apply(params, x), 3)  # one pass for all three
      return triplets.triplet_loss(a, p, n, config.margin)
    if config.loss == 'batch_hard':
      emb = network.apply(params, batch['images'])
      return triplets.batch_hard_loss(emb, batch['labels'], config.margin)
    x = jnp.concatenate([batch['first'], batch['second']])
    e1, e2 = jnp.split(network.apply(params, x), 2)
    return contrastive.contrastive_loss(e1, e2, batch['same'], config.margin)

  return loss


def make_train_step(
  network: physnet.Network,
  optimizer: optax.GradientTransformation,
  schedule: optax.Schedule,
  config: TrainConfig,
) -> Callable[[TrainState, dict], tuple[TrainState, dict]]:
  """The (unjitted) train step; jit it once at the call site with ``donate_argnums=0``.

  Args:
    network: the network pair.
    optimizer: from ``make_optimizer``.
    schedule: from ``make_optimizer`` (for logging the lr).
    config: training config (``loss`` and ``margin``).

  Returns:
    ``train_step(state, batch) -> (state, metrics)``; ``batch`` holds images
    ``{'anchor', 'positive', 'negative'}`` each ``(B, *item)`` for 'triplet',
    ``{'images' (B, *item), 'labels' (B,)}`` for 'batch_hard', ``{'first',
    'second' (B, *item), 'same' (B,)}`` for 'contrastive'. ``metrics`` has
    scalar 'loss', 'active' (fraction of nonzero hinges), 'grad_norm', 'lr'
    (``fit`` logs their means over each ``log_every`` window).
  """
  loss_fn = _loss_fn(network, config)

  def train_step(state, batch):
    net, stats = state.params['net'], state.params['stats']
    (loss, active), grads = jax.value_and_grad(loss_fn, has_aux=True)(net, stats, batch)
    updates, opt_state = optimizer.update(grads, state.opt_state, net)
    net = optax.apply_updates(net, updates)
    new = state.replace(
      params={'net': net, 'stats': stats}, opt_state=opt_state, step=state.step + 1
    )
    out = {
      'loss': loss,
      'active': active,
      'grad_norm': optax.tree.norm(grads),
      'lr': schedule(state.step),
    }
    return new, out

  return train_step


def make_sampler(config: TrainConfig, labels: np.ndarray, epoch_steps: int) -> Callable:
  """``sample(key, step) -> dict of index arrays`` for ``config.loss`` (pure, jittable).

  Args:
    config: training config.
    labels: ``(N_train,)`` int labels of the training set.
    epoch_steps: steps per epoch.

  Returns:
    The sampler; indices point into the training set.
  """
  labels = jnp.asarray(labels, jnp.int32)
  unique = jnp.asarray(np.unique(np.asarray(labels)), jnp.int32)
  n, b = labels.shape[0], config.batch_size

  def sample(key, step):
    epoch, i = step // epoch_steps, step % epoch_steps
    k_step = jax.random.fold_in(jax.random.fold_in(key, 1), step)
    if config.loss == 'batch_hard':
      p = b // config.per_label
      return {'images': triplets.pk_batch(k_step, labels, unique, p, config.per_label)}
    perm = jax.random.permutation(
      jax.random.fold_in(jax.random.fold_in(key, 0), epoch), n
    )
    # An epoch shorter than one batch (tiny sets) wraps around the permutation.
    anchors = jnp.take(perm, (i * b + jnp.arange(b)) % n)
    if config.loss == 'triplet':
      return triplets.random_triplets(k_step, labels, anchors)._asdict()
    return contrastive.random_pairs(k_step, labels, anchors)._asdict()

  return sample


def _gather(images: np.ndarray, labels: np.ndarray, idx: dict) -> dict:
  """Host gather of the batch images named by sampler indices."""
  idx = {k: np.asarray(v) for k, v in idx.items()}
  if 'images' in idx:
    return {'images': images[idx['images']], 'labels': labels[idx['images']]}
  if 'anchor' in idx:
    return {k: images[idx[k]] for k in ('anchor', 'positive', 'negative')}
  return {
    'first': images[idx['first']],
    'second': images[idx['second']],
    'same': idx['same'],
  }


def _check_data(images, labels, groups, config: TrainConfig):
  images = np.asarray(images, dtype=np.float32)
  want = item_shape(config)
  if images.ndim != len(want) + 1 or images.shape[1:] != want:
    raise ValueError(
      f'images must have shape (N, {", ".join(map(str, want))}) for this config, got {images.shape}.'
    )
  labels = triplets.check_labels(labels)
  groups = labels if groups is None else np.asarray(groups)
  if labels.shape[0] != images.shape[0] or groups.shape != labels.shape:
    raise ValueError(
      f'images ({images.shape[0]}), labels {labels.shape} and groups {groups.shape} disagree in length.'
    )
  if not np.all(np.isfinite(images)):
    raise ValueError('images contain NaN or inf.')
  return images, labels, groups


def _prepare_workdir(workdir: str, config: TrainConfig) -> None:
  """Writes config.json; refuses a workdir whose run used a different config."""
  os.makedirs(workdir, exist_ok=True)
  path = os.path.join(workdir, CONFIG_FILE)
  if os.path.exists(path):
    old = config_io.to_dict(
      config_io.from_dict(TrainConfig, config_io.read_json(path), path)
    )
    new = config_io.to_dict(config)
    diff = sorted(k for k in new if k not in RESUMABLE_FIELDS and new[k] != old.get(k))
    if diff:
      raise ValueError(
        f'{path} belongs to a run with different {diff}; use a new workdir.'
      )
  config_io.write_json(path, config_io.to_dict(config))


def _read_history(workdir: str, max_step: int) -> list[dict]:
  """Rows of metrics.jsonl up to ``max_step``; rewrites the file without later rows."""
  path = os.path.join(workdir, METRICS_FILE)
  if not os.path.exists(path):
    return []
  with open(path) as f:
    rows = [json.loads(line) for line in f if line.strip()]
  rows = [r for r in rows if r.get('step', 0) <= max_step]
  tmp = path + '.tmp'
  with open(tmp, 'w') as f:
    f.writelines(json.dumps(r) + '\n' for r in rows)
  os.replace(tmp, path)
  return rows


def evaluate(
  network: physnet.Network,
  params,
  images: np.ndarray,
  labels: np.ndarray,
  train_idx: np.ndarray,
  test_idx: np.ndarray,
  config: TrainConfig,
) -> dict:
  """Held-out metrics: triplet accuracy on the test set; k-NN accuracy under the random split.

  Args:
    network: the network pair.
    params: its params.
    images: ``(N, *item)`` all images.
    labels: ``(N,)``.
    train_idx: training indices (k-NN reference set).
    test_idx: held-out indices.
    config: training config (seed, eval sizes, split).

  Returns:
    ``{'test_triplet_accuracy', 'test_knn_accuracy'}`` (the latter only for
    the random split; a metric is left out when the test set cannot support it).
  """
  out = {}
  if test_idx.size == 0:
    return out
  key = jax.random.fold_in(jax.random.PRNGKey(config.seed), 7)
  emb = metrics.embed(network.apply, params, images[test_idx], config.eval_batch_size)
  if np.unique(labels[test_idx]).size >= 2:
    out['test_triplet_accuracy'] = metrics.triplet_accuracy(
      key, emb, labels[test_idx], config.eval_triplets
    )
  if config.split == 'random':
    ref = metrics.embed(
      network.apply, params, images[train_idx], config.eval_batch_size
    )
    k = min(config.knn_k, train_idx.size)
    out['test_knn_accuracy'] = metrics.knn_accuracy(
      ref, labels[train_idx], emb, labels[test_idx], k
    )
  return out


def split_indices(
  config: TrainConfig, labels, groups=None
) -> tuple[np.ndarray, np.ndarray]:
  """The (train, test) split ``fit`` uses for this config (reproducible from the seed).

  Args:
    config: training config (``seed``, ``split``, ``test_fraction``).
    labels: ``(N,)`` int labels.
    groups: ``(N,)`` group ids for the 'simulation' split (None: labels).

  Returns:
    (train, test) sorted index arrays.
  """
  labels = np.asarray(labels)
  groups = labels if groups is None else np.asarray(groups)
  k_split = jax.random.split(jax.random.PRNGKey(config.seed))[0]
  return splits.split(k_split, config.split, labels, groups, config.test_fraction)


def validation_split(
  config: TrainConfig, labels, groups, train_idx
) -> tuple[np.ndarray, np.ndarray]:
  """(fit, validation) indices: ``val_fraction`` of the training part held out.

  The validation set is drawn from ``train_idx`` only, the way the test set
  was drawn (whole groups, or single images under the 'random' split), so
  choosing an epoch by it never looks at the test set.

  Args:
    config: training config (``seed``, ``split``, ``val_fraction``).
    labels: ``(N,)`` int labels of all images.
    groups: ``(N,)`` group ids (None: labels).
    train_idx: the training part of ``split_indices``.

  Returns:
    (fit, validation) sorted index arrays into ``labels``; validation is
    empty when ``val_fraction`` is 0.
  """
  train_idx = np.asarray(train_idx)
  if not config.val_fraction:
    return train_idx, np.zeros((0,), np.int64)
  labels = np.asarray(labels)
  groups = labels if groups is None else np.asarray(groups)
  kind = 'random' if config.split == 'random' else 'simulation'
  key = jax.random.fold_in(jax.random.PRNGKey(config.seed), 11)
  fit_part, val_part = splits.split(
    key, kind, labels[train_idx], groups[train_idx], config.val_fraction
  )
  fit_idx, val_idx = train_idx[fit_part], train_idx[val_part]
  if np.unique(labels[val_idx]).size < 2:
    raise ValueError(
      f'val_fraction={config.val_fraction} leaves '
      f'{np.unique(labels[val_idx]).size} label(s) for validation; triplets need '
      '>= 2 (more simulations or a larger val_fraction)'
    )
  return fit_idx, val_idx


def _selection_score(row: dict, config: TrainConfig) -> float:
  """The validation score of an eval row under ``config.select_by`` (higher is better)."""
  if config.select_by == 'triplet':
    return row['val_triplet_accuracy']
  if 'val_retrieval' not in row:
    raise ValueError(
      "select_by='retrieval': no validation clip has a training clip of its camera"
    )
  return -row['val_retrieval']['error']


def _val_score(row: dict) -> float | None:
  # Runs logged before 'val_score' existed selected by triplet accuracy.
  return row.get('val_score', row.get('val_triplet_accuracy'))


def best_epoch(history: Sequence[dict]) -> dict | None:
  """The eval row with the best validation score (``TrainConfig.select_by``;
  the first of equals: the one whose params are in ``best/``), or None without
  validation."""
  rows = [r for r in history if _val_score(r) is not None]
  return max(rows, key=_val_score) if rows else None


def selected_eval(history: Sequence[dict]) -> dict:
  """The eval row of the params ``load_network`` returns: the best validation
  epoch's with validation, else the last epoch's ({} before any)."""
  best = best_epoch(history)
  if best is not None:
    return best
  evals = [r for r in history if r.get('eval')]
  return evals[-1] if evals else {}


def stopped_early(history: Sequence[dict], patience: int) -> bool:
  """Whether ``patience`` epochs have passed since the best validation epoch."""
  best = best_epoch(history)
  if not patience or best is None:
    return False
  last = max(r['epoch'] for r in history if r.get('eval'))
  return last - best['epoch'] >= patience


def read_evals(workdir: str) -> list[dict]:
  """The eval rows of a run's ``metrics.jsonl`` ([] without the file); reads only."""
  path = os.path.join(workdir, METRICS_FILE)
  if not os.path.isfile(path):
    return []
  with open(path) as f:
    return [r for r in map(json.loads, filter(str.strip, f)) if r.get('eval')]


def ended(evals: Sequence[dict], epochs: int, patience: int) -> bool:
  """Whether a run with these eval rows is over: it reached ``epochs`` or
  stopped early."""
  return bool(evals) and (
    evals[-1]['epoch'] >= epochs or stopped_early(evals, patience)
  )


def _val_accuracy(network, params, images, labels, val_idx, config) -> float:
  key = jax.random.fold_in(jax.random.PRNGKey(config.seed), 13)
  emb = metrics.embed(network.apply, params, images[val_idx], config.eval_batch_size)
  return metrics.triplet_accuracy(key, emb, labels[val_idx], config.eval_triplets)


def evaluate_retrieval(
  network, params, images, videos: retrieval.Videos, fit_idx, val_idx, test_idx, config
) -> dict:
  """Parameter retrieval of the validation and test simulations among the
  training ones (``model.retrieval``): ``{'val_retrieval': summary,
  'test_retrieval': summary}``, each left out without queries."""
  used = np.concatenate([fit_idx, val_idx, test_idx])
  part = metrics.embed(network.apply, params, images[used], config.eval_batch_size)
  emb = np.zeros((len(images), part.shape[1]), np.float32)
  emb[used] = part
  out = {}
  for name, idx in (('val', val_idx), ('test', test_idx)):
    if scores := retrieval.score(emb, videos, idx, fit_idx):
      out[f'{name}_retrieval'] = scores
  return out


def data_parallel(batch_size: int, devices=None):
  """(batch sharding, replicated sharding) that split a training batch over
  ``devices`` (default: every local device) and keep the state whole on each,
  or None with one device or a batch the device count does not divide.

  The train step is jitted once; given inputs placed this way, XLA runs each
  device's share of the batch and sums the gradients across devices, so the
  update is the one-device update of the same global batch."""
  devices = list(devices) if devices is not None else jax.local_devices()
  if len(devices) < 2 or batch_size % len(devices):
    return None
  mesh = jax.sharding.Mesh(np.array(devices), ('batch',))
  return (
    jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec('batch')),
    jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec()),
  )


def fit(
  images,
  labels,
  groups,
  config: TrainConfig,
  workdir: str,
  *,
  progress: bool = True,
  videos: retrieval.Videos | None = None,
  devices=None,
  after_epoch: Callable[[float], None] | None = None,
) -> FitResult:
  """Trains (or resumes training) a network and evaluates it after every epoch.

  Args:
    images: ``(N, H, W, C)`` float32 (``(N, T, H, W, C)`` clips for SDN).
    labels: ``(N,)`` int: one simulation's parameter set.
    groups: ``(N,)`` int group ids for the 'simulation' split (None: labels).
    config: training config.
    workdir: run folder; an existing checkpoint there is resumed.
    progress: show a progress bar on stderr (tqdm's on a terminal; in a log,
      a line every 5%: model.progress).
    videos: clip ids, cameras and true parameters of the items; with the
      'simulation' split, every eval row then also holds the parameter
      retrieval of the validation and test simulations (``evaluate_retrieval``).
      Needed by ``select_by='retrieval'``.
    devices: the devices a batch is split over (``data_parallel``; default
      every local device).
    after_epoch: called with the epoch's seconds once each epoch but the last
      is checkpointed; an exception it raises stops the fit there, and the same
      call resumes (a script's ``--time_limit``).

  Returns:
    ``FitResult``.
  """
  images, labels, groups = _check_data(images, labels, groups, config)
  if videos is not None:
    videos = retrieval.check_videos(videos, len(images))
  if config.select_by == 'retrieval' and videos is None:
    raise ValueError("TrainConfig.select_by='retrieval' needs fit(videos=...)")
  _prepare_workdir(workdir, config)
  k_state = jax.random.split(jax.random.PRNGKey(config.seed))[1]
  train_idx, test_idx = split_indices(config, labels, groups)
  train_idx, val_idx = validation_split(config, labels, groups, train_idx)
  train_images, train_labels = images[train_idx], labels[train_idx]
  triplets.check_labels(train_labels, 'training labels')

  network = make_network(config)
  epoch_steps = steps_per_epoch(config, train_idx.size)
  optimizer, schedule = make_optimizer(config, epoch_steps)
  stats = physnet.compute_stats(train_images)
  init = lambda key: init_state(network, optimizer, key, stats)
  with (
    checkpoint.manager(workdir, config.max_to_keep) as mngr,
    (
      checkpoint.manager(workdir, 1, BEST_DIR)
      if val_idx.size
      else contextlib.nullcontext()
    ) as best_mngr,
  ):
    # An existing checkpoint wins; the target is only shapes, so nothing is initialised.
    state = checkpoint.restore(mngr, jax.eval_shape(init, k_state))
    if state is None:
      # Eager, not jitted: op-by-op compiles are cached across fits, while a
      # jitted init recompiles for every new network (2-3 s each on a CPU); the
      # values are the same bits.
      state, history = init(k_state), []
    else:
      history = _read_history(workdir, int(state.step))
    train_step = jax.jit(
      make_train_step(network, optimizer, schedule, config), donate_argnums=0
    )
    sample = jax.jit(make_sampler(config, train_labels, epoch_steps))
    parallel = data_parallel(config.batch_size, devices)
    if parallel is not None:
      state = jax.device_put(state, parallel[1])
    place = (
      (lambda b: b) if parallel is None else (lambda b: jax.device_put(b, parallel[0]))
    )
    total = config.epochs * epoch_steps
    # A run that already stopped early (and is called again) does nothing.
    start = total if stopped_early(history, config.patience) else int(state.step)
    log_path = os.path.join(workdir, METRICS_FILE)
    t0 = t_epoch = time.perf_counter()
    with (
      open(log_path, 'a') as log,
      progress_lib.bar(total, 'fit', initial=start, disable=not progress) as bar,
    ):

      def write(row):
        history.append(row)
        log.write(json.dumps(row) + '\n')
        log.flush()

      window, count = None, 0  # running sums on device: no host sync per step
      for step in range(start, total):
        batch = place(_gather(train_images, train_labels, sample(state.key, step)))
        state, m = train_step(state, batch)
        window = m if window is None else jax.tree.map(jnp.add, window, m)
        count += 1
        bar.update(1)
        # Windows also end at epoch ends, so a resumed run logs the same rows.
        if (step + 1) % config.log_every == 0 or (step + 1) % epoch_steps == 0:
          m = {k: float(v) / count for k, v in window.items()}
          window, count = None, 0
          bar.set_postfix(loss=f'{m["loss"]:.4f}')
          row = {'step': step + 1, 'epoch': (step + 1) / epoch_steps}
          write({**row, 'time': time.perf_counter() - t0, **m})
        if (step + 1) % epoch_steps == 0:
          row = evaluate(
            network, state.params, images, labels, train_idx, test_idx, config
          )
          if videos is not None and config.split == 'simulation':
            row.update(
              evaluate_retrieval(
                network, state.params, images, videos, train_idx, val_idx,
                test_idx, config,
              )
            )  # fmt: skip
          if val_idx.size:
            acc = _val_accuracy(network, state.params, images, labels, val_idx, config)
            row['val_triplet_accuracy'] = acc
            row['val_score'] = _selection_score(row, config)
            best = best_epoch(history)
            if best is None or row['val_score'] > _val_score(best):
              # Before the row: a crash in between redoes this epoch and saves again.
              checkpoint.save(best_mngr, step + 1, state.params)
          write(
            {'step': step + 1, 'epoch': (step + 1) // epoch_steps, 'eval': True, **row}
          )
          checkpoint.save(mngr, step + 1, state)
          if stopped_early(history, config.patience):
            break
          if after_epoch is not None and step + 1 < total:
            after_epoch(time.perf_counter() - t_epoch)
          t_epoch = time.perf_counter()
  return FitResult(state, network, train_idx, test_idx, history, val_idx)


def select_lr(
  images,
  labels,
  groups,
  config: TrainConfig,
  workdir: str,
  candidates: Sequence[float] = (1e-2, 1e-3),
  *,
  progress: bool = True,
) -> tuple[float, dict[float, float]]:
  """Chooses the learning rate by validation triplet accuracy on held-out simulations.

  Pass the *training* portion only: each candidate is trained with ``fit`` on
  a by-simulation split of it (``groups``; use labels to hold out whole
  simulations) in ``workdir/lr_<lr>``, and scored by its last validation
  triplet accuracy.

  Args:
    images: training images.
    labels: their labels.
    groups: their group ids.
    config: base config (its ``learning_rate`` and ``split`` are overridden).
    workdir: parent folder of the candidate runs.
    candidates: learning rates to try (default: the paper's and the code's).
    progress: show progress bars.

  Returns:
    (best lr, {lr: validation triplet accuracy}).
  """
  scores = {}
  for lr in candidates:
    cfg = dataclasses.replace(
      config, learning_rate=float(lr), split='simulation', val_fraction=0.0,
      patience=0,
    )  # fmt: skip
    result = fit(
      images,
      labels,
      groups,
      cfg,
      os.path.join(workdir, f'lr_{lr:g}'),
      progress=progress,
    )
    evals = [r for r in result.history if 'test_triplet_accuracy' in r]
    if not evals:
      raise ValueError('select_lr: the validation split has fewer than two labels.')
    scores[float(lr)] = evals[-1]['test_triplet_accuracy']
  return max(scores, key=scores.get), scores


def load_network(
  workdir: str, step: int | None = None, *, best: bool = True
) -> tuple[physnet.Network, Any, TrainConfig]:
  """Rebuilds the network from ``config.json`` and restores its params.

  Args:
    workdir: a ``fit`` run folder.
    step: checkpoint step (None: the best validation epoch's params if the run
      kept them and ``best``, else the latest).
    best: see ``step``.

  Returns:
    (network, params incl. input stats, config).
  """
  path = os.path.join(workdir, CONFIG_FILE)
  if not os.path.exists(path):
    raise ValueError(f'{path} does not exist: not a fit workdir.')
  config = config_io.from_dict(TrainConfig, config_io.read_json(path), path)
  network = make_network(config)
  optimizer, _ = make_optimizer(config, 1)  # the schedule's values are not in the state
  channels = (
    config.sdn.in_channels if config.network == 'sdn' else config.physnet.in_channels
  )
  stats = physnet.identity_stats(channels)
  target = jax.eval_shape(
    lambda: init_state(network, optimizer, jax.random.PRNGKey(0), stats)
  )
  if step is None and best and os.path.isdir(os.path.join(workdir, BEST_DIR)):
    with checkpoint.manager(workdir, None, BEST_DIR) as mngr:
      params = checkpoint.restore(mngr, target.params)
    if params is not None:
      return network, params, config
  with checkpoint.manager(workdir, None) as mngr:
    state = checkpoint.restore(mngr, target, step)
  if state is None:
    raise ValueError(
      f'no checkpoint under {os.path.join(workdir, checkpoint.CHECKPOINT_DIR)}.'
    )
  return network, state.params, config
