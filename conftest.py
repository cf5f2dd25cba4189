"""Test session settings for the whole suite.

Tiers: ``python -m pytest -q tests`` (README's command) is the fast tier:
pyproject's ``addopts`` leave out tests marked ``slow`` (whole searches,
trainings and studies end to end). ``-m slow`` runs those alone and
``-m "slow or not slow"`` both; ``.ci/run`` runs the fast tier, then the slow
one on both cores with pytest-xdist. ``gpu`` tests need a CUDA device and skip
without one (``-m gpu`` on a GPU machine).
"""

from __future__ import annotations

import atexit
import gc
import os
import shutil
import signal
import tempfile

# Quiet and small: no TF-style logging, no preallocation if a GPU is present.
os.environ.setdefault('TF_CPP_MIN_LOG_LEVEL', '2')
os.environ.setdefault('XLA_PYTHON_CLIENT_PREALLOCATE', 'false')
# Two CPU devices (the scripts have one per core but one: cli.host_devices):
# lockstep searches put their GPs on different devices, and the tests cover
# that path (at the tests' small sizes it has not hung: cli_test says why it can).
if 'xla_force_host_platform_device_count' not in os.environ.get('XLA_FLAGS', ''):
  os.environ['XLA_FLAGS'] = (
    os.environ.get('XLA_FLAGS', '') + ' --xla_force_host_platform_device_count=2'
  ).strip()

# Scripts the tests run (cli.run turns JAX's persistent compilation cache on)
# share one cache for this session, never the user's: a later subprocess loads
# what an earlier one compiled, and nothing outlives the run.
if 'PHYSNET_JAX_CACHE' not in os.environ:
  os.environ['PHYSNET_JAX_CACHE'] = tempfile.mkdtemp(prefix='physnet-jax-cache-')
  atexit.register(shutil.rmtree, os.environ['PHYSNET_JAX_CACHE'], True)

import jax  # noqa: E402
import pytest  # noqa: E402


def pytest_collection_modifyitems(config, items):
  """Skips ``gpu`` tests when JAX has no GPU."""
  if jax.default_backend() == 'gpu':
    return
  skip = pytest.mark.skip(reason='needs a CUDA GPU')
  for item in items:
    if 'gpu' in item.keywords:
      item.add_marker(skip)


@pytest.fixture(autouse=True, scope='module')
def _free_compiled_programs():
  """Drops compiled programs after each test module: a session that keeps every
  module's executables (MJX, renderers, networks, GPs) grows by gigabytes."""
  yield
  jax.clear_caches()
  gc.collect()


@pytest.fixture
def deferring_sigint(monkeypatch):
  """``physsim.interrupt``'s handler on SIGINT for one test, fresh state (no
  resend left from an earlier test), then the handler before it again."""
  from physsim import interrupt  # noqa: PLC0415 - imports jax, MuJoCo

  monkeypatch.setattr(interrupt, '_state', interrupt._State())
  before = signal.signal(signal.SIGINT, interrupt.handler)
  yield interrupt
  signal.signal(signal.SIGINT, before)
