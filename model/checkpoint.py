"""Checkpoints under ``workdir/checkpoints/<step>/``, restored against a target tree.

Orbax writes them. Under ``jax.distributed`` (several processes, each training
its own networks: Table 1's share of a multi-GPU run) orbax's multi-host model
does not fit, since it writes one checkpoint shared by all processes (NumPy
leaves from process 0 only, process-local arrays refused); there each process
writes its own as flax msgpack (``<step>/state.msgpack``, written atomically).
``restore`` reads either.
"""

from __future__ import annotations

import os
import re
import shutil
from typing import TYPE_CHECKING, Any

import jax
import numpy as np
from flax import serialization

if TYPE_CHECKING:
  import orbax.checkpoint as ocp

_MSGPACK = 'state.msgpack'

CHECKPOINT_DIR = 'checkpoints'


def _orbax():
  """``orbax.checkpoint``, imported on first use (half a second of imports an
  estimate without a network does not need)."""
  import orbax.checkpoint

  return orbax.checkpoint


class LocalManager:
  """This process's own checkpoints (``jax.distributed`` runs), with the part
  of ``ocp.CheckpointManager``'s interface the project uses."""

  def __init__(self, directory: str, max_to_keep: int | None):
    self.directory = directory
    self.max_to_keep = max_to_keep
    os.makedirs(directory, exist_ok=True)

  def all_steps(self) -> list[int]:
    # Step folders: this process's msgpack ones, or orbax's (read only).
    return sorted(int(d) for d in os.listdir(self.directory) if re.fullmatch(r'\d+', d))

  def latest_step(self) -> int | None:
    steps = self.all_steps()
    return steps[-1] if steps else None

  def save(self, step: int, state: Any) -> None:
    folder = os.path.join(self.directory, str(int(step)))
    os.makedirs(folder, exist_ok=True)
    data = serialization.msgpack_serialize(
      serialization.to_state_dict(jax.device_get(state))
    )
    tmp = os.path.join(folder, f'.{_MSGPACK}.tmp')
    with open(tmp, 'wb') as f:
      f.write(data)
    os.replace(tmp, os.path.join(folder, _MSGPACK))
    if self.max_to_keep:
      for old in self.all_steps()[: -self.max_to_keep]:
        shutil.rmtree(os.path.join(self.directory, str(old)))

  def restore(self, step: int, target: Any) -> Any:
    with open(os.path.join(self.directory, str(int(step)), _MSGPACK), 'rb') as f:
      raw = serialization.msgpack_restore(f.read())
    out = serialization.from_state_dict(target, raw)
    return jax.tree.map(
      lambda t, v: np.asarray(v, dtype=getattr(t, 'dtype', None)), target, out
    )

  def __enter__(self):
    return self

  def __exit__(self, *exc):
    return False

  def close(self) -> None:
    pass


def manager(
  workdir: str, max_to_keep: int | None = 2, subdir: str = CHECKPOINT_DIR
) -> ocp.CheckpointManager | LocalManager:
  """A checkpoint manager for ``workdir/<subdir>`` (created if missing).

  Args:
    workdir: run folder.
    max_to_keep: number of newest checkpoints kept (None keeps all).
    subdir: the folder under ``workdir``.

  Returns:
    The manager; close it (or use it as a context manager) when done.
  """
  path = os.path.join(os.path.abspath(workdir), subdir)
  if jax.process_count() > 1:
    return LocalManager(path, max_to_keep)
  ocp = _orbax()
  options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, create=True)
  return ocp.CheckpointManager(path, options=options)


def save(mngr: ocp.CheckpointManager, step: int, state: Any) -> None:
  """Saves ``state`` (any pytree) at ``step`` and waits for the write to finish."""
  if isinstance(mngr, LocalManager):
    mngr.save(step, state)
    return
  ocp = _orbax()
  mngr.save(int(step), args=ocp.args.StandardSave(state), force=True)
  mngr.wait_until_finished()


def _on_this_device(target: Any) -> Any:
  """``target``'s shapes and dtypes, on this process's first device."""
  here = jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
  return jax.tree.map(
    lambda t: jax.ShapeDtypeStruct(t.shape, t.dtype, sharding=here), target
  )


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
  ocp = _orbax()
  try:
    if os.path.isfile(os.path.join(str(mngr.directory), str(int(step)), _MSGPACK)):
      return LocalManager(str(mngr.directory), None).restore(step, target)
    if isinstance(mngr, LocalManager):
      # An orbax checkpoint (written by one process) read in a multi-process
      # run: onto this process's own device.
      target = _on_this_device(target)
      with ocp.CheckpointManager(mngr.directory) as orbax_mngr:
        return orbax_mngr.restore(int(step), args=ocp.args.StandardRestore(target))
    try:
      return mngr.restore(int(step), args=ocp.args.StandardRestore(target))
    except ValueError as e:
      if 'topology' not in str(e).lower():
        raise
      # Saved from other devices (the scripts make one CPU device per core, a
      # training may run over several GPUs): onto this process's first device.
      target = _on_this_device(target)
      return mngr.restore(int(step), args=ocp.args.StandardRestore(target))
  except Exception as e:  # noqa: BLE001 - orbax raises many kinds for a bad file
    raise ValueError(
      f'{mngr.directory}: checkpoint step {step} cannot be read, corrupt or from '
      f'another network ({type(e).__name__}: {str(e).splitlines()[0][:200]})'
    ) from e
