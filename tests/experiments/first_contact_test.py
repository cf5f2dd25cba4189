"""A newcomer's first contact with the scripts (issue 78): one name for the
camera flag across scripts, docstring examples that paste into a shell as
written."""

from __future__ import annotations

import ast
import pathlib

import pytest

from experiments import overhang
from experiments.pipeline import cli

_ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = sorted(
  p.stem for p in (_ROOT / 'experiments').glob('*.py') if p.stem != '__init__'
)


def test_overhang_names_the_camera_as_estimate_does():
  argv = ['overhang', '--overhang=0.05', '--depth=strip']
  got = cli.parse(overhang.Args, overhang.PRESETS, [*argv, '--camera_json=c.json'])
  assert got.camera == 'c.json'
  # The older name still answers, as an alias of the same flag.
  old = cli.parse(overhang.Args, overhang.PRESETS, [*argv, '--camera=d.json'])
  assert old.camera == 'd.json'
  with pytest.raises(ValueError, match='needs --camera_json'):
    overhang.main(overhang.Args(overhang=(0.05,), depth=('strip',)))


def _module_docstring_source(path: pathlib.Path) -> str:
  src = path.read_text()
  node = ast.parse(src).body[0]
  return ast.get_source_segment(src, node) or ''


@pytest.mark.parametrize('name', SCRIPTS)
def test_docstring_examples_keep_their_line_continuations(name):
  """A backslash at a line's end in a plain docstring is an escape: Python
  drops it and the newline, so --help showed the example's lines run
  together. Raw docstrings (or doubled backslashes) keep them."""
  path = _ROOT / 'experiments' / f'{name}.py'
  seg = _module_docstring_source(path)
  raw = seg[:1].lower() == 'r'
  if raw:
    return
  lines = seg.splitlines()
  broken = [
    k + 1 for k, line in enumerate(lines)
    if line.endswith('\\') and not line.endswith('\\\\')
  ]  # fmt: skip
  assert not broken, f'experiments/{name}.py: line(s) {broken} end in a lone backslash'
  doc = ast.get_docstring(ast.parse(path.read_text()), clean=False) or ''
  for line in doc.splitlines():
    assert not line.rstrip().endswith('\\') or line.rstrip().endswith(' \\'), line


def test_the_licence_pyproject_names_is_at_the_root():
  text = (_ROOT / 'LICENSE').read_text()
  assert 'Apache License' in text and 'Version 2.0, January 2004' in text
  assert 'END OF TERMS AND CONDITIONS' in text
  assert 'Apache-2.0' in (_ROOT / 'pyproject.toml').read_text()


@pytest.mark.parametrize('name', ['estimate', 'plan', 'demo', 'calibrate'])
def test_an_empty_workdir_is_refused_by_name(name):
  """'--workdir=' (a shell variable never set) was "No such file or
  directory: ''"."""
  import importlib  # noqa: PLC0415

  script = importlib.import_module(f'experiments.{name}')
  presets = getattr(script, 'PRESETS', {'default': script.Args()})
  for value in ('', '  '):
    with pytest.raises(ValueError, match=r'^--workdir: empty$'):
      cli.parse(script.Args, presets, [name, f'--workdir={value}'])
  # a flag whose empty value means "none" stays accepted
  if name == 'estimate':
    got = cli.parse(script.Args, presets, [name, '--workdir=w', '--camera_json='])
    assert got.camera_json == ''


def test_estimate_help_leads_with_the_flags_a_person_needs():
  """--help was 345 lines of 72 flags in alphabetical order; it now lists
  the key ones, and --helpfull all."""
  import re  # noqa: PLC0415

  from absl import flags  # noqa: PLC0415

  from experiments import estimate  # noqa: PLC0415

  fv = flags.FlagValues()
  cli.define_flags(
    estimate.Args, estimate.PRESETS, fv, module_name='est', key_flags=estimate.KEY_FLAGS
  )
  short = set(re.findall(r'^\s+--(?:\[no\])?(\w+):', fv.module_help('est'), re.M))
  full = set(re.findall(r'^\s+--(?:\[no\])?(\w+):', fv.get_help(), re.M))
  assert short == set(estimate.KEY_FLAGS) and len(short) <= 25
  assert {'recording', 'camera_json', 'workdir', 'material'} <= short
  assert {'n_init', 'q', 'posterior_grid', 'verbose'} <= full - short
  assert len(full) > 60
  with pytest.raises(ValueError, match=r"key flags \['recordings'\]"):
    cli.define_flags(
      estimate.Args, estimate.PRESETS, flags.FlagValues(), key_flags=['recordings']
    )


def test_an_error_line_is_at_most_300_characters_naming_its_flag():
  e = ValueError('--nodes=' + 'x' * 10_000 + ': need 1 to 16')
  line = cli.one_line(e)
  assert len(line) <= cli.MAX_LINE and line.startswith('--nodes=xxx')
  assert line.endswith('(10022 characters)')
  assert cli.one_line(ValueError('a\nb')) == 'a; b'


def test_a_line_break_in_a_list_flag_is_one_line_and_exit_status_2(tmp_path):
  """absl parses list flags as CSV: its error, a line break, still one line."""
  import os  # noqa: PLC0415
  import subprocess  # noqa: PLC0415
  import sys  # noqa: PLC0415

  out = subprocess.run(
    [sys.executable, '-m', 'experiments.plan', f'--workdir={tmp_path}',
     '--candidates=a\nb,c'],
    capture_output=True, text=True, cwd=_ROOT, timeout=300,
    env=dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=str(_ROOT)),
  )  # fmt: skip
  lines = [x for x in out.stderr.splitlines() if x.startswith('error')]
  assert out.returncode == 2, out.stderr[-2000:]
  assert len(lines) == 1 and lines[0].startswith('error: flag --candidates=a; b,c')


def test_an_int_flag_of_hundreds_of_digits_is_refused_by_name():
  """check_numbers raised OverflowError (a traceback) on such an int."""
  from experiments import plan  # noqa: PLC0415

  argv = ['plan', '--workdir=w', '--seed=' + '9' * 400]
  with pytest.raises(ValueError, match=r'^--seed=9{20}\.\.\.: 400 digits, too large'):
    cli.parse(plan.Args, plan.PRESETS, argv)
  argv = ['plan', '--workdir=w', '--nodes=' + '9' * 400]
  with pytest.raises(ValueError, match=r'^--nodes=9{20}\.\.\.: need 1 to 1000'):
    cli.parse(plan.Args, plan.PRESETS, argv)


@pytest.mark.parametrize('name', SCRIPTS)
def test_every_count_flag_is_bounded_before_the_script_runs(name):
  """A count or size of a billion on the command line is refused by cli
  before any script allocates by it (plan --nodes=1e9 ran out of memory)."""
  import importlib  # noqa: PLC0415

  script = importlib.import_module(f'experiments.{name}')
  presets = getattr(script, 'PRESETS', {'default': script.Args()})
  ints = [
    leaf.flag for leaf in cli.leaves(script.Args)
    if cli._parser(leaf.type, leaf.flag)[0] == 'int' and 'seed' not in leaf.flag
  ]  # fmt: skip
  for flag in ints:
    for value in (10**9, -1):
      argv = [name, '--workdir=w', '--out=o', f'--{flag}={value}']
      argv = [a for a in argv if a.split('=')[0][2:] in _flags_of(script) or a == name]
      with pytest.raises(ValueError, match=rf'^--{flag}={value}: need'):
        cli.parse(script.Args, presets, argv)


def _flags_of(script) -> set[str]:
  return {leaf.flag for leaf in cli.leaves(script.Args)}
