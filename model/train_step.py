"""Training's step: the optimizer (Adam, StepLR), the fresh state, the loss of
``TrainConfig.loss``, the pure train step, the batch sampler (pure, keyed by
step: a resumed run draws the same batches), the host gather of its images
and the batch's placement over several devices."""

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax

from model import contrastive, physnet, triplets
from model.train_config import TrainConfig, TrainState


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


def gather(images: np.ndarray, labels: np.ndarray, idx: dict) -> dict:
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
