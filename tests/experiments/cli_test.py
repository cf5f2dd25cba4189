"""Tests of experiments.pipeline.cli and of the scripts' command lines."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import os
import pathlib
import subprocess
import sys

import pytest
from absl import flags

from experiments.pipeline import cli

_ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = sorted(
  p.stem for p in (_ROOT / 'experiments').glob('*.py') if p.stem != '__init__'
)


@dataclasses.dataclass(frozen=True)
class _Inner:
  """A library config.

  Attributes:
    rate: steps per second, Hz.
    names, sizes: described together; the second line
      continues the text.
    hidden: set by the library.
  """

  rate: float = 1.0
  names: tuple[str, ...] = ('a',)
  sizes: tuple[int, ...] = (1, 2)
  hidden: int = 0


@dataclasses.dataclass(frozen=True)
class _Args:
  """A script.

  Attributes:
    path: where.
    mode: how.
    inner: the library's settings.
  """

  path: str = cli.required()
  mode: str = cli.choice('fast', ('fast', 'slow'))
  inner: _Inner = cli.nested(_Inner(), skip=('hidden',))


_PRESETS = {'default': _Args(), 'small': _Args(inner=_Inner(rate=0.5))}


def test_field_docs_by_hand():
  docs = cli.field_docs(_Inner)
  assert docs['rate'] == 'steps per second, Hz.'
  assert docs['names'] == docs['sizes']
  assert docs['sizes'].endswith('the second line continues the text.')


def test_nested_fields_become_flags_and_presets_are_overridden():
  args = cli.parse(
    _Args, _PRESETS,
    ['prog', '--preset=small', '--path=x', '--sizes=3,4', '--names=b,c', '--mode=slow'],
  )  # fmt: skip
  assert args == _Args(path='x', mode='slow',
                       inner=_Inner(rate=0.5, names=('b', 'c'), sizes=(3, 4)))  # fmt: skip
  # a flag not given keeps the preset's value
  assert cli.parse(_Args, _PRESETS, ['p', '--path=y']).inner.rate == 1.0
  names = [leaf.path[-1] for leaf in cli.leaves(_Args)]
  assert 'hidden' not in names and {'rate', 'names', 'path'} <= set(names)


def test_bad_command_lines_are_refused():
  with pytest.raises(ValueError, match='missing --path'):
    cli.parse(_Args, _PRESETS, ['prog'])
  with pytest.raises(ValueError, match='--sizes'):
    cli.parse(_Args, _PRESETS, ['prog', '--path=x', '--sizes=1,two'])
  with pytest.raises(flags.IllegalFlagValueError):
    cli.parse(_Args, _PRESETS, ['prog', '--path=x', '--mode=medium'])
  with pytest.raises(flags.IllegalFlagValueError):
    cli.parse(_Args, _PRESETS, ['prog', '--path=x', '--preset=huge'])


def test_configs_that_cannot_be_flags_are_refused():
  @dataclasses.dataclass(frozen=True)
  class Undocumented:
    """One field undocumented.

    Attributes:
      a: documented.
    """

    a: int = 0
    b: int = 0

  with pytest.raises(ValueError, match=r'Undocumented\.b'):
    cli.leaves(Undocumented)

  @dataclasses.dataclass(frozen=True)
  class Clash:
    """A flag name twice.

    Attributes:
      rate: again.
      inner: the library's.
    """

    rate: float = 0.0
    inner: _Inner = _Inner()

  with pytest.raises(ValueError, match='rate'):
    cli.leaves(Clash)


@pytest.mark.parametrize('name', SCRIPTS)
def test_every_script_documents_every_flag(name):
  # Each script is a thin main over a documented dataclass: every flag has
  # help text, and its presets build.
  script = importlib.import_module(f'experiments.{name}')
  presets = getattr(script, 'PRESETS', {'default': script.Args()})
  leaves = cli.leaves(script.Args)
  assert all(leaf.doc.strip() for leaf in leaves)
  fv = flags.FlagValues()
  cli.define_flags(script.Args, presets, fv)
  assert set(presets) == set(fv['preset'].parser.enum_values)


@pytest.mark.parametrize('name', SCRIPTS)
def test_each_flags_help_says_what_differs_from_its_neighbours(name):
  # Fields described together (``a, b: text``) gave two flags one help text.
  script = importlib.import_module(f'experiments.{name}')
  docs = [leaf.doc.strip() for leaf in cli.leaves(script.Args)]
  shared = {d[:60] for d in docs if docs.count(d) > 1}
  assert not shared, f'flags of experiments.{name} share help: {shared}'


def _imports(path: pathlib.Path) -> set[str]:
  tree = ast.parse(path.read_text())
  out = set()
  for node in ast.walk(tree):
    if isinstance(node, ast.ImportFrom) and node.module:
      out.add(node.module)
      out.update(f'{node.module}.{a.name}' for a in node.names)
    elif isinstance(node, ast.Import):
      out.update(a.name for a in node.names)
  return out


def test_no_script_imports_another_script():
  scripts = {f'experiments.{s}' for s in SCRIPTS}
  users = [
    *(_ROOT / 'experiments').rglob('*.py'),
    *(_ROOT / 'benchmarks').glob('*.py'),
  ]
  for path in users:
    bad = _imports(path) & scripts
    assert not bad, f'{path.relative_to(_ROOT)} imports {sorted(bad)}'


def test_a_user_error_is_one_line_and_exit_status_2(tmp_path):
  env = dict(os.environ, PYTHONPATH=str(_ROOT))
  cmd = [sys.executable, '-m', 'experiments.estimate', '--recording=nowhere',
         f'--model={tmp_path}']  # fmt: skip
  out = subprocess.run(cmd, cwd=_ROOT, env=env, capture_output=True, text=True)
  assert out.returncode == 2
  assert out.stderr.startswith('error: ') and 'Traceback' not in out.stderr
  assert str(tmp_path) in out.stderr
  verbose = subprocess.run(
    cmd + ['--verbose'], cwd=_ROOT, env=env, capture_output=True, text=True
  )
  assert verbose.returncode != 0 and 'Traceback' in verbose.stderr


@pytest.mark.parametrize('cores, devices', [(1, 1), (2, 1), (8, 7)])
def test_scripts_ask_for_one_host_device_fewer_than_cores(monkeypatch, cores, devices):
  monkeypatch.delenv('XLA_FLAGS', raising=False)
  monkeypatch.setattr(os, 'cpu_count', lambda: cores)
  cli.host_devices()
  assert os.environ['XLA_FLAGS'] == f'--xla_force_host_platform_device_count={devices}'
  monkeypatch.setenv('XLA_FLAGS', '--xla_force_host_platform_device_count=3')
  cli.host_devices()  # the environment's count is kept
  assert os.environ['XLA_FLAGS'] == '--xla_force_host_platform_device_count=3'


# A GP step's shape on CPU devices (bo.batched 'map'): rows sharded over every
# device, each a batch of Cholesky factorisations. With a device per core,
# jaxlib's batched LAPACK kernels can wait in every thread of XLA's intra-op
# pool for work queued on it: on two cores, two devices hung 3 runs of 3 (one
# device: 2.7 s).
_CHOLESKY_OVER_DEVICES = """
from experiments.pipeline import cli
cli.host_devices()
import jax, jax.numpy as jnp, numpy as np
jax.config.update('jax_enable_x64', True)
mesh = jax.sharding.Mesh(np.array(jax.devices()), ('x',))
spec = jax.sharding.PartitionSpec('x')
rows = lambda a: jax.lax.map(lambda m: jnp.linalg.cholesky(m).sum(), a)
f = jax.jit(jax.shard_map(rows, mesh=mesh, in_specs=spec, out_specs=spec))
b = 2 * np.eye(40) + np.zeros((2 * len(jax.devices()), 64, 40, 40))
for _ in range(100):
  assert np.isclose(float(jax.device_get(f(b)).sum()), len(b) * 64 * 40 * 2**0.5)
print('ok', len(jax.devices()))
"""


def test_the_host_devices_run_batched_cholesky_without_deadlock():
  env = {k: v for k, v in os.environ.items() if k != 'XLA_FLAGS'}
  out = subprocess.run(
    [sys.executable, '-c', _CHOLESKY_OVER_DEVICES], env=env, capture_output=True,
    text=True, timeout=120,
  )  # fmt: skip
  assert out.returncode == 0, out.stderr[-2000:]
  assert out.stdout.split() == ['ok', str(max(1, (os.cpu_count() or 1) - 1))]
