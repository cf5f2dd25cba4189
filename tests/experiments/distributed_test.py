"""experiments.pipeline.distributed: discovery from the environment, shares of
jobs, and two real processes on this machine's CPU joined by jax.distributed."""

import json
import os
import socket
import sys

import numpy as np
import pytest

from experiments.pipeline import distributed
from experiments.studies import calibration

pytestmark = pytest.mark.slow  # several processes simulate and train

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_launch_settings_from_the_environment():
  explicit = {
    'JAX_COORDINATOR_ADDRESS': 'node0:1234', 'JAX_NUM_PROCESSES': '4', 'JAX_PROCESS_ID': '3',
  }  # fmt: skip
  assert distributed.launch_settings(explicit) == dict(
    coordinator_address='node0:1234', num_processes=4, process_id=3
  )
  assert distributed.launch_settings({}) is None
  assert distributed.launch_settings({'SLURM_NTASKS': '8', 'SLURM_PROCID': '2'}) == {}
  assert distributed.launch_settings({'SLURM_NTASKS': '1', 'SLURM_PROCID': '0'}) is None
  assert (
    distributed.launch_settings(
      dict(explicit, JAX_NUM_PROCESSES='1', JAX_PROCESS_ID='0')
    )
    is None
  )
  with pytest.raises(ValueError, match='set all of'):
    distributed.launch_settings({'JAX_NUM_PROCESSES': '2'})
  with pytest.raises(ValueError, match='not in'):
    distributed.launch_settings(dict(explicit, JAX_PROCESS_ID='4'))


def test_shares_are_contiguous_disjoint_and_cover_every_job():
  jobs = list(range(11))
  shares = [distributed.share(jobs, i, 3) for i in range(3)]
  assert sum(shares, []) == jobs
  assert [len(s) for s in shares] in ([4, 4, 3], [4, 3, 4], [3, 4, 4])
  assert distributed.share([], 0, 2) == []


def _free_port():
  with socket.socket() as s:
    s.bind(('localhost', 0))
    return s.getsockname()[1]


def test_two_processes_share_the_jobs_and_a_global_mesh(tmp_path, capsys):
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=_ROOT,
             XLA_FLAGS='--xla_force_host_platform_device_count=2')  # fmt: skip
  worker = os.path.join(_ROOT, 'tests/experiments/distributed_worker.py')
  code = distributed.launch(
    [sys.executable, worker, str(tmp_path)], 2, port=_free_port(), env=env
  )
  out = capsys.readouterr().out
  assert code == 0, out[-3000:]
  line = next(x for x in out.splitlines() if x.startswith('[0] {'))
  result = json.loads(line[4:])
  assert result['count'] == 2 and result['jobs'] == list(range(7))
  # Rows 0, 1 (process 0) and 10, 11 (process 1) on four devices.
  assert result['total'] == 22.0
  owners = {
    json.loads((tmp_path / f'job{j}.json').read_text())['process'] for j in range(7)
  }
  assert owners == {0, 1}
  # A failing process's exit status is the launch's.
  fail = [
    sys.executable,
    '-c',
    'import os, sys; sys.exit(3 * int(os.environ["JAX_PROCESS_ID"]))',
  ]
  assert distributed.launch(fail, 2, port=_free_port(), env=env) == 3


def test_table1_as_two_processes_trains_each_run_once(rgb_dataset, tmp_path, capsys):
  # The real script under the launcher: each process trains its share, its
  # checkpoints its own (orbax's shared multi-host writer does not fit), and
  # process 0 writes the table once both have finished.
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=_ROOT)
  workdir = tmp_path / 't1'
  command = [
    sys.executable, '-m', 'experiments.table1', '--preset=smoke',
    f'--dataset={rgb_dataset}', f'--workdir={workdir}', '--columns=physnet_depth',
    '--splits=simulation,random', '--epochs=2',
  ]  # fmt: skip
  code = distributed.launch(command, 2, port=_free_port(), env=env)
  out = capsys.readouterr().out
  assert code == 0, out[-3000:]
  trained = [x for x in out.splitlines() if 'training on' in x]
  assert sorted(x[:3] for x in trained) == ['[0]', '[1]']  # one run each
  assert (workdir / 'table1.md').is_file()
  for split in ('simulation', 'random'):  # one fabric, two runs
    run = workdir / 'physnet_depth' / split / 'gray_interlock'
    steps = os.listdir(run / 'checkpoints')
    assert steps and all(
      (run / 'checkpoints' / s / 'state.msgpack').is_file() for s in steps
    )
  # A later single-process estimate loads what a process trained.
  from experiments.pipeline import embedding

  net = embedding.load_embedding(str(run))
  assert net.image_size == (32, 32)


def test_dataset_sweep_as_two_processes_equals_one(tmp_path, capsys):
  # generate_dataset under the launcher: each process simulates and renders
  # its share of the batches into the one folder; process 0 indexes them all.
  # Frames, poses and parameters are those of a one-process sweep.
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=_ROOT)
  flags_ = [
    '--preset=smoke', '--materials=gray_interlock', '--sequences=4', '--batch_size=1',
    '--backend=c', '--workers=1', '--frames=3', '--resolution=24',
  ]  # fmt: skip
  two, one = tmp_path / 'two', tmp_path / 'one'
  command = [sys.executable, '-m', 'experiments.generate_dataset', f'--out={two}']
  code = distributed.launch(command + flags_, 2, port=_free_port(), env=env)
  out = capsys.readouterr().out
  assert code == 0, out[-3000:]
  from physsim import dataset

  rows = dataset.open_dataset(str(two)).rows
  assert len(rows) == 4
  summary = json.loads((two / 'summary.json').read_text())
  assert summary['processes'] == 2 and summary['sequences_written'] == 4
  code = distributed.launch(
    [sys.executable, '-m', 'experiments.generate_dataset', f'--out={one}'] + flags_,
    1, port=_free_port(), env=env,
  )  # fmt: skip
  assert code == 0, capsys.readouterr().out[-3000:]
  for r in rows:
    a, b = (
      dataset.read_sequence(dataset.sequence_dir(str(root), r['material'], r['seq_id']))
      for root in (two, one)
    )
    np.testing.assert_array_equal(a.depth, b.depth)


def test_calibration_as_two_processes_estimates_as_one(tmp_path, capsys):
  # The calibration study under the launcher (the scaling benchmark's
  # calibrate stage): each process estimates its share of the recordings
  # (here one each: the single-estimate path) while one process estimates
  # both in one lockstep; the posteriors are the same (MuJoCo C, same keys).
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=_ROOT)
  flags_ = [
    '--preset=smoke', '--distance=shape', '--materials=gray_interlock', '--pairs=1',
    '--backend=c', '--simulate_only',
  ]  # fmt: skip
  runs = {}
  for n in (2, 1):
    workdir = tmp_path / f'p{n}'
    command = [sys.executable, '-m', 'experiments.calibrate', f'--workdir={workdir}']
    code = distributed.launch(command + flags_, n, port=_free_port(), env=env)
    out = capsys.readouterr().out
    assert code == 0, out[-3000:]
    assert (workdir / 'packed' / 'runs-000.npz').is_file()
    # process 0 packed both, the other's gathered from its files (each
    # process read and set up its own share alone)
    packed = calibration.packed_runs(str(workdir))
    assert sorted(r['seq'] for r in packed) == [0, 1]
    if n == 2:
      assert out.count('1 of 2 recordings in lockstep') == 2, out[-3000:]
    runs[n] = {
      s: json.loads((workdir / 'estimates' / s / 'estimate.json').read_text())
      for s in ('0000', '0001')
    }
  for s in ('0000', '0001'):
    a, b = runs[2][s], runs[1][s]
    assert a['truth'] == b['truth']
    assert a['evaluations'] == b['evaluations']
    for name, fields in b['estimate'].items():  # MuJoCo C, the same draws
      for field, value in fields.items():
        np.testing.assert_allclose(
          a['estimate'][name][field], value, rtol=1e-6, err_msg=f'{name} {field}'
        )
