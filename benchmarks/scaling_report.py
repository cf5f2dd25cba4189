"""The table of ``benchmarks/gpu.sh scaling``: the same program on 1 and N GPUs.

  python -m benchmarks.scaling_report --logs=out/gpu_scaling

Reads the script's logs (``sweep_<N>gpu.log`` with the sweep's
``summary.json`` copied beside it as ``sweep_<N>gpu.json``, and
``lockstep_<N>gpu.log``) and prints, per stage and device count, the wall time
of the whole command and of its device work after compile, each as a speed-up
over the one-device run of the same stage:

* the sweep: its simulation seconds from ``summary.json`` (with the render
  seconds of batches after the first; the first render call, which compiles,
  is left out; a one-batch sweep's simulation includes the batch program's
  compile, under a second with the warm Warp cache) and the files' writing
  apart;
* the lockstep estimate: the seconds of its simulation steps after the first
  (the lines ``step k: ... (S simulations X s, search Y s)``, or
  ``iteration k: ...`` where a process has one recording: the first
  step compiles the fused objective) and the searches' own time;
* the calibration study (``calibrate_<N>gpu.log``: N processes of one GPU
  each, their lines prefixed ``[i]`` by ``experiments.launch``;
  ``calsharded_<N>gpu.log``: one process over N GPUs): as the lockstep, each
  process's steps summed and the slowest process taken, since they run at
  once.

Writes the rows as JSON (``--out``).
"""

from __future__ import annotations

import dataclasses
import json
import os
import re

from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The scaling report.

  Attributes:
    logs: ``gpu.sh scaling``'s $OUT.
    out: JSON output (empty: LOGS/scaling.json).
  """

  logs: str = 'out/gpu_scaling'
  out: str = ''


PRESETS = {'default': Args()}

_WALL = re.compile(r'^wall ([\d.]+) s, exit (-?\d+)$', re.M)
_STEP = re.compile(
  r'^(?:\[(\d+)\] )?(?:step|iteration) +(\d+): .*\((\d+) simulations ([\d.]+) s, '
  r'search ([\d.]+) s(?:; [^)]*)?\)$',
  re.M,
)
_LOG = re.compile(r'^(sweep|lockstep|calibrate|calsharded)_(\d+)gpu\.log$')


def _wall(text: str, path: str) -> tuple[float, int]:
  m = _WALL.findall(text)
  if not m:
    raise ValueError(f'{path}: no "wall S s, exit RC" line (did the run finish?)')
  return float(m[-1][0]), int(m[-1][1])


def sweep_row(log: str, devices: int) -> dict:
  """One sweep run: wall, simulate + render and write seconds."""
  with open(log) as f:
    wall, rc = _wall(f.read(), log)
  row = {'stage': 'sweep', 'devices': devices, 'wall_s': wall, 'exit': rc}
  summary = log[: -len('.log')] + '.json'
  if os.path.exists(summary):
    with open(summary) as f:
      s = json.load(f)['seconds']
    row['device_s'] = sum(
      s.get(k, 0.0) for k in ('simulate_first_batches', 'simulate', 'render')
    )
    row['write_s'] = s.get('write', 0.0)
  return row


def lockstep_row(log: str, devices: int, stage: str = 'lockstep') -> dict:
  """One lockstep run: wall, and its steps after the first (compiled); with
  several processes (lines ``[i] step ...``), each process's sums and the
  slowest process's seconds."""
  with open(log) as f:
    text = f.read()
  wall, rc = _wall(text, log)
  by_proc: dict[str, list] = {}
  for proc, k, n, x, y in _STEP.findall(text):
    by_proc.setdefault(proc, []).append((int(k), int(n), float(x), float(y)))
  steps = [s for ss in by_proc.values() for s in ss]
  later = {p: [s for s in ss if s[0] > 0] for p, ss in by_proc.items()}
  firsts = [s[2] for s in steps if s[0] == 0]
  return {
    'stage': stage,
    'devices': devices,
    'processes': max(len(by_proc), 1),
    'wall_s': wall,
    'exit': rc,
    'steps': max((len(ss) for ss in by_proc.values()), default=0),
    'simulations': sum(s[1] for s in steps),
    'first_step_s': max(firsts) if firsts else None,
    'device_s': max(sum(s[2] for s in ss) for ss in later.values())
    if any(later.values())
    else None,
    'search_s': max(sum(s[3] for s in ss) for ss in by_proc.values())
    if by_proc
    else 0.0,
    'simulations_after_first': sum(s[1] for ss in later.values() for s in ss),
  }


def rows(logs: str) -> list[dict]:
  """Every run in ``logs``, with speed-ups over the same stage's one-device run."""
  out = []
  for name in sorted(os.listdir(logs)):
    m = _LOG.match(name)
    if not m:
      continue
    path, devices = os.path.join(logs, name), int(m[2])
    if m[1] == 'sweep':
      out.append(sweep_row(path, devices))
    else:
      out.append(lockstep_row(path, devices, m[1]))
  out.sort(key=lambda r: (r['stage'], r['devices']))
  for r in out:
    stage = 'calibrate' if r['stage'] == 'calsharded' else r['stage']
    base = next((b for b in out if b['stage'] == stage and b['devices'] == 1), None)
    for k in ('wall_s', 'device_s'):
      if base and base.get(k) and r.get(k):
        r[k.replace('_s', '_speedup')] = base[k] / r[k]
  return out


def table(rs: list[dict]) -> str:
  def f(x, fmt):
    return '' if x is None else fmt.format(x)

  lines = [
    '| stage | GPUs | wall | speed-up | device work after compile | speed-up | other |',
    '|---|---:|---:|---:|---:|---:|---|',
  ]
  for r in rs:
    if r['stage'] == 'sweep':
      other = f(r.get('write_s'), 'writing files {:.1f} s')
    else:
      other = (
        f'{r["processes"]} process(es); '
        * (r['stage'] != 'lockstep')
        + f'{r["steps"]} steps, {r["simulations"]} simulations; first step '
        f'{f(r["first_step_s"], "{:.1f}")} s; searches {r["search_s"]:.1f} s'
      )
    lines.append(
      f'| {r["stage"]} | {r["devices"]} | {r["wall_s"]:.1f} s | '
      f'{f(r.get("wall_speedup"), "{:.2f}x")} | {f(r.get("device_s"), "{:.1f} s")} | '
      f'{f(r.get("device_speedup"), "{:.2f}x")} | {other} |'
    )
  return '\n'.join(lines)


def main(args: Args) -> None:
  rs = rows(args.logs)
  if not rs:
    raise ValueError(
      f'{args.logs}: no sweep_, lockstep_, calibrate_ or calsharded_<N>gpu.log'
    )
  out = args.out or os.path.join(args.logs, 'scaling.json')
  files.write_json(out, rs)
  print(table(rs))
  print(f'wrote {out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
