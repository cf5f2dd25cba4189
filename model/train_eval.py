"""Training's evaluation and model selection: the (train, test) and
validation splits, held-out triplet and k-NN accuracy, parameter retrieval,
and which epoch's params a run keeps (``best_epoch``) and when it ends."""

import json
import os
from collections.abc import Sequence

import jax
import numpy as np

from model import metrics, physnet, retrieval, splits
from model.train_config import METRICS_FILE, TrainConfig


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


def selection_score(row: dict, config: TrainConfig) -> float:
  """The validation score of an eval row under ``config.select_by`` (higher is better)."""
  if config.select_by == 'triplet':
    return row['val_triplet_accuracy']
  if 'val_retrieval' not in row:
    raise ValueError(
      "select_by='retrieval': no validation clip has a training clip of its camera"
    )
  return -row['val_retrieval']['error']


def val_score(row: dict) -> float | None:
  # Runs logged before 'val_score' existed selected by triplet accuracy.
  return row.get('val_score', row.get('val_triplet_accuracy'))


def best_epoch(history: Sequence[dict]) -> dict | None:
  """The eval row with the best validation score (``TrainConfig.select_by``;
  the first of equals: the one whose params are in ``best/``), or None without
  validation."""
  rows = [r for r in history if val_score(r) is not None]
  return max(rows, key=val_score) if rows else None


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


def val_accuracy(network, params, images, labels, val_idx, config) -> float:
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
