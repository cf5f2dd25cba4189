"""experiments.plan's first contact (issue 78): every count and size bounded
before anything is read or allocated, and progress with the time left."""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest

import physsim
from experiments import plan as script
from experiments.pipeline import cli
from experiments.studies import (
  protocol_candidates,
  protocol_config,
  protocol_plan,
  protocol_slopes,
)


@pytest.mark.parametrize(
  ('flag', 'message'),
  [('--nodes=1000000000', r'--nodes=1000000000: need 1 to 1000'),
   ('--nodes=17', r'--nodes=17: need 1 to 16'),
   ('--nodes=0', r'--nodes=0: need 1 to'),
   ('--draws=0', r'--draws=0: need 3 to 64'),
   ('--draws=2', r'--draws=2: need 3 to 64'),
   ('--clip=1e9', r'--clip=1e\+09: need 0.25 to 10 s'),
   ('--reading=-1', r'--reading=-1: need 0 to 1'),
   ('--candidates=sheet_1e9cm_2ms_r9', r'--candidates: candidate .sheet_1e9cm'),
   ('--candidates=sheet_100cm_2ms_r9,sheet_100cm_2ms_r9',
    r'--candidates: sheet_100cm_2ms_r9 listed twice'),
   ('--candidates=' + ','.join([f'sheet_100cm_{v}ms_r9' for v in range(1, 41)]),
    r'--candidates=40 given: need 1 to 32')],
)  # fmt: skip
def test_counts_and_sizes_are_bounded_before_anything_is_read(tmp_path, flag, message):
  workdir = tmp_path / 'nowhere'
  t0 = time.perf_counter()
  with pytest.raises(ValueError, match=message) as e:
    argv = ['plan', f'--workdir={workdir}', flag]
    script.main(cli.parse(script.Args, script.PRESETS, argv))
  assert time.perf_counter() - t0 < 1.0 and len(str(e.value)) <= 300
  assert not workdir.exists()


def test_plan_shows_its_progress_and_time_left(tmp_path, monkeypatch, capsys):
  """Each candidate and node a step of the bar; cached ones counted, not
  timed (a second run says nothing is left to simulate)."""
  rng = np.random.default_rng(0)
  u = rng.uniform(-1, 1, (200, 3))
  space = physsim.search_space('gray_interlock')
  np.savez(tmp_path / 'posterior.npz', samples=u, bounds=space.bounds())
  (tmp_path / 'estimate.json').write_text(json.dumps({'material': 'gray_interlock'}))
  calls = []

  def fake(c, bending, area_weight, config, cache_dir, key):
    calls.append(c.name)
    time.sleep(0.01)
    path = protocol_slopes.slope_path(c, bending, area_weight, config, cache_dir)
    os.makedirs(cache_dir, exist_ok=True)
    row = {'wind': c.wind, 'slopes': [[1.0, 0.5, 0.2]] if c.wind else [[1.0, 0.5]],
           'noise_cov': [[0.1]]}  # fmt: skip
    with open(path, 'w') as f:
      json.dump(row, f)
    return row

  monkeypatch.setattr(protocol_slopes, 'candidate_slopes', fake)
  names = ('sheet_100cm_2ms_r5', 'swatch_20cm_still_r5', 'sheet_100cm_5ms_r5')
  args = script.Args(workdir=str(tmp_path), candidates=names, nodes=2, draws=3)
  script.main(args)
  err = capsys.readouterr().err
  assert len(calls) == 6
  assert 'plan: slopes' in err and '6/6 (100%)' in err and 'left' in err, err
  calls.clear()
  script.main(args)
  assert len(calls) == 6  # the real one would read its cache: counted, not timed
  err = capsys.readouterr().err
  assert '6/6 (100%)' in err and 'all found done' in err and 'compiling' not in err


@pytest.mark.parametrize(
  'content',
  ['{"slopes": [[1', '[]', '{"wind": 0}', '{"wind": 0, "slopes": [[1, 2]], '
   '"noise_cov": [[1, 2], [3, 4]]}', '{"wind": 0, "slopes": [[NaN, 2]], '
   '"noise_cov": [[1]]}', '\xff\xfe'],
)  # fmt: skip
def test_a_damaged_cached_slope_file_is_named(tmp_path, content):
  c = protocol_candidates.parse('swatch_20cm_still_r5')
  config = protocol_config.Config(draws=3, clip=0.5)
  path = protocol_slopes.slope_path(c, 1.0, 0.2, config, str(tmp_path))
  with open(path, 'w', encoding='latin-1') as f:
    f.write(content)
  with pytest.raises(ValueError, match=r'a damaged cached slope file') as e:
    protocol_slopes.candidate_slopes(c, 1.0, 0.2, config, str(tmp_path), None)
  assert str(e.value).startswith(path) and len(str(e.value)) <= 300


def test_the_command_leads_with_its_progress_not_jaxs_tpu_line(tmp_path):
  """A rerun from cached slopes: its first line is the bar's, not JAX's
  "Unable to initialize backend 'tpu'"."""
  import dataclasses  # noqa: PLC0415
  import pathlib  # noqa: PLC0415
  import subprocess  # noqa: PLC0415
  import sys  # noqa: PLC0415

  from experiments.pipeline import layout  # noqa: PLC0415

  space = physsim.search_space('gray_interlock')
  u = np.random.default_rng(0).uniform(-1, 1, (200, 3))
  np.savez(tmp_path / 'posterior.npz', samples=u, bounds=space.bounds())
  (tmp_path / 'estimate.json').write_text(json.dumps({'material': 'gray_interlock'}))
  smoke = script.PRESETS['smoke']
  material, draws, _ = layout.read_draws(str(tmp_path))
  config = protocol_config.Config(
    draws=smoke.draws, clip=smoke.clip, warmup=0.25, seed=0
  )
  config = dataclasses.replace(config, material=material)
  b, w = np.exp(protocol_plan.node_values(draws, 1)[0])
  cache = tmp_path / protocol_plan.PLAN_CACHE_DIR / f'clip{smoke.clip:g}_draws3_seed0'
  for name in smoke.candidates:
    c = protocol_candidates.parse(name)
    path = protocol_slopes.slope_path(c, float(b), float(w), config, str(cache))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    row = {'wind': c.wind, 'slopes': [[1.0, 0.5, 0.2]] if c.wind else [[1.0, 0.5]],
           'noise_cov': [[0.1]]}  # fmt: skip
    pathlib.Path(path).write_text(json.dumps(row))
  root = pathlib.Path(__file__).resolve().parents[2]
  out = subprocess.run(
    [sys.executable, '-m', 'experiments.plan', f'--workdir={tmp_path}',
     '--preset=smoke'],
    capture_output=True, text=True, cwd=root, timeout=300,
    env=dict(os.environ, PYTHONPATH=str(root)),
  )  # fmt: skip
  assert out.returncode == 0, out.stderr[-2000:]
  first = out.stderr.splitlines()[0]
  assert first.startswith('plan: slopes: 2/2 (100%)') and 'all found done' in first
  assert "backend 'tpu'" not in out.stderr and 'Next recording' in out.stdout
