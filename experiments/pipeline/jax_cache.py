"""JAX's persistent compilation cache for the scripts (issue 41, item 3).

Every process compiles the same programs (the fused simulator, renderer and
scorer; the GP steps): tens of seconds each, again in every process. With the
persistent cache on, a process loads what an earlier one compiled.

  from experiments.pipeline import jax_cache
  jax_cache.enable()  # before the first compile

The directory: ``enable(path)``, else ``$PHYSNET_JAX_CACHE``, else JAX's own
setting (``$JAX_COMPILATION_CACHE_DIR``) if any, else
``$XDG_CACHE_HOME/physnet-jax/jax`` (``~/.cache/physnet-jax/jax``). The word
``off`` (as the path or the variable) turns it off.

JAX writes no entry for a program with host callbacks (the C simulator's
``pure_callback``), and under ``jax.distributed`` only process 0 writes.
Programs that call foreign functions (MuJoCo Warp's kernels through XLA's FFI)
are cached like any other: the cache stores XLA's executable, whose custom
calls name their targets, and a later process registers those targets when it
traces the same program, before the cached executable runs (a GPU test,
tests/experiments/jax_cache_test.py, checks that a second process loads the
Warp simulator's programs and moves a cloth as the first did);
``$PHYSNET_JAX_CACHE=off`` is the way out should a cached program misbehave.
"""

from __future__ import annotations

import importlib.util
import os
import warnings

import jax

ENV = 'PHYSNET_JAX_CACHE'
OFF = 'off'
# Programs that compile faster than this are not worth a disk round trip.
MIN_COMPILE_SECONDS = 0.5
# Least recently used entries go beyond this (the default is unbounded), where
# the ``filelock`` package is installed (JAX refuses the cache without it).
MAX_BYTES = 8 << 30


def default_dir() -> str:
  """The user cache directory: ``$XDG_CACHE_HOME/physnet-jax/jax``."""
  root = os.environ.get('XDG_CACHE_HOME') or os.path.join(
    os.path.expanduser('~'), '.cache'
  )
  return os.path.join(root, 'physnet-jax', 'jax')


def resolve(path: str | None = None) -> str | None:
  """The directory ``enable(path)`` would use; None: off."""
  path = path if path is not None else os.environ.get(ENV)
  if path is None:
    path = jax.config.jax_compilation_cache_dir or default_dir()
  if not path or path.strip().lower() == OFF:
    return None
  return os.path.abspath(os.path.expanduser(path))


def enable(path: str | None = None, *,
           min_compile_seconds: float = MIN_COMPILE_SECONDS) -> str | None:  # fmt: skip
  """Turns JAX's persistent compilation cache on (call before compiling).

  Args:
    path: the directory; default as the module doc says; ``'off'``: leave
      the cache off.
    min_compile_seconds: programs compiled faster are not written.

  Returns:
    The directory in use, or None if off (or not writable: a warning).
  """
  where = resolve(path)
  if where is None:
    return None
  try:
    os.makedirs(where, exist_ok=True)
  except OSError as e:
    warnings.warn(
      f'JAX compilation cache off: cannot create {where}: {e}', stacklevel=2
    )
    return None
  if not os.access(where, os.W_OK):
    warnings.warn(f'JAX compilation cache off: {where} is not writable', stacklevel=2)
    return None
  jax.config.update('jax_compilation_cache_dir', where)
  jax.config.update('jax_persistent_cache_min_compile_time_secs', min_compile_seconds)
  if importlib.util.find_spec('filelock') is not None:  # JAX needs it for the bound
    jax.config.update('jax_compilation_cache_max_size', MAX_BYTES)
  return where
