"""Tests for benchmarks/scaling_report.py: the logs of gpu.sh scaling, read back
into rows whose speed-ups are worked out by hand."""

from __future__ import annotations

import json

import pytest

from benchmarks import scaling_report as sr

_EXACT = 1e-12


def _write(tmp_path, name, text):
  (tmp_path / name).write_text(text)


def _lockstep_log(steps, wall):
  lines = ['21 estimates in lockstep']
  for k, (n, x, y) in enumerate(steps):
    lines.append(
      f'step {k:3d}: 21 searches, 21 still searching ({n} simulations {x} s, search {y} s)'
    )
  lines.append(f'wall {wall} s, exit 0')
  return '\n'.join(lines) + '\n'


def test_rows_and_speedups_by_hand(tmp_path):
  _write(
    tmp_path,
    'lockstep_1gpu.log',
    _lockstep_log([(1008, 90.0, 0.1), (504, 40.0, 60.0), (504, 30.0, 50.0)], 300.0),
  )
  _write(
    tmp_path,
    'lockstep_2gpu.log',
    _lockstep_log([(1008, 70.0, 0.2), (504, 25.0, 61.0), (504, 15.0, 49.0)], 250.0),
  )
  for g, (sim, write, wall) in {1: (24.0, 20.0, 100.0), 2: (16.0, 21.0, 80.0)}.items():
    _write(
      tmp_path, f'sweep_{g}gpu.log', f'210 sequences written\nwall {wall} s, exit 0\n'
    )
    summary = {
      'seconds': {
        'simulate_first_batches': sim,
        'simulate': 0.0,
        'render': 0.0,
        'write': write,
      }
    }
    _write(tmp_path, f'sweep_{g}gpu.json', json.dumps(summary))
  _write(tmp_path, 'setup_train.log', 'wall 5.0 s, exit 0\n')  # not a stage run
  rows = sr.rows(str(tmp_path))
  assert [(r['stage'], r['devices']) for r in rows] == [
    ('lockstep', 1), ('lockstep', 2), ('sweep', 1), ('sweep', 2)
  ]  # fmt: skip
  one, two = rows[0], rows[1]
  assert one['simulations'] == 2016 and one['steps'] == 3
  assert one['device_s'] == pytest.approx(70.0, abs=_EXACT)  # steps after the first
  assert two['device_s'] == pytest.approx(40.0, abs=_EXACT)
  assert two['device_speedup'] == pytest.approx(70.0 / 40.0, abs=_EXACT)
  assert two['wall_speedup'] == pytest.approx(300.0 / 250.0, abs=_EXACT)
  assert two['search_s'] == pytest.approx(110.2, abs=1e-9)
  sweep2 = rows[3]
  assert sweep2['device_s'] == pytest.approx(16.0, abs=_EXACT)
  assert sweep2['device_speedup'] == pytest.approx(1.5, abs=_EXACT)
  assert sweep2['write_s'] == pytest.approx(21.0, abs=_EXACT)
  assert '| sweep | 2 | 80.0 s | 1.25x | 16.0 s | 1.50x |' in sr.table(rows)


def test_an_unfinished_run_is_named(tmp_path):
  _write(
    tmp_path,
    'lockstep_2gpu.log',
    _lockstep_log([(1008, 70.0, 0.2)], 1.0).replace('wall 1.0 s, exit 0\n', ''),
  )
  with pytest.raises(ValueError, match='lockstep_2gpu.log'):
    sr.rows(str(tmp_path))


def test_processes_run_at_once_so_the_slowest_counts(tmp_path):
  """A calibration as two processes (launch's ``[i]`` prefixes): each
  process's steps after the first summed, the slower process taken."""
  one = _lockstep_log([(672, 80.0, 0.1), (336, 40.0, 1.0), (336, 38.0, 1.0)], 400.0)
  _write(tmp_path, 'calibrate_1gpu.log', one)
  two = [
    '[0] step   0: 7 searches, 7 still searching (336 simulations 50.0 s, search 0.1 s)',
    '[1] step   0: 7 searches, 7 still searching (336 simulations 55.0 s, search 0.1 s)',
    '[1] step   1: 7 searches, 7 still searching (168 simulations 22.0 s, search 1.0 s)',
    '[0] step   1: 7 searches, 7 still searching (168 simulations 20.0 s, search 2.0 s)',
    '[0] step   2: 7 searches, 0 still searching (168 simulations 21.0 s, search 2.0 s)',
    '[1] step   2: 7 searches, 0 still searching (168 simulations 23.0 s, search 1.0 s)',
    'wall 250.0 s, exit 0',
  ]
  _write(tmp_path, 'calibrate_2gpu.log', '\n'.join(two) + '\n')
  _write(tmp_path, 'calsharded_2gpu.log', one.replace('wall 400.0', 'wall 320.0'))
  rows = {(r['stage'], r['devices']): r for r in sr.rows(str(tmp_path))}
  base, procs = rows['calibrate', 1], rows['calibrate', 2]
  assert base['processes'] == 1 and procs['processes'] == 2
  assert procs['steps'] == 3 and procs['simulations'] == 1344
  assert procs['first_step_s'] == pytest.approx(55.0, abs=_EXACT)
  assert procs['device_s'] == pytest.approx(45.0, abs=_EXACT)  # process 1: 22 + 23
  assert procs['search_s'] == pytest.approx(4.1, abs=1e-9)  # process 0: 0.1 + 2 + 2
  assert procs['device_speedup'] == pytest.approx(78.0 / 45.0, abs=_EXACT)
  assert procs['wall_speedup'] == pytest.approx(400.0 / 250.0, abs=_EXACT)
  # one process over two GPUs is compared with the same one-GPU run
  assert rows['calsharded', 2]['wall_speedup'] == pytest.approx(1.25, abs=_EXACT)
  assert (
    '| calibrate | 2 | 250.0 s | 1.60x | 45.0 s | 1.73x | 2 process(es)'
    in sr.table(list(rows.values()))
  )
