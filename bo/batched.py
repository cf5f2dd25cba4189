"""Many searches' GP steps as one device program (issue 41).

``ask_many`` and ``result_many`` advance several searches (``bo.Minimizer``,
``bo.PosteriorSearch``, or a mix) at once. Each search plans its step on the
host (``ask_plan``, ``result_plan``): the initial design, or a quasi-random
batch while every evaluation failed, is an answer (``Ready``); a step that
needs the GP (the fit, then the proposal or the posterior grid) is one row of
fixed-shape arguments (``Call``). Rows of one program (equal settings, equal
buffer capacity) are stacked along a leading axis and run by one jitted
program; a single ``ask`` or ``result`` is the batch of one.

A row holds everything its search's step depends on: its data in a buffer of
the search's own capacity (padding rows masked, as ``bo.gp`` does), its own
key ``fold_in(key(seed), iteration)`` and its warm start; rows never mix, so
searches at different iterations share a program, and a search proposes the
same points alone as inside any batch (see ``run`` for how exactly).

A group is padded to a power of two (copies of its first row, whose outputs
are dropped) and spread over its devices with ``shard_map`` on a 1-D
``jax.sharding.Mesh``: the ``devices`` passed, else the distinct ``device``
of its searches (else JAX's first local device). On each device the rows run
as a ``vmap`` (GPUs) or a ``lax.map`` (CPUs); ``run`` says why.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import numpy as np

AXIS = 'search'


class Ready(NamedTuple):
  """A step that needed no GP: its answer."""

  value: Any


class Call(NamedTuple):
  """A step that runs ``fn`` on one row of arguments (NumPy arrays, fixed
  shapes), then ``finish(outputs_of_the_row)`` (host arrays) gives its answer.
  ``fn`` must be hashable and the same object for searches that can share a
  program (memoise it per config)."""

  fn: Callable
  args: tuple
  finish: Callable[[Any], Any]


MODES = ('vmap', 'map')


def _pad(n: int) -> int:
  """The next power of two >= n."""
  return 1 << max(0, int(np.ceil(np.log2(max(n, 1)))))


@functools.lru_cache(maxsize=64)
def _program(fn: Callable, mode: str, mesh: jax.sharding.Mesh):
  """The jitted ``program(live, *stacked_args)``: ``fn`` on every row, the
  rows sharded over ``mesh`` (see ``run``)."""
  if mode == 'vmap':

    def local(live, *args):
      del live  # padded rows run (a vmapped cond would run both branches)
      return jax.vmap(fn)(*args)

  elif mode == 'map':

    def local(live, *args):
      def row(a):
        ok, rest = a[0], a[1:]

        def skip(r):
          shapes = jax.eval_shape(fn, *r)
          return jax.tree.map(lambda s: jax.numpy.zeros(s.shape, s.dtype), shapes)

        # Padding rows are skipped: a scalar cond runs one branch.
        return jax.lax.cond(ok, lambda r: fn(*r), skip, rest)

      return jax.lax.map(row, (live, *args))

  else:
    raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
  spec = jax.sharding.PartitionSpec(AXIS)
  # check_vma off: jaxopt's loops build carries the varying-axis check rejects.
  return jax.jit(
    jax.shard_map(local, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)
  )


def _signature(args) -> tuple:
  leaves, tree = jax.tree.flatten(args)
  return tree, tuple((np.shape(a), np.asarray(a).dtype.str) for a in leaves)


def _mesh_devices(devices: Sequence, n: int) -> list:
  """The first ``k`` devices, ``k`` the largest power of two dividing ``n``
  (itself a power of two) and at most the number of devices."""
  k = 1
  while 2 * k <= min(len(devices), n):
    k *= 2
  return list(devices[:k])


def default_mode(devices: Sequence) -> str:
  """'map' on CPUs, else 'vmap' (see ``run``)."""
  return 'map' if all(d.platform == 'cpu' for d in devices) else 'vmap'


def run(calls: Sequence[Call], devices: Sequence | None = None,
        call_devices: Sequence | None = None, mode: str | None = None,
        min_rows: int = 1) -> list:  # fmt: skip
  """Runs ``calls`` grouped by program (``fn`` and argument shapes), one
  jitted program per group under float64; returns each call's ``finish``
  value.

  The rows of a group are stacked, padded to a power of two and to every
  device, and spread over the group's devices by ``shard_map`` on the
  leading axis. On each device they run as

  * ``'vmap'`` (the default off CPUs): one batched program. It suits a GPU,
    whose GP loops would otherwise wait on kernel launches: on an H200, 8
    searches of the estimate's default size took 0.2 s where one takes 3 s
    on a CPU core (its first call compiled for 107 s). A row agrees with the
    same row alone up to float reassociation.
  * ``'map'`` (the default on CPUs): ``lax.map``, one row after another with
    the code of a batch of one, padding rows skipped, and jaxopt's L-BFGS-B
    loops unbatched (``gp.fit`` keeps them out of ``vmap`` on CPU). Since
    any batch over the same devices runs the program of one mesh, a search
    proposes bit for bit the same points alone as in any batch (a mesh of
    two devices rounds differently from a mesh of one: 1e-8 apart after an
    L-BFGS-B).

  Args:
    calls: the rows.
    devices: devices to spread every group over; default each group's
      ``call_devices``.
    call_devices: per call, the device its search asked for (None: JAX's
      default device).
    mode: 'vmap' or 'map'; default ``default_mode`` of the devices.
    min_rows: pad every group to at least this many rows (skipped with
      'map', computed and dropped with 'vmap'), so that a driver whose
      searches finish one by one keeps one compiled program (pass the
      number it started with).
  """
  groups: dict[tuple, list[int]] = {}
  for i, c in enumerate(calls):
    groups.setdefault((c.fn, _signature(c.args)), []).append(i)
  out: list = [None] * len(calls)
  for (fn, _), members in groups.items():
    if devices is not None:
      devs = list(devices)
    else:
      wanted = [None if call_devices is None else call_devices[i] for i in members]
      devs = list(dict.fromkeys(d for d in wanted if d is not None))
    devs = devs or [jax.local_devices()[0]]
    devs = [d for d in devs if d.platform == devs[0].platform]
    how = mode or default_mode(devs)
    rows = [calls[i].args for i in members]
    # Padded to every device: any batch size runs the program of one mesh,
    # whose arithmetic differs from another mesh's.
    n_pad = _pad(max(len(rows), min_rows, len(devs)))
    rows += [rows[0]] * (n_pad - len(rows))
    live = np.arange(n_pad) < len(members)
    mesh = jax.sharding.Mesh(np.asarray(_mesh_devices(devs, n_pad)), (AXIS,))
    where = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(AXIS))
    program = _program(fn, how, mesh)
    with jax.enable_x64(True):
      stacked = jax.tree.map(lambda *a: np.stack(a), *rows)
      stacked = jax.device_put((live, *stacked), where)
      res = jax.device_get(program(*stacked))
    for r, i in enumerate(members):
      out[i] = calls[i].finish(jax.tree.map(lambda a, r=r: a[r], res))
  return out


def _gather(plans: Sequence, devices, call_devices, mode, min_rows) -> list:
  idx = [i for i, p in enumerate(plans) if isinstance(p, Call)]
  ran = run(
    [plans[i] for i in idx], devices, [call_devices[i] for i in idx], mode,
    min_rows,
  ) if idx else []  # fmt: skip
  out = [p.value if isinstance(p, Ready) else None for p in plans]
  for i, v in zip(idx, ran, strict=True):
    out[i] = v
  return out


def ask_many(searches: Sequence, states: Sequence, *,
             devices: Sequence | None = None, mode: str | None = None,
             min_rows: int = 1) -> list[tuple[np.ndarray, Any]]:  # fmt: skip
  """Every search's ``ask``: per search, its points and its new state.

  Args:
    searches: ``bo.Minimizer`` or ``bo.PosteriorSearch`` objects, none done.
    states: their states, in order.
    devices: where the batched steps run (default: the searches' devices).
    mode, min_rows: as ``run``'s.
  """
  plans = [s.ask_plan(st) for s, st in zip(searches, states, strict=True)]
  return _gather(plans, devices, [s.device for s in searches], mode, min_rows)


def result_many(searches: Sequence, states: Sequence, *,
                devices: Sequence | None = None, mode: str | None = None,
                min_rows: int = 1) -> list:  # fmt: skip
  """Every search's ``result`` (a ``bo.PosteriorSearch``'s needs one more GP
  fit, batched as in ``ask_many``; the same arguments)."""
  plans = [s.result_plan(st) for s, st in zip(searches, states, strict=True)]
  return _gather(plans, devices, [s.device for s in searches], mode, min_rows)


def warm_ask(searches: Sequence, states: Sequence, xs: Sequence, *,
             devices: Sequence | None = None, mode: str | None = None,
             min_rows: int = 1) -> None:  # fmt: skip
  """Runs the GP program that ``ask_many`` will run once the searches are
  told values at ``xs``, on placeholder values, and drops what it returns.

  Tracing a step's program (and loading it from JAX's compilation cache)
  takes seconds on the host; a driver calls this in a thread while the
  simulations of ``xs`` run, so that the real step finds the program ready.
  Nothing is told or saved: ``ask_plan`` is pure, and the placeholder state
  has the told state's shapes (the values, ``1 + |x|^2``, only need to be
  finite), hence the same program.

  Args:
    searches, states: as ``ask_many``'s (the states before the tell).
    xs: per search, the points it asked.
    devices, mode, min_rows: as ``ask_many``'s.
  """
  plans, where = [], []
  for s, st, x in zip(searches, states, xs, strict=True):
    x = np.asarray(x, np.float64).reshape(-1, st.X.shape[1])
    y = 1.0 + np.sum(x**2, axis=1)
    y = np.broadcast_to(
      y.reshape(-1, *[1] * (st.Y.ndim - 1)), (len(x), *st.Y.shape[1:])
    )
    told = st._replace(X=np.concatenate([st.X, x]), Y=np.concatenate([st.Y, y]))
    if not s.done(told):
      plans.append(s.ask_plan(told))
      where.append(s.device)
  _gather(plans, devices, where, mode, min_rows)
