"""Several runs of ``experiments.tables`` on one evaluation set, side by side.

Per run (a label and its ``tables.json``): the mean error of the reported
point and of the posterior median for wind, area weight, bending (geometric
mean factor) and the load ratio, and how many 90% and 50% credible intervals
held the truth. Used to compare networks (one network against an ensemble of
several, ``--models=a,b,c``) on the same recordings and readings. No
simulation: seconds on a CPU.

  python -m benchmarks.tables_compare \
    --tables=single=out/t_single/tables.json,ensemble=out/t_ens/tables.json \
    --out=compare.json
  # several evaluation sets estimated by one network, pooled in one row:
  python -m benchmarks.tables_compare --tables=video=a/tables.json+b/tables.json
  # estimate.json files (quote the pattern), e.g. a calibration check's:
  python -m benchmarks.tables_compare --tables="check=out/check/estimates/*/estimate.json"
"""

from __future__ import annotations

import dataclasses
import glob
import json

import numpy as np

import physsim
from experiments.pipeline import cli, files, summaries
from experiments.pipeline import posterior as posterior_lib
from experiments.studies import tables as tables_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """The comparison of ``experiments.tables`` runs.

  Attributes:
    tables: label=tables.json pairs (comma-separated; required);
      label=a.json+b.json pools runs.
    out: JSON path.
  """

  tables: tuple[str, ...] = cli.required(())
  out: str = 'out/benchmarks/tables_compare.json'


PRESETS = {'default': Args()}
ERRORS = tables_lib.ERRORS
QUANTITIES = ('wind_speed', 'area_weight', 'bending_scale', 'load_ratio')


def summarise(estimates: list[dict]) -> dict:
  """Mean errors (point, posterior median) and coverage counts of finished
  estimates (``tables.json``'s ``estimates`` values) that know their truth."""
  rows = [e for e in estimates if 'truth' in e and 'covered' in e]
  point = {k: [] for k in ERRORS}
  median = {k: [] for k in ERRORS}
  held = {f'{q}_{lvl}': 0 for q in QUANTITIES for lvl in ('90', '50')}
  spread = []  # the load ratio's 90% half-width over its median: what the video says
  for e in rows:
    space = physsim.search_space(e['material'])
    mid = physsim.params.make(
      *(e['estimate'][f]['median'] for f in posterior_lib.FIELDS)
    )
    med = summaries.errors(mid, e['truth'], space)['estimate']
    for k in ERRORS:
      point[k].append(e['errors']['estimate'][k])
      median[k].append(med[k])
    lo, hi = e['load_ratio']['interval_90']
    spread.append(50 * (hi - lo) / e['load_ratio']['median'])
    for q in QUANTITIES:
      for lvl in ('90', '50'):
        held[f'{q}_{lvl}'] += bool(e['covered'][q][f'interval_{lvl}'])
  return {
    'n': len(rows),
    'point': {k: summaries.mean_error(v, k) for k, v in point.items()},
    'median': {k: summaries.mean_error(v, k) for k, v in median.items()},
    'held': held,
    'load_ratio_half_width_90_pct': float(np.mean(spread)),
  }


def load(paths: str) -> list[dict]:
  """The estimates of ``'A+B+...'``: each a ``tables.json`` (many estimates)
  or an ``estimate.json`` (one), or a glob pattern of them.

  Raises:
    ValueError: a pattern that matches nothing, naming it.
  """
  estimates = []
  for pattern in paths.split('+'):
    found = sorted(glob.glob(pattern))
    if not found:
      raise ValueError(f'--tables: nothing matches {pattern!r}')
    for path in found:
      with open(path) as f:
        d = json.load(f)
      estimates += list(d['estimates'].values()) if 'estimates' in d else [d]
  return estimates


def _row(label: str, s: dict) -> str:
  def cell(k):
    p, m = s['point'][k], s['median'][k]
    return f'x{p:.2f} (x{m:.2f})' if k == 'bending_factor' else f'{p:.1f}% ({m:.1f}%)'

  held = ', '.join(str(s['held'][f'{q}_90']) for q in QUANTITIES)
  held50 = ', '.join(str(s['held'][f'{q}_50']) for q in QUANTITIES)
  return (
    f'| {label} | {s["n"]} | '
    + ' | '.join(cell(k) for k in ERRORS)
    + f' | {held} / {held50} | {s["load_ratio_half_width_90_pct"]:.0f}% |'
  )


def main(args: Args) -> None:
  out = {}
  for item in args.tables:
    label, _, paths = item.partition('=')
    if not paths:
      raise ValueError(f'--tables: {item!r} is not label=path[+path...]')
    out[label] = summarise(load(paths))
  print(
    '| run | n | wind | area weight | bending | load ratio | 90% / 50% held '
    '(wind, area weight, bending, load ratio) | load ratio 90% half-width |'
  )
  print('|---|---:|---|---|---|---|---|---:|')
  for label, s in out.items():
    print(_row(label, s))
  print(
    'Mean error of the reported point (of the posterior median in brackets); '
    "the load ratio's 90% interval, half its width over its median, averaged."
  )
  files.write_json(args.out, out)
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
