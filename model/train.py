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

The settings and state are in ``train_config``, the step (optimizer, loss,
sampler) in ``train_step``, evaluation and model selection in ``train_eval``;
this module runs them: the run folder, the loop, learning-rate selection and
loading a trained network. Their public names are importable from here.
"""

import contextlib
import dataclasses
import json
import os
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from model import checkpoint, config_io, physnet, retrieval, triplets
from model import progress as progress_lib
from model.train_config import (
  BEST_DIR,
  CONFIG_FILE,
  LOSSES,
  METRICS_FILE,
  NETWORKS,
  RESUMABLE_FIELDS,
  SELECT_BY,
  FitResult,
  TrainConfig,
  TrainState,
  item_shape,
  make_network,
  steps_per_epoch,
)
from model.train_eval import (
  best_epoch,
  ended,
  evaluate,
  evaluate_retrieval,
  read_evals,
  selected_eval,
  selection_score,
  split_indices,
  stopped_early,
  val_accuracy,
  val_score,
  validation_split,
)
from model.train_step import (
  data_parallel,
  gather,
  init_state,
  make_optimizer,
  make_sampler,
  make_train_step,
)

__all__ = [
  'BEST_DIR', 'CONFIG_FILE', 'LOSSES', 'METRICS_FILE', 'NETWORKS',
  'RESUMABLE_FIELDS', 'SELECT_BY', 'FitResult', 'TrainConfig', 'TrainState',
  'best_epoch', 'data_parallel', 'ended', 'evaluate', 'evaluate_retrieval', 'fit',
  'init_state', 'item_shape', 'load_network', 'make_network', 'make_optimizer',
  'make_sampler', 'make_train_step', 'read_evals', 'select_lr', 'selected_eval',
  'split_indices', 'steps_per_epoch', 'stopped_early', 'validation_split',
]  # fmt: skip
# The batch gather under the name the tests call it by.
_gather = gather


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


class _Data(NamedTuple):
  """A fit's images and its split (indices into ``images``)."""

  images: np.ndarray  # (N, *item) float32
  labels: np.ndarray  # (N,) int
  train_idx: np.ndarray  # (N_train,) the images trained on
  val_idx: np.ndarray  # (N_val,) validation (empty without)
  test_idx: np.ndarray  # (N_test,) held out
  videos: retrieval.Videos | None


class _Loop(NamedTuple):
  """What a fit's steps run: the network, the jitted step and sampler, the
  batch's placement and the step counts."""

  network: physnet.Network
  train_step: Callable  # jitted, donates the state
  sample: Callable  # jitted: (key, step) -> index arrays
  batch: Callable  # sampled indices -> the batch's images, on the devices
  epoch_steps: int
  total: int  # epochs * epoch_steps


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
  data = _Data(images, labels, train_idx, val_idx, test_idx, videos)
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
    loop, state = _make_loop(
      network, (optimizer, schedule), config, (train_images, train_labels),
      epoch_steps, state, devices,
    )  # fmt: skip
    state = _steps(
      loop, state, history, data, config, workdir, (mngr, best_mngr), progress,
      after_epoch,
    )  # fmt: skip
  return FitResult(state, network, train_idx, test_idx, history, val_idx)


def _make_loop(network, optimizer: tuple, config: TrainConfig, train: tuple,
               epoch_steps: int, state: TrainState,
               devices) -> tuple[_Loop, TrainState]:  # fmt: skip
  """The fit's jitted step and sampler, and its batches placed over
  ``devices`` (``data_parallel``; ``state`` replicated there, returned).
  ``optimizer``: (optimizer, schedule); ``train``: (images, labels)."""
  train_step = jax.jit(make_train_step(network, *optimizer, config), donate_argnums=0)
  train_images, train_labels = train
  sample = jax.jit(make_sampler(config, train_labels, epoch_steps))
  parallel = data_parallel(config.batch_size, devices)
  if parallel is not None:
    state = jax.device_put(state, parallel[1])
  place = (
    (lambda b: b) if parallel is None else (lambda b: jax.device_put(b, parallel[0]))
  )
  batch = lambda idx: place(gather(train_images, train_labels, idx))
  loop = _Loop(
    network, train_step, sample, batch, epoch_steps, config.epochs * epoch_steps
  )
  return loop, state


def _steps(loop: _Loop, state: TrainState, history: list, data: _Data,
           config: TrainConfig, workdir: str, managers: tuple, progress: bool,
           after_epoch) -> TrainState:  # fmt: skip
  """Runs the fit's steps from ``state``'s on: logs each window's mean
  metrics, evaluates and checkpoints at each epoch's end (``managers``: the
  run's and the best epoch's), and stops early; appends the rows written to
  ``history``. Returns the last state."""
  mngr, best_mngr = managers
  total, epoch_steps = loop.total, loop.epoch_steps
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
      state, m = loop.train_step(state, loop.batch(loop.sample(state.key, step)))
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
        row, best = _epoch_row(loop.network, state.params, data, config, history)
        if best:
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
  return state


def _epoch_row(network, params, data: _Data, config: TrainConfig,
               history: list) -> tuple[dict, bool]:  # fmt: skip
  """An epoch's eval row: held-out metrics, retrieval (with ``videos`` under
  the 'simulation' split) and the validation score; and whether this epoch's
  params beat the best so far."""
  row = evaluate(
    network, params, data.images, data.labels, data.train_idx, data.test_idx, config
  )
  if data.videos is not None and config.split == 'simulation':
    row.update(
      evaluate_retrieval(
        network, params, data.images, data.videos, data.train_idx, data.val_idx,
        data.test_idx, config,
      )
    )  # fmt: skip
  if data.val_idx.size:
    row['val_triplet_accuracy'] = val_accuracy(
      network, params, data.images, data.labels, data.val_idx, config
    )
    row['val_score'] = selection_score(row, config)
    best = best_epoch(history)
    return row, best is None or row['val_score'] > val_score(best)
  return row, False


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
