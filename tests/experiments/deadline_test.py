"""experiments.pipeline.deadline and --time_limit: a long job stops between
steps with one line and exit status 75, and the same command resumes."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from experiments.pipeline import deadline

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_forecast_against_what_is_left(monkeypatch):
  monkeypatch.setattr(deadline.time, 'monotonic', lambda: 100.0)
  try:
    deadline.set_limit(30.0, start=80.0)  # 10 s left
    assert deadline.remaining() == pytest.approx(10.0)
    deadline.check(9.0, 'step 1')  # ends in time
    with pytest.raises(deadline.Reached, match=r'before step 2 \(forecast 11 s, 10 s'):
      deadline.check(11.0, 'step 2')
  finally:
    deadline.set_limit(0.0)
  assert deadline.remaining() is None
  deadline.check(1e9, 'anything')  # no limit, no stop
  for bad in (-1.0, float('nan'), float('inf')):
    with pytest.raises(ValueError, match='--time_limit'):
      deadline.set_limit(bad)


def test_a_sweep_past_its_limit_stops_in_one_line_and_resumes(tmp_path):
  # A limit already spent when the first batch would start: no sequence is
  # written, one line names the resume command, exit status 75; the same
  # command without the limit then writes every sequence.
  out = tmp_path / 'sweep'
  cmd = [
    sys.executable, '-m', 'experiments.generate_dataset', '--preset=smoke',
    f'--out={out}', '--materials=gray_interlock', '--sequences=2', '--batch_size=1',
    '--backend=c', '--frames=2', '--resolution=16',
  ]  # fmt: skip
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=_ROOT)
  stopped = subprocess.run(
    cmd + ['--time_limit=1e-6'], env=env, capture_output=True, text=True, timeout=600
  )
  assert stopped.returncode == deadline.EXIT_STATUS, stopped.stderr[-2000:]
  last = stopped.stderr.strip().splitlines()[-1]
  assert last.startswith('stopped before batch 1 of 2') and 'resume with:' in last
  assert 'Traceback' not in stopped.stderr
  assert not (
    out / 'gray_interlock'
  ).exists()  # no sequence (dataset.json: the sweep's record)
  done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
  assert done.returncode == 0, done.stderr[-2000:]
  assert '2 sequences written' in done.stdout


def test_the_launcher_stops_the_others_when_one_reaches_its_limit():
  # Process 0 stops at its limit; process 1 would otherwise wait for it at its
  # next barrier (here: sleep a minute). It is interrupted, and the launch
  # ends with the limit's status.
  import time

  from experiments.pipeline import distributed

  code = (
    'import os, sys, time\n'
    "if os.environ['JAX_PROCESS_ID'] == '0': sys.exit(75)\n"
    'time.sleep(60)\n'
  )
  t0 = time.monotonic()
  status = distributed.launch([sys.executable, '-c', code], 2, env=dict(os.environ))
  assert status == deadline.EXIT_STATUS
  assert time.monotonic() - t0 < 30


def test_sigterm_ends_a_script_as_ctrl_c_does():
  # A batch system's time limit (or the launcher) sends SIGTERM: one line with
  # the resume command and exit status 130, as Ctrl-C.
  code = (
    'import dataclasses, time\n'
    'from experiments.pipeline import cli\n'
    '@dataclasses.dataclass(frozen=True)\n'
    'class A:\n'
    '  """A.\n\n  Attributes:\n    n: a number.\n  """\n'
    '  n: int = 1\n'
    'def main(a):\n'
    "  print('ready', flush=True)\n"
    '  time.sleep(60)\n'
    "cli.run(A, {'default': A()}, main)\n"
  )
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=_ROOT)
  p = subprocess.Popen(
    [sys.executable, '-c', code], env=env, stdout=subprocess.PIPE,
    stderr=subprocess.PIPE, text=True,
  )  # fmt: skip
  try:
    assert p.stdout.readline().strip() == 'ready'
    p.terminate()
    _, err = p.communicate(timeout=30)
  finally:
    p.kill()
  assert p.returncode == 130, err
  assert err.strip().splitlines()[-1].startswith('interrupted; resume with:')
  assert 'Traceback' not in err
