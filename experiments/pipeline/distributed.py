"""Many processes, one program: ``jax.distributed`` for the experiment scripts.

A script run under several processes (one per GPU, or per host of a cluster)
joins them at start (``initialize``, called by ``cli.run``), takes its share of
the independent jobs (``share``: Table 1's fabrics x methods, Tables 2/3's
recordings, calibration's recordings) and meets the others at a barrier
(``barrier``) before the main process (``is_main``) writes what needs them all.
Results pass through the shared workdir, which every job already resumes from.

Discovery, in order:

* ``JAX_COORDINATOR_ADDRESS`` (host:port of process 0), ``JAX_NUM_PROCESSES``
  and ``JAX_PROCESS_ID``: any launcher, e.g. one process per local GPU::

    for i in 0 1 2 3; do
      JAX_COORDINATOR_ADDRESS=localhost:12355 JAX_NUM_PROCESSES=4 JAX_PROCESS_ID=$i \\
      CUDA_VISIBLE_DEVICES=$i python -m experiments.tables ... &
    done; wait

* SLURM: ``srun`` with ``SLURM_NTASKS`` > 1 (``jax.distributed`` reads the job's
  variables itself)::

    srun --ntasks=8 --gpus-per-task=1 python -m experiments.tables ...

* otherwise one process (nothing to join).

On CPU devices the processes' collectives use gloo (as the CI test does).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import TypeVar

import jax

T = TypeVar('T')
_ENV = ('JAX_COORDINATOR_ADDRESS', 'JAX_NUM_PROCESSES', 'JAX_PROCESS_ID')


def launch_settings(env: Mapping[str, str] | None = None) -> dict | None:
  """``jax.distributed.initialize`` arguments the environment asks for: {}
  for SLURM (JAX reads it), the explicit three, or None for one process.

  Raises:
    ValueError: some but not all of the explicit variables, or bad values.
  """
  env = os.environ if env is None else env
  given = [k for k in _ENV if env.get(k)]
  if given:
    if len(given) != len(_ENV):
      raise ValueError(f'set all of {list(_ENV)} to join processes, got only {given}')
    try:
      n, i = int(env['JAX_NUM_PROCESSES']), int(env['JAX_PROCESS_ID'])
    except ValueError:
      raise ValueError(
        f'JAX_NUM_PROCESSES and JAX_PROCESS_ID must be integers, got '
        f'{env["JAX_NUM_PROCESSES"]!r}, {env["JAX_PROCESS_ID"]!r}'
      ) from None
    if not 0 <= i < n:
      raise ValueError(f'JAX_PROCESS_ID {i} is not in [0, JAX_NUM_PROCESSES={n})')
    if n == 1:
      return None
    return dict(
      coordinator_address=env['JAX_COORDINATOR_ADDRESS'], num_processes=n, process_id=i
    )
  if int(env.get('SLURM_NTASKS', '1') or 1) > 1 and 'SLURM_PROCID' in env:
    return {}
  return None


_joined = False


def initialize(env: Mapping[str, str] | None = None) -> bool:
  """Joins the other processes when the environment describes a multi-process
  run (module docstring); call before anything uses JAX. True when joined."""
  global _joined
  settings = launch_settings(env)
  if settings is None or _joined:
    return _joined
  # CPU devices talk through gloo; a GPU run ignores this setting.
  jax.config.update('jax_cpu_collectives_implementation', 'gloo')
  jax.distributed.initialize(**settings)
  _joined = True
  return True


def process() -> tuple[int, int]:
  """(this process's index, the number of processes)."""
  return jax.process_index(), jax.process_count()


def is_main() -> bool:
  """Whether this is process 0, which writes what needs every process's jobs."""
  return jax.process_index() == 0


def share(
  jobs: Sequence[T], index: int | None = None, count: int | None = None
) -> list[T]:
  """This process's contiguous share of ``jobs`` (sizes differ by at most one;
  contiguous, so jobs sorted by kind keep each process's kinds few)."""
  i, n = process() if index is None else (index, count)
  return [job for k, job in enumerate(jobs) if k * n // max(len(jobs), 1) == i]


# A barrier waits for the slowest process's share (hours of training at most).
BARRIER_TIMEOUT_S = 24 * 3600
_barriers = 0


def barrier(name: str, timeout_s: float = BARRIER_TIMEOUT_S) -> None:
  """Waits until every process has reached the barrier ``name``.

  It waits at the coordination service (``jax.distributed``'s client, as JAX's
  own array serialization does), not through a device collective, whose
  transport (gloo on CPU) gives up on a peer after seconds when the other
  process is still busy with its share."""
  global _barriers
  if jax.process_count() == 1:
    return
  _barriers += 1  # every process passes the same barriers in the same order
  from jax._src import distributed as jax_distributed  # noqa: PLC0415

  jax_distributed.global_state.client.wait_at_barrier(
    f'physnet:{_barriers}:{name}', int(timeout_s * 1000)
  )


def launch(
  command: Sequence[str],
  processes: int,
  *,
  port: int = 12355,
  gpus_per_process: int = 0,
  env: Mapping[str, str] | None = None,
) -> int:
  """Runs ``command`` as ``processes`` processes of one jax.distributed run
  on this machine (the launcher SLURM would otherwise be), each told its
  place by the ``JAX_*`` variables and, with ``gpus_per_process``, given its
  own GPUs (``CUDA_VISIBLE_DEVICES``). Output lines are prefixed ``[i]``.
  A process that stops at its ``--time_limit`` (``deadline``) interrupts the
  others, which would otherwise wait for it at their next barrier.

  Returns:
    0 when every process succeeded, ``deadline.EXIT_STATUS`` when one
    stopped at its time limit, else the first failing exit status.
  """
  import signal  # noqa: PLC0415
  import subprocess  # noqa: PLC0415
  import sys  # noqa: PLC0415
  import threading  # noqa: PLC0415
  import time  # noqa: PLC0415

  from experiments.pipeline import deadline  # noqa: PLC0415

  if processes < 1 or not command:
    raise ValueError(f'need processes >= 1 and a command, got {processes}, {command!r}')
  base = dict(os.environ if env is None else env)
  procs = []
  for i in range(processes):
    e = dict(
      base, JAX_COORDINATOR_ADDRESS=f'localhost:{port}',
      JAX_NUM_PROCESSES=str(processes), JAX_PROCESS_ID=str(i),
    )  # fmt: skip
    if gpus_per_process:
      gpus = range(i * gpus_per_process, (i + 1) * gpus_per_process)
      e['CUDA_VISIBLE_DEVICES'] = ','.join(map(str, gpus))
    procs.append(
      subprocess.Popen(
        list(command),
        env=e,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
      )  # fmt: skip
    )

  def forward(i, p):
    for line in p.stdout:
      sys.stdout.write(f'[{i}] {line}')
      sys.stdout.flush()

  threads = [threading.Thread(target=forward, args=ip) for ip in enumerate(procs)]
  for t in threads:
    t.start()
  codes: list[int | None] = [None] * len(procs)
  while None in codes:
    for i, p in enumerate(procs):
      if codes[i] is None and (code := p.poll()) is not None:
        codes[i] = code
        if code == deadline.EXIT_STATUS:  # --time_limit: the others stop too
          for q in procs:  # (they would wait at the next barrier for it)
            if q.poll() is None:
              q.send_signal(signal.SIGTERM)  # (a background job ignores SIGINT)
    time.sleep(0.2)
  for t in threads:
    t.join()
  if deadline.EXIT_STATUS in codes:
    return deadline.EXIT_STATUS
  return next((c for c in codes if c), 0)
