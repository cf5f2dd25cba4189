"""Every benchmark is a script on the scripts' one config mechanism
(``experiments.pipeline.cli``): a frozen ``Args`` with documented fields and
presets, no raw absl flags, no ``sys.path`` edits, run as
``python -m benchmarks.NAME``, and its results by default outside the source
tree."""

from __future__ import annotations

import dataclasses
import importlib
import os
import pathlib
import subprocess
import sys
from unittest import mock

import pytest
from absl import flags

from experiments.pipeline import cli, objective

_ROOT = pathlib.Path(__file__).resolve().parents[2]
NAMES = sorted(
  p.stem for p in (_ROOT / 'benchmarks').glob('*.py') if p.stem != '__init__'
)


def _module(name: str):
  with mock.patch.dict(os.environ):  # some set XLA's settings on import
    return importlib.import_module(f'benchmarks.{name}')


def _presets(mod) -> dict:
  """The presets ``cli.run`` gets (mesh_convergence's wrap its study's)."""
  return {
    k: v if isinstance(v, mod.Args) else mod.Args(study=v)
    for k, v in mod.PRESETS.items()
  }


def test_every_benchmark_is_found():
  assert len(NAMES) >= 16 and 'joint_pairs' in NAMES and 'train_throughput' in NAMES


def test_benchmarks_stays_small():
  # issue 75: at most 25 entries in benchmarks/ (results/ one of them): what
  # BENCHMARKS.md cites; a study run once leaves the tree (git keeps it).
  # Counted in git, so that a script being written beside them does not count.
  proc = subprocess.run(
    ['git', 'ls-files', 'benchmarks'], cwd=_ROOT, capture_output=True, text=True
  )
  if proc.returncode != 0 or not proc.stdout:
    pytest.skip('not a git checkout')
  entries = {p.split('/')[1] for p in proc.stdout.split()}
  assert len(entries) <= 25, (
    f'benchmarks/ has {len(entries)} entries: {sorted(entries)}'
  )


@pytest.mark.parametrize('name', NAMES)
def test_a_benchmark_declares_its_settings_as_the_scripts_do(name):
  text = (_ROOT / 'benchmarks' / f'{name}.py').read_text()
  # the package is not installed: a module that imported it would not run as
  # a file (python benchmarks/NAME.py), as the GPU job scripts run them
  for raw in ('flags.DEFINE', 'FLAGS.', 'sys.path', 'app.run(', 'from benchmarks'):
    assert raw not in text, f'{name}: {raw}'
  assert 'cli.run(' in text and "if __name__ == '__main__':" in text
  mod = _module(name)
  assert dataclasses.is_dataclass(mod.Args)
  assert mod.Args.__dataclass_params__.frozen
  presets = _presets(mod)
  assert 'default' in presets
  cli.leaves(mod.Args)  # every field documented, of a type a flag carries
  fv = flags.FlagValues()
  cli.define_flags(mod.Args, presets, fv)  # flag names unique, presets valid
  for preset in presets.values():  # results go to the user's folder
    for leaf in cli.leaves(mod.Args):
      if leaf.path[-1] in ('out', 'workdir'):
        value = str(getattr(preset, leaf.path[-1]))
        assert not value.startswith('benchmarks'), f'{name}: {value}'


def test_default_json_paths_are_outside_the_source_tree():
  assert _module('physsim_throughput').Args().out == (
    'out/benchmarks/physsim_throughput.json'
  )


def test_a_benchmark_runs_as_a_module_and_names_a_missing_flag(tmp_path):
  env = dict(os.environ, PYTHONPATH=str(_ROOT))
  run = lambda *a: subprocess.run(  # noqa: E731
    [sys.executable, '-m', *a], cwd=_ROOT, env=env, capture_output=True, text=True,
    timeout=300,
  )  # fmt: skip
  helped = run('benchmarks.tables_compare', '--help')
  assert '--tables' in helped.stdout + helped.stderr
  assert helped.returncode == 0  # asking for help is no failure
  missing = run('benchmarks.tables_compare')
  assert missing.returncode == 2
  assert missing.stderr.startswith('error: missing --tables')
  assert 'Traceback' not in missing.stderr


def test_the_latency_benchmark_needs_a_network_only_for_a_distance_that_embeds():
  latency = _module('estimate_latency')
  with pytest.raises(
    ValueError, match='--settings=psd embeds frames: it needs --model'
  ):
    latency.main(latency.Args(recording='/nowhere', settings=('psd',)))
  assert latency.SETTINGS['psd'][1] == {'distance': 'energy'}
  # the default setting is the estimate's default: the shape, no network
  assert latency.SETTINGS['default'][1] == {}
  assert objective.PRESETS['default'].scoring.distance == 'shape'


def test_the_default_fabrics_table_reads_what_the_script_wrote(tmp_path):
  # one estimate.json as experiments.estimate writes it (its fields that the
  # table reads), and the shell's times; a malformed times line is refused
  import json

  from benchmarks import default_fabrics

  entry = lambda v, lo, hi: {'value': v, 'interval_90': [lo, hi],
                             'interval_50': [v, v], 'narrowing_90': 2.0}  # fmt: skip
  result = {
    'config': {'distance': 'shape'},
    'calibration': {
      'matches': True,
      'recalibrated': True,
      'mode': 'video',
      'n_calibration_recordings': 210,
      'setting': 's',
      'coverage': {},
    },  # fmt: skip
    'truth': {'bending_scale': 1.0, 'wind_speed': 3.0, 'area_weight': 0.2},
    'estimate': {
      'bending_scale': entry(1.0, 0.5, 2.0),
      'wind_speed': entry(3.3, 3.1, 3.5),
      'area_weight': entry(0.2, 0.15, 0.25),
    },  # fmt: skip
    'load_ratio': entry(1.0, 0.5, 2.0),
    'errors': {
      'estimate': {
        'wind_speed_pct': 10.0,
        'area_weight_pct': 1.0,
        'bending_factor': 1.0,
        'load_ratio_pct': 5.0,
      }
    },  # fmt: skip
  }
  (tmp_path / 'est_black_denim').mkdir()
  (tmp_path / 'est_black_denim' / 'estimate.json').write_text(json.dumps(result))
  (tmp_path / 'times.txt').write_text('black_denim rc=0 47214 ms\n')
  out = tmp_path / 'df.json'
  default_fabrics.main(default_fabrics.Args(root=str(tmp_path), out=str(out)))
  summary = json.loads(out.read_text())
  row = summary['rows']['black_denim']
  assert row['calibrated'] and not row['indicative'] and row['seconds'] == 47.214
  assert row['held']['wind_speed'] == {'90': False, '50': False}  # 3.0 below 3.1
  assert row['held']['area_weight']['90'] and row['held']['bending_scale']['90']
  assert summary['summary']['calibrated'] == 1
  (tmp_path / 'times.txt').write_text('black_denim 47214\n')
  with pytest.raises(ValueError, match='times.txt:1'):
    default_fabrics.main(default_fabrics.Args(root=str(tmp_path), out=str(out)))


def test_the_warm_start_stages_are_read_from_the_estimates_stamped_lines():
  from benchmarks import warm_start

  jax_log = 'W1129 03:29:48.511306 1406 dispatch.py:204] '
  lines = [
    (2.9, 'gray_interlock: 1 recording into /tmp/w; reading and aligning, then'),
    (8.0, jax_log + 'Finished tracing _fused for jit in 1.5 sec'),
    (8.6, jax_log + 'Finished jaxpr to MLIR module conversion jit(_fused) in 0.5 sec'),
    (9.0, jax_log + "Persistent compilation cache hit for 'jit__fused' with key 'k'"),
    (9.0, jax_log + 'Finished XLA compilation of jit(_fused) in 0.4 sec'),
    (9.1, jax_log + 'Finished XLA compilation of jit(add) in 0.05 sec'),
    (20.0, 'iteration   0: initial design scored (40 simulations 12.0 s, search 0.0 s)'),
    (25.0, 'iteration   1: posterior so far (40 simulations 4.5 s, search 0.5 s)'),
    (30.0, 'iteration   2: posterior so far (40 simulations 4.5 s, search 0.5 s)'),
    (33.0, '| quantity        | true  | point | 50% interval   |'),
  ]  # fmt: skip
  s = warm_start.stages(lines, 36.0)
  want = dict(
    total=36.0, to_table=33.0, imports=2.9, before_search=20.0 - 12.0 - 2.9,
    first_step=12.0, later_steps=10.0, to_table_after_search=3.0,
    after_search=6.0, steps=3,
  )  # fmt: skip
  assert s.keys() == want.keys()
  for k, v in want.items():
    assert s[k] == pytest.approx(v), k
  j = warm_start.jax_times(lines)
  assert j['tracing'] == 1.5 and j['lowering'] == 0.5 and j['cache_hits'] == 1
  assert j['compile_or_load'] == pytest.approx(0.45)
  assert j['top'][0] == ['_fused', 2.4] and j['top'][1] == ['add', 0.05]
