"""The estimate's defaults on one recording of each fabric, as a user runs them.

Reads what ``benchmarks/gpu.sh fabrics`` left under ``--root``: each
fabric's ``est_<fabric>/estimate.json`` (a paper-size estimate with nothing
but the recording, its fabric and a workdir given: the default distance, the
sheet's shape) and ``times.txt`` (process start to table, from the shell).
Prints per fabric whether the estimate quoted measured coverage (issue 41:
never "indicative" at paper size for any of the 7 fabrics), its errors and
which 90% / 50% intervals held the truth, and writes JSON.

  bash benchmarks/gpu.sh fabrics_make /tmp/df
  bash benchmarks/gpu.sh fabrics /tmp/df
  python -m benchmarks.default_fabrics --root=/tmp/df --out=/tmp/df/default_fabrics.json
"""

from __future__ import annotations

import dataclasses
import glob
import os

import numpy as np

import physsim
from experiments.pipeline import cli, files, summaries, table_notes

_QUANTITIES = ('bending_scale', 'wind_speed', 'area_weight', 'load_ratio')


@dataclasses.dataclass(frozen=True)
class Args:
  """Where the runs are.

  Attributes:
    root: the folder ``gpu.sh fabrics`` wrote.
    out: the JSON summary.
  """

  root: str = cli.required()
  out: str = 'out/benchmarks/default_fabrics.json'


PRESETS = {'default': Args()}


def read_times(path: str) -> dict[str, dict]:
  """``{fabric: {'rc', 'seconds'}}`` from ``times.txt`` lines
  ``<fabric> rc=<status> <ms> ms`` (a fabric run twice: its last line)."""
  out = {}
  if not os.path.isfile(path):
    return out
  with open(path) as f:
    for n, line in enumerate(f, 1):
      parts = line.split()
      if len(parts) != 4 or not parts[1].startswith('rc=') or parts[3] != 'ms':
        raise ValueError(f'{path}:{n}: not "<fabric> rc=<status> <ms> ms": {line!r}')
      out[parts[0]] = {'rc': int(parts[1][3:]), 'seconds': int(parts[2]) / 1000}
  return out


def row(result: dict) -> dict:
  """One estimate's line: whether it quoted measured coverage, its errors,
  and which intervals held the truth."""
  note = result.get('calibration') or {}
  line = table_notes.calibration_line(note or None)
  cov = summaries.covered(result, result['truth'])
  held = {q: {lv: cov[q][f'interval_{lv}'] for lv in (90, 50)} for q in _QUANTITIES}
  return {
    'distance': result['config']['distance'],
    'calibrated': bool(note.get('matches') and note.get('recalibrated')),
    'indicative': 'indicative' in line,
    'mode': note.get('mode'),
    'errors': result['errors']['estimate'],
    'held': held,
    'narrowing_90': {q: result['estimate'][q]['narrowing_90'] for q in _QUANTITIES[:3]},
  }


def main(args: Args) -> None:
  paths = sorted(glob.glob(os.path.join(args.root, 'est_*', 'estimate.json')))
  if not paths:
    raise ValueError(f'--root={args.root}: no est_*/estimate.json there')
  times = read_times(os.path.join(args.root, 'times.txt'))
  rows = {}
  for path in paths:
    fabric = os.path.basename(os.path.dirname(path))[len('est_') :]
    rows[fabric] = {**row(physsim.dataset.read_json(path)), **times.get(fabric, {})}
  print('| fabric | distance | calibrated | wind | area weight | bending | '
        '90% held (b, v, w, ratio) | 50% held | process s |')  # fmt: skip
  print('|---|---|---|---|---|---|---|---|---|')
  for fabric, r in rows.items():
    e = r['errors']
    mark = lambda lv, r=r: ''.join(
      'y' if r['held'][q][lv] else 'n' for q in _QUANTITIES
    )
    print(
      f'| {fabric} | {r["distance"]} | {"yes" if r["calibrated"] else "no"} | '
      f'{e["wind_speed_pct"]:.1f}% | {e["area_weight_pct"]:.1f}% | '
      f'x{e["bending_factor"]:.2f} | {mark(90)} | {mark(50)} | '
      f'{r.get("seconds", float("nan")):.1f} |'
    )
  summary = {
    'estimates': len(rows),
    'calibrated': sum(r['calibrated'] for r in rows.values()),
    'indicative': sum(r['indicative'] for r in rows.values()),
    'wind_mean_pct': float(
      np.mean([r['errors']['wind_speed_pct'] for r in rows.values()])
    ),
    'held_90': {
      q: float(np.mean([r['held'][q][90] for r in rows.values()])) for q in _QUANTITIES
    },
    'held_50': {
      q: float(np.mean([r['held'][q][50] for r in rows.values()])) for q in _QUANTITIES
    },
  }
  print(
    f'\n{summary["calibrated"]} of {summary["estimates"]} quoted measured coverage '
    f'({summary["indicative"]} indicative); wind {summary["wind_mean_pct"]:.1f}% mean'
  )
  files.write_json(args.out, {'root': args.root, 'summary': summary, 'rows': rows})


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
