"""Orbax checkpoints under ``workdir/checkpoints/<step>/``, restored against a target tree."""

import os
from typing import Any

import orbax.checkpoint as ocp

CHECKPOINT_DIR = 'checkpoints'


def manager(
  workdir: str, max_to_keep: int | None = 2, subdir: str = CHECKPOINT_DIR
) -> ocp.CheckpointManager:
  """A checkpoint manager for ``workdir/<subdir>`` (created if missing).

  Args:
    workdir: run folder.
    max_to_keep: number of newest checkpoints kept (None keeps all).
    subdir: the folder under ``workdir``.

  Returns:
    The manager; close it (or use it as a context manager) when done.
  """
  path = os.path.join(os.path.abspath(workdir), subdir)
  options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, create=True)
  return ocp.CheckpointManager(path, options=options)


def save(mngr: ocp.CheckpointManager, step: int, state: Any) -> None:
  """Saves ``state`` (any pytree) at ``step`` and waits for the write to finish."""
  mngr.save(int(step), args=ocp.args.StandardSave(state), force=True)
  mngr.wait_until_finished()


def restore(
  mngr: ocp.CheckpointManager, target: Any, step: int | None = None
) -> Any | None:
  """Restores into the structure, shapes and dtypes of ``target``.

  Args:
    mngr: the manager.
    target: a pytree of arrays or ``jax.ShapeDtypeStruct`` (e.g. from
      ``jax.eval_shape(init, key)``) with the saved structure.
    step: the step to restore; the latest if None.

  Returns:
    The restored pytree, or None when there is no checkpoint.
  """
  step = mngr.latest_step() if step is None else step
  if step is None:
    return None
  try:
    return mngr.restore(int(step), args=ocp.args.StandardRestore(target))
  except Exception as e:  # noqa: BLE001 - orbax raises many kinds for a bad file
    raise ValueError(
      f'{mngr.directory}: checkpoint step {step} cannot be read, corrupt or from '
      f'another network ({type(e).__name__}: {str(e).splitlines()[0][:200]})'
    ) from e
