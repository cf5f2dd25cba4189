"""The house's shape (issue 75): the import graph of physsim, model, bo and
experiments has no cycle, function-level imports included, the estimate
pipeline's stages import only the stages before them, and no module or
function of the libraries and benchmarks outgrows the size issue 75 cut them
to. Reads source files only (no imports run)."""

from __future__ import annotations

import ast
import os

import pytest

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_PACKAGES = ('physsim', 'model', 'bo', 'experiments')
_P = 'experiments.pipeline.'
# Issue 75's targets: a module a person reads in one sitting, a function on a
# screen or two (end_lineno - lineno + 1, its docstring included).
_SIZED = (*_PACKAGES, 'benchmarks')
_MAX_MODULE_LINES = 600
_MAX_FUNCTION_LINES = 80

# The estimate's stages in the order they run (experiments/pipeline/__init__.py).
# A module may import modules of its own stage or earlier ones, never later.
STAGES = (
  ('files', 'layout', 'cli', 'progress', 'deadline', 'distributed', 'jax_cache',
   'embedding', 'simulation', 'recording'),
  ('intake', 'intake_record', 'intake_frames', 'intake_alignment', 'intake_files',
   'cloth_view', 'takes', 'rig'),
  ('measurements',),
  ('config', 'problem', 'objective'),
  ('carried_errors', 'calibration_tables', 'protocol_checks', 'reading_floor',
   'setup'),
  ('evaluation', 'searcher', 'resume', 'search'),
  ('posterior', 'posterior_figure', 'fit_check'),
  ('summaries', 'units', 'table_notes', 'report', 'advice', 'search_figures',
   'results', 'joint'),
  ('estimation', 'user_recordings'),
)  # fmt: skip


def _modules() -> dict[str, str]:
  """Dotted module name -> its file, for every module of the packages."""
  out = {}
  for package in _PACKAGES:
    for folder, _, names in os.walk(os.path.join(_ROOT, package)):
      for name in names:
        if name.endswith('.py'):
          path = os.path.join(folder, name)
          dotted = os.path.relpath(path, _ROOT)[:-3].replace(os.sep, '.')
          out[dotted.removesuffix('.__init__')] = path
  return out


def _imports(modules: dict[str, str]) -> dict[str, set[str]]:
  """Each module's imports of the packages' modules, wherever in the file
  they stand (top level or inside a function); ``from a import b`` counts
  ``a.b`` where that is a module, else ``a``."""
  graph = {}
  for name, path in modules.items():
    with open(path, encoding='utf-8') as f:
      tree = ast.parse(f.read(), path)
    package = name if path.endswith('__init__.py') else name.rpartition('.')[0]
    found = set()
    for node in ast.walk(tree):
      if isinstance(node, ast.Import):
        targets = [a.name for a in node.names]
      elif isinstance(node, ast.ImportFrom):
        base = node.module or ''
        if node.level:  # relative: from the package, up level - 1
          parts = package.split('.')
          parts = parts[: len(parts) - node.level + 1]
          base = '.'.join([*parts, base] if base else parts)
        targets = [
          f'{base}.{a.name}' if f'{base}.{a.name}' in modules else base
          for a in node.names
        ]
      else:
        continue
      for t in targets:
        while t and t not in modules:
          t = t.rpartition('.')[0]
        if t and t != name:
          found.add(t)
    graph[name] = found
  return graph


def _cycle(graph: dict[str, set[str]]) -> list[str]:
  """One cycle of ``graph`` as a path (first == last), or [] if none."""
  state: dict[str, int] = {}  # 1: on the path, 2: done
  path: list[str] = []

  def visit(v):
    state[v] = 1
    path.append(v)
    for w in sorted(graph[v]):
      if state.get(w) == 1:
        return [*path[path.index(w) :], w]
      if w not in state and (c := visit(w)):
        return c
    path.pop()
    state[v] = 2
    return []

  for v in sorted(graph):
    if v not in state and (c := visit(v)):
      return c
  return []


@pytest.fixture(scope='module')
def graph():
  return _imports(_modules())


def test_the_import_graph_has_no_cycle(graph):
  assert _cycle(graph) == []


def test_a_planted_cycle_is_found():
  g = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}
  assert _cycle(g) == ['a', 'b', 'c', 'a']
  assert _cycle({'a': {'b'}, 'b': set()}) == []


def test_each_stage_imports_only_the_stages_before_it(graph):
  level = {f'{_P}{m}': i for i, stage in enumerate(STAGES) for m in stage}
  late = [
    f'{m} (stage {level[m]}) imports {t} (stage {level[t]})'
    for m in sorted(level)
    for t in sorted(graph.get(m, ()))
    if t in level and level[t] > level[m]
  ]
  assert late == []


def test_every_pipeline_module_has_a_stage_or_is_an_application(graph):
  """A new pipeline module is placed in ``STAGES``, or imports no stage of
  it from below (an application at the top: datasets, training, demo)."""
  staged = {f'{_P}{m}' for stage in STAGES for m in stage}
  pipeline = {m for m in graph if m.startswith(_P)}
  unknown = staged - pipeline
  assert not unknown, f'STAGES names modules that do not exist: {unknown}'
  below = [m for m in pipeline - staged if any(m in graph[s] for s in staged)]
  assert below == [], f'staged modules import these unstaged ones: {below}'


def _too_big(root: str, packages: tuple[str, ...]) -> list[str]:
  """'path: N lines' for each module of ``packages`` (under ``root``) over
  ``_MAX_MODULE_LINES``, and 'path:line name: N lines' for each function (any
  depth) over ``_MAX_FUNCTION_LINES``."""
  out = []
  for package in packages:
    for folder, _, names in sorted(os.walk(os.path.join(root, package))):
      for name in sorted(n for n in names if n.endswith('.py')):
        path = os.path.join(folder, name)
        with open(path, encoding='utf-8') as f:
          text = f.read()
        where = os.path.relpath(path, root)
        if (n := text.count('\n')) > _MAX_MODULE_LINES:
          out.append(f'{where}: {n} lines')
        for node in ast.walk(ast.parse(text, path)):
          if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            n = node.end_lineno - node.lineno + 1
            if n > _MAX_FUNCTION_LINES:
              out.append(f'{where}:{node.lineno} {node.name}: {n} lines')
  return out


def test_no_module_or_function_outgrows_issue_75s_sizes():
  big = _too_big(_ROOT, _SIZED)
  assert big == [], (
    f'over {_MAX_MODULE_LINES} lines a module or {_MAX_FUNCTION_LINES} a '
    f'function (cut along responsibilities): {big}'
  )


def test_a_planted_long_function_and_module_are_named(tmp_path):
  pkg = tmp_path / 'pkg'
  pkg.mkdir()
  body = '\n'.join(f'  x{i} = {i}' for i in range(_MAX_FUNCTION_LINES))
  (pkg / 'long.py').write_text(f'def f():\n{body}\n\n\ndef g():\n  return 1\n')
  (pkg / 'big.py').write_text('x = 1\n' * (_MAX_MODULE_LINES + 1))
  (pkg / 'fine.py').write_text('x = 1\n' * _MAX_MODULE_LINES)
  assert _too_big(str(tmp_path), ('pkg',)) == [
    f'pkg/big.py: {_MAX_MODULE_LINES + 1} lines',
    f'pkg/long.py:1 f: {_MAX_FUNCTION_LINES + 1} lines',
  ]
