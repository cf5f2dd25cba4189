"""Batches of worlds over the local devices: the world mesh and the memory budget.

A batch of worlds (simulations, rendered videos, candidates of a search) is
split along its leading axis over a 1-D ``jax.sharding.Mesh`` of this process's
devices, axis ``'worlds'``. ``shard_worlds`` wraps a traceable per-batch
function in ``shard_map``: every device runs the same program on its share, so
MuJoCo Warp's kernels, the ray-caster and the network each see a per-device
batch and only the results travel. The same code runs on one device (no
``shard_map`` at all), on every GPU of a machine, and on forced host CPU
devices (``--xla_force_host_platform_device_count``, as the tests do). Across
processes (``jax.distributed``) each process shards its own jobs over its own
devices.

``on_host`` keeps the small eager work around those programs (set-up,
stacking, read-out) on the CPU. ``chunk_size`` turns free device memory into a
batch size, so stages that loop over chunks (rendering a sweep, scoring
candidates) size them from what the device has rather than from a constant.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

AXIS = 'worlds'
# Share of free memory a chunk may take (the rest: XLA's own buffers, the
# arrays a stage keeps, fragmentation).
MEMORY_SHARE = 0.5

try:  # jax >= 0.7 exports it at the top level
  _shard_map = jax.shard_map
except AttributeError:  # pragma: no cover - older jax
  from jax.experimental.shard_map import shard_map as _shard_map


def world_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:
  """A 1-D mesh (axis ``'worlds'``) over ``devices`` (default: every device
  of this process on the default backend)."""
  devices = list(devices) if devices is not None else jax.local_devices()
  if not devices:
    raise ValueError('no devices to build a mesh over')
  return Mesh(np.array(devices), (AXIS,))


# On a GPU a MuJoCo Warp step of up to this many worlds costs one step's fixed
# time, its kernel launches and the solver's loops (BENCHMARKS.md: 48 worlds
# as fast as 24 on an H200): a batch this small gains nothing from a second
# device and pays its set-up (Warp's buffers, the frame's graph, the program).
FLAT_WORLDS = 48


def mesh_for(mesh: Mesh | None, n_worlds: int) -> Mesh | None:
  """The mesh a batch of ``n_worlds`` runs on: ``mesh``, or its first device
  alone when the batch is at most ``FLAT_WORLDS`` worlds."""
  if mesh is None or mesh.devices.size == 1 or n_worlds > FLAT_WORLDS:
    return mesh
  return world_mesh([mesh.devices.flat[0]])


def host() -> jax.Device:
  """This process's first CPU device (under ``jax.distributed``, its own)."""
  return jax.local_devices(backend='cpu')[0]


def on_host():
  """A context in which arrays made without a device land on the host's CPU
  (``jax.default_device``), for a stage's small set-up and read-out work: on a
  GPU every eager operation compiles a program of its own, in every process
  and far slower than a CPU compiles it, and an estimate makes many. Programs
  placed explicitly (``place``) still run where they are placed."""
  return jax.default_device(host())


def mesh_key(mesh: Mesh | None) -> tuple:
  """A hashable identity of a mesh (its device ids), for caches of programs."""
  return () if mesh is None else tuple(d.id for d in mesh.devices.flat)


def padded(n: int, k: int) -> int:
  """The smallest multiple of ``k`` that is at least ``n``."""
  return k * math.ceil(n / k)


def _pad_rows(x, n_pad: int):
  """``x`` with its last row repeated to ``n_pad`` rows (works for PRNG keys)."""
  n = x.shape[0]
  if n == n_pad:
    return x
  return x[jnp.minimum(jnp.arange(n_pad), n - 1)]


def shard_worlds(
  fn: Callable, mesh: Mesh | None, *, replicated: Sequence[int] = ()
) -> Callable:
  """``fn`` with its worlds split over ``mesh``: a traceable function of the
  same signature and results (jit it at the call site).

  Every positional argument not in ``replicated`` is a pytree whose leaves
  share a leading world axis B; the results are pytrees with that leading
  axis. B is padded to a multiple of the device count by repeating the last
  world (its results are dropped), so any B works. With a mesh of one device
  (or None) ``fn`` is returned as it is.

  Args:
    fn: ``fn(*args) -> outputs``, written for one batch of worlds.
    mesh: the world mesh (``world_mesh``), or None.
    replicated: indices of arguments every device gets whole (e.g. network
      parameters, a recording's embedding).

  Returns:
    The sharded function.
  """
  if mesh is None or mesh.devices.size == 1:
    return fn
  k = mesh.devices.size
  replicated = frozenset(replicated)

  def sharded(*args):
    batched = [a for i, a in enumerate(args) if i not in replicated]
    sizes = {leaf.shape[0] for leaf in jax.tree.leaves(batched)}
    if len(sizes) != 1:
      raise ValueError(
        f'batched arguments disagree on the world count: {sorted(sizes)}'
      )
    (b,) = sizes
    n_pad = padded(b, k)
    args = [
      a if i in replicated else jax.tree.map(lambda x: _pad_rows(x, n_pad), a)
      for i, a in enumerate(args)
    ]
    specs = tuple(P() if i in replicated else P(AXIS) for i in range(len(args)))
    # check_vma off: MJX's scan carries per-world data that starts as shared
    # constants (the model's initial state), which the check would refuse.
    out = _shard_map(fn, mesh=mesh, in_specs=specs, out_specs=P(AXIS), check_vma=False)(
      *args
    )
    return jax.tree.map(lambda x: x[:b], out)

  return sharded


def place(tree, mesh: Mesh | None):
  """``tree`` placed whole where a program over ``mesh`` runs: on every device
  of a mesh of several (arrays committed to one device, such as another jit's
  output, cannot enter a program sharded over the mesh; placed like this they
  can, and shard_map splits them inside); on the one device of a one-device
  mesh; with no mesh, on the first local device. The last two matter as much:
  arrays replicated over several devices (a checkpoint restored with its
  data-parallel training's sharding) spread every program they enter over all
  of those devices, which then computes everything on each and runs host
  callbacks on one while the others wait at a collective (XLA's CPU client
  aborts a collective kept waiting 40 s)."""
  return jax.device_put(tree, placement(mesh))


def placement(mesh: Mesh | None) -> jax.sharding.Sharding:
  """The sharding ``place`` gives every array of a tree for ``mesh``."""
  if mesh is None:
    return jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
  if mesh.devices.size == 1:
    return jax.sharding.SingleDeviceSharding(mesh.devices.flat[0])
  return NamedSharding(mesh, P())


def abstract(tree, mesh: Mesh | None):
  """``tree``'s shapes and dtypes as ``place`` would put them on ``mesh``, and
  no device memory: what ``jax.jit(...).lower`` takes to compile a program
  before its arguments exist (``None`` leaves stay None)."""
  where = placement(mesh)
  return jax.tree.map(
    lambda a: jax.ShapeDtypeStruct(np.shape(a), a.dtype, sharding=where), tree
  )


def free_bytes(device: jax.Device | None = None) -> int:
  """Bytes free on ``device`` (default: the first local device): the
  allocator's limit minus what is in use on an accelerator; on a CPU, the
  host's available memory."""
  device = device or jax.local_devices()[0]
  stats = None
  try:
    stats = device.memory_stats()
  except Exception:  # noqa: BLE001 - backends without stats raise or return None
    stats = None
  if stats and 'bytes_limit' in stats:
    return max(int(stats['bytes_limit']) - int(stats.get('bytes_in_use', 0)), 0)
  try:
    return int(os.sysconf('SC_AVPHYS_PAGES') * os.sysconf('SC_PAGE_SIZE'))
  except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
    return 8 << 30


def chunk_size(
  bytes_per_item: float,
  *,
  device: jax.Device | None = None,
  share: float = MEMORY_SHARE,
  cap: int | None = None,
  free: int | None = None,
) -> int:
  """How many items of ``bytes_per_item`` fit in ``share`` of the free memory
  of ``device`` (at least 1, at most ``cap``).

  Args:
    bytes_per_item: the stage's working memory per item (a frame, a world).
    device: where it runs (default the first local device).
    share: the share of free memory to use.
    cap: an upper bound (e.g. the batch itself).
    free: free bytes, if already known (default ``free_bytes(device)``).
  """
  if not bytes_per_item > 0:
    raise ValueError(f'bytes_per_item must be > 0, got {bytes_per_item}')
  free = free_bytes(device) if free is None else free
  n = max(int(share * free // bytes_per_item), 1)
  return min(n, cap) if cap else n
