"""README.md stays true: its test command is the one CI runs, and its library
snippet runs as written (on the demo's outputs, at the demo's size)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _readme() -> str:
  with open(os.path.join(_ROOT, 'README.md')) as f:
    return f.read()


def _blocks(language: str) -> list[str]:
  return re.findall(rf'```{language}\n(.*?)```', _readme(), flags=re.S)


def test_ci_runs_the_readme_test_command():
  bash = _blocks('bash')
  tests = [b for b in bash if 'pytest' in b]
  assert tests, 'README gives no test command'
  command = tests[0].strip().split('&&')[-1].strip()
  with open(os.path.join(_ROOT, '.ci', 'run')) as f:
    ci = [line.strip() for line in f]
  assert command in ci, f'.ci/run does not run README\'s "{command}"'


def test_readme_is_a_short_guide():
  assert len(_readme().splitlines()) <= 150


@pytest.mark.slow
def test_the_library_snippet_runs_as_written_on_the_demos_outputs(tmp_path):
  """The demo (fewer training simulations), then README's snippet saved as a
  plain script (no ``__main__`` guard) with the demo's folder swapped in."""
  from experiments.pipeline import demo

  workdir = str(tmp_path / 'demo')
  demo.run(workdir, 'gray_interlock', sequences=8, seed=0, backend='c')
  (snippet,) = [b for b in _blocks('python') if 'estimation.estimate' in b]
  assert "'out/demo'" in snippet
  script = tmp_path / 'snippet.py'
  script.write_text(snippet.replace("'out/demo'", repr(workdir)))
  env = dict(os.environ, PYTHONPATH=_ROOT)
  done = subprocess.run(
    [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True,
    text=True, timeout=1800,
  )  # fmt: skip
  assert done.returncode == 0, done.stderr[-3000:]
  assert os.path.isfile(os.path.join(workdir, 'library', 'estimate.json'))
  assert "'interval_90'" in done.stdout  # it printed the wind's summary
