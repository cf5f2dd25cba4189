"""experiments.pipeline.files: atomic writes, resume by config, one process per workdir."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap

import pytest

from experiments.pipeline import files


def _tree(folder) -> dict[str, bytes]:
  out = {}
  for root, _, names in os.walk(folder):
    for n in names:
      p = os.path.join(root, n)
      with open(p, 'rb') as f:
        out[os.path.relpath(p, folder)] = f.read()
  return out


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
  path = tmp_path / 'result.json'
  files.write_json(str(path), {'a': 1})
  before = _tree(tmp_path)

  def broken(tmp):
    with open(tmp, 'w') as f:
      f.write('{"half": ')
    raise KeyboardInterrupt  # as Ctrl-C mid-write

  with pytest.raises(KeyboardInterrupt):
    files.write_atomic(str(path), broken)
  assert _tree(tmp_path) == before


@dataclasses.dataclass(frozen=True)
class _Config:
  n: int = 3
  sizes: tuple[int, ...] = (1, 2)


def test_resume_only_for_the_same_config(tmp_path):
  path = str(tmp_path / 'run.json')
  assert files.resume(path, _Config()) == {}
  files.write_json(path, {'config': dataclasses.asdict(_Config()), 'done': 7})
  assert files.resume(path, _Config())['done'] == 7  # tuples came back as lists
  assert files.resume(path, _Config(n=4)) == {}


def test_a_second_hold_is_refused_naming_the_holder(tmp_path):
  workdir = str(tmp_path / 'run')
  with files.locked(workdir):
    with pytest.raises(ValueError, match=rf'in use by process {os.getpid()}'):
      with files.locked(workdir):
        pass
  assert not os.path.exists(workdir)  # made by the hold, left empty: removed


def test_another_process_is_refused_while_held_and_served_after(tmp_path):
  workdir = str(tmp_path / 'run')
  script = textwrap.dedent(f"""
    from experiments.pipeline import files
    try:
      with files.locked({workdir!r}):
        print('held')
    except ValueError as e:
      print('refused:', e)
  """)
  run = lambda: subprocess.run(
    [sys.executable, '-c', script], capture_output=True, text=True, check=True,
    cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))),
  ).stdout  # fmt: skip
  with files.locked(workdir):
    out = run()
  assert out.startswith('refused:') and f'process {os.getpid()}' in out
  assert run().strip() == 'held'


def test_an_estimate_loads_matplotlib_and_orbax_only_when_it_uses_them(tmp_path):
  """An estimate prints its table before it draws, and a shape-distance one
  reads no checkpoint: importing the estimate imports neither matplotlib nor
  orbax (about a second of a warm start); ``files.pyplot`` then gives pyplot
  on the Agg backend, and a figure saved through it is a PNG."""
  code = (
    'import sys, experiments.estimate; '
    "print(sorted(m for m in ('matplotlib', 'orbax') if m in sys.modules)); "
    'from experiments.pipeline import files; plt = files.pyplot(); '
    'import matplotlib; print(matplotlib.get_backend().lower()); '
    f'fig = plt.figure(); files.savefig(fig, {str(tmp_path / "f.png")!r})'
  )
  out = subprocess.run(
    [sys.executable, '-c', code], capture_output=True, text=True, check=True,
    env={**os.environ, 'JAX_PLATFORMS': 'cpu'}, timeout=300,
  ).stdout.split('\n')  # fmt: skip
  assert out[:2] == ['[]', 'agg']
  with open(tmp_path / 'f.png', 'rb') as f:
    assert f.read(8) == b'\x89PNG\r\n\x1a\n'
