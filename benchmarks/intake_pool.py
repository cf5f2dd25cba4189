"""The windy rig's checks through the intake, pooled: how often the wind's
quoted 90% / 50% intervals held the truth over many ``windy_rig.json`` runs.

One run is a handful of recordings (six on one GPU in ten minutes, one or two
an hour on a CPU), too few to read a coverage; this adds up the rows of
several, grouped by the tables each estimate quoted and by whether each
recording's fabric was drawn over the prior (``--fabric_draws``, what the
tables' coverage is averaged over) or was the recipe's own (the prior's
centre). Beside each count, its 90% Wilson interval, and the truth's place in
the 50% interval's half-widths (|truth - median| / half-width on the truth's
side: 1 at the edge; a median near 1 is what a calibrated 50% interval
gives):

  python -m benchmarks.intake_pool \
      --runs='benchmarks/results/camera_intake_claim_tables/*.json' \
      --out=out/intake_pool

and draws each recording's place (pooled.png), so that a count's few misses
can be told from a spread that is too wide or too narrow throughout.
"""

from __future__ import annotations

import dataclasses
import glob
import json
import math
import os

import numpy as np

from experiments.pipeline import cli, files

_Z90 = 1.6448536269514722  # the standard normal's 95th percentile


@dataclasses.dataclass(frozen=True)
class Args:
  """Flags.

  Attributes:
    runs: comma-separated ``windy_rig.json`` files or globs.
    out: folder for pooled.json.
  """

  runs: str = 'benchmarks/results/camera_intake_claim_tables/*.json'
  out: str = 'out/benchmarks/intake_pool'


PRESETS = {'default': Args()}


def wilson(k: int, n: int, z: float = _Z90) -> tuple[float, float]:
  """The Wilson score interval of a proportion k / n (90% by default)."""
  if n == 0:
    return 0.0, 1.0
  p = k / n
  centre = (p + z * z / (2 * n)) / (1 + z * z / n)
  half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
  return max(0.0, centre - half), min(1.0, centre + half)


def half_widths(row: dict) -> float:
  """|truth - median| in the 50% interval's half-widths on the truth's side."""
  lo, hi = row['interval_50']
  m, t = row['median'], row['truth']
  side = (hi - m) if t >= m else (m - lo)
  return abs(t - m) / side if side > 0 else math.inf


def table_of_row(row: dict) -> str:
  """The tables a row's estimate quoted, by their cameras' words."""
  setting = row.get('calibration_setting') or 'no table'
  return setting.split('cameras off by ')[-1].split(' (')[0]


def read_rows(paths: list[str]) -> list[dict]:
  """Every estimated row of the runs, with its run, fabric and table."""
  rows = []
  for path in paths:
    try:
      run = json.load(open(path))
    except (OSError, ValueError) as e:
      raise ValueError(f'{path}: not a windy_rig.json ({e})') from e
    if 'rows' not in run or 'settings' not in run:
      raise ValueError(f'{path}: not a windy_rig.json (no rows or settings)')
    drawn = int(run['settings'].get('fabric_draws', -1)) >= 0
    for r in run['rows']:
      if r.get('exit') == 0 and 'interval_50' in r:
        rows.append({**r, 'run': os.path.basename(path), 'drawn': drawn,
                     'table': table_of_row(r)})  # fmt: skip
  return rows


def pooled(rows: list[dict]) -> list[dict]:
  """Per (fabric, table) group and over all: counts, intervals, errors."""
  groups = {}
  for r in rows:
    key = ('drawn over the prior' if r['drawn'] else "the recipe's own", r['table'])
    groups.setdefault(key, []).append(r)
  out = []
  for (fabric, table), rs in [*sorted(groups.items()), (('all', 'all'), rows)]:
    n = len(rs)
    k90, k50 = sum(bool(r['holds']) for r in rs), sum(bool(r['holds_50']) for r in rs)
    out.append({
      'fabric': fabric, 'table': table, 'n': n,
      'held_90': k90, 'held_90_ci': wilson(k90, n),
      'held_50': k50, 'held_50_ci': wilson(k50, n),
      'mean_error': float(np.mean([r['error'] for r in rs])) if n else None,
      'median_half_widths': float(np.median([half_widths(r) for r in rs])) if n else None,
    })  # fmt: skip
  return out


def table(groups: list[dict]) -> str:
  lines = [
    '| fabric | tables quoted | n | wind error | 90% held [90% CI] | '
    '50% held [90% CI] | median half-widths |',
    '|---|---|---|---|---|---|---|',
  ]
  for g in groups:
    ci = lambda c: f'[{100 * c[0]:.0f}, {100 * c[1]:.0f}%]'  # noqa: E731
    lines.append(
      f'| {g["fabric"]} | {g["table"]} | {g["n"]} | {100 * g["mean_error"]:.1f}% | '
      f'{g["held_90"]}/{g["n"]} {ci(g["held_90_ci"])} | '
      f'{g["held_50"]}/{g["n"]} {ci(g["held_50_ci"])} | '
      f'{g["median_half_widths"]:.2f} |'
    )
  return '\n'.join(lines)


def figure(rows: list[dict], path: str) -> None:
  """Each recording's truth in its 50% interval's half-widths, a row per
  group, with the 50% interval's edge (1) and where a Gaussian's 90% one
  would be (2.44)."""
  plt = files.pyplot()
  keys = sorted({(r['drawn'], r['table']) for r in rows})
  fig, ax = plt.subplots(figsize=(7, 0.6 * len(keys) + 1.4))
  for i, key in enumerate(keys):
    x = [min(half_widths(r), 4.0) for r in rows if (r['drawn'], r['table']) == key]
    ax.plot(x, np.full(len(x), i), 'o', alpha=0.6)
  for edge, words in ((1.0, '50% edge'), (2.44, "a Gaussian's 90% edge")):
    ax.axvline(edge, color='gray', ls='--', lw=1)
    ax.text(edge, len(keys) - 0.4, f' {words}', fontsize=8, color='gray')
  ax.set_yticks(range(len(keys)))
  ax.set_yticklabels(
    [f'{"drawn" if d else "centre"}: {t}' for d, t in keys], fontsize=8
  )
  ax.set_ylim(-0.6, len(keys) - 0.1)
  ax.set_xlim(0, 4.1)
  ax.set_xlabel("|truth - median| / the 50% interval's half-width (capped at 4)")
  ax.set_title("wind through the intake: each recording's truth", fontsize=10)
  fig.tight_layout()
  files.savefig(fig, path)
  plt.close(fig)


def main(args: Args) -> None:
  paths = sorted({p for pat in args.runs.split(',') if pat for p in glob.glob(pat)})
  if not paths:
    raise ValueError(f'--runs={args.runs!r}: no such files')
  rows = read_rows(paths)
  if not rows:
    raise ValueError(f'--runs={args.runs!r}: no estimated recordings in {paths}')
  groups = pooled(rows)
  os.makedirs(args.out, exist_ok=True)
  out = os.path.join(args.out, 'pooled.json')
  keep = ('run', 'recording', 'truth', 'median', 'error', 'holds', 'holds_50',
          'drawn', 'table')  # fmt: skip
  files.write_json(out, {
    'runs': paths, 'groups': groups,
    'rows': [{k: r[k] for k in keep} | {'half_widths': half_widths(r)} for r in rows],
  })  # fmt: skip
  figure(rows, os.path.join(args.out, 'pooled.png'))
  print(table(groups))
  print(f'wrote {out} and pooled.png')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
