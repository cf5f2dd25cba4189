"""Which fan settings measure area weight: one-recording errors split by wind.

Reads the ``joint_pairs.json`` files of ``benchmarks/joint_pairs.py`` and
prints, for the recordings whose anemometer reading is at most ``--split``
m/s and for the rest, the mean error (with its standard error) of area weight
and of the load ratio from one recording and its reading, beside the range
centre's area-weight error on the same recordings; the same split by the
true load ratio (``--ratio_split``). The reading is what a user sees when
choosing a setting; the load ratio is what the physics cares about (the sheet
blows flat at high ratios and its mean shape stops following the ratio:
docs/identifiability.md). Then, pooled over the files, each estimate's
mean error with its standard error over groups (``by_group``): a group's
recordings share one joint area weight, so the group, not the recording, is
the independent unit. No simulation: seconds on a CPU.

  python -m benchmarks.fan_settings \\
      --results=/tmp/jf/joint_pairs.json,/tmp/jf4/joint_pairs.json,/tmp/jf5/joint_pairs.json
"""

from __future__ import annotations

import collections
import dataclasses
import json

import numpy as np

from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The fan-settings summary.

  Attributes:
    results: joint_pairs.json files (comma-separated; required).
    split: gentle fan settings: readings up to this, m/s.
    ratio_split: low load ratios: truths up to this.
    out: JSON path.
  """

  results: tuple[str, ...] = cli.required(())
  split: float = 3.5
  ratio_split: float = 8.0
  out: str = 'out/benchmarks/fan_settings.json'


PRESETS = {'default': Args()}


def strata(rows: list[dict], split: float, ratio_split: float) -> dict:
  """Per stratum: n, and mean and standard error of each one-recording error."""
  reading = np.array([r['reading'][0] for r in rows])
  ratio = np.array([r['truth']['load_ratio'] for r in rows])
  masks = {
    f'reading <= {split:g} m/s': reading <= split,
    f'reading > {split:g} m/s': reading > split,
    f'load ratio <= {ratio_split:g}': ratio <= ratio_split,
    f'load ratio > {ratio_split:g}': ratio > ratio_split,
  }
  cols = {
    'area_weight': [r['alone']['area_weight'] for r in rows],
    'load_ratio': [r['alone']['load_ratio'] for r in rows],
    'centre_area_weight': [r['centre']['area_weight'] for r in rows],
  }
  out = {}
  for name, m in masks.items():
    n = int(m.sum())
    s = {'n': n}
    for col, values in cols.items():
      v = np.asarray(values)[m]
      s[col] = float(v.mean()) if n else float('nan')
      s[f'{col}_se'] = float(v.std(ddof=1) / np.sqrt(n)) if n > 1 else float('nan')
    out[name] = s
  return out


NAMES = ('wind_speed', 'area_weight', 'load_ratio')
# a row's estimates (benchmarks/joint_pairs.py): one recording, the group's first
# two jointly, the whole group jointly (reported point), the range centre
ESTIMATES = ('alone', 'first_2', 'joint', 'centre')


def by_group(runs: list[tuple[list[dict], int]]) -> dict:
  """Per estimate: mean error over recordings and its standard error over groups.

  ``runs`` holds each file's rows and its group size; a row's group is its
  ``seq // size`` within its file. Every group counts once in the standard
  error (the standard deviation of group means over the square root of their
  number), so a joint estimate shared by a group's recordings is not counted
  as several independent ones.
  """
  out = {}
  for who in ESTIMATES:
    groups = []  # one dict of error lists per group
    for rows, size in runs:
      by = collections.defaultdict(list)
      for r in rows:
        if who in r:
          by[r['seq'] // size].append(r[who])
      groups += list(by.values())
    if not groups:
      continue
    s = {'groups': len(groups), 'n': sum(len(g) for g in groups)}
    for n in NAMES:
      means = np.array([np.mean([e[n] for e in g]) for g in groups])
      s[n] = float(np.mean([e[n] for g in groups for e in g]))  # over recordings
      s[f'{n}_se'] = (
        float(means.std(ddof=1) / np.sqrt(len(means)))
        if len(means) > 1
        else float('nan')
      )
    out[who] = s
  return out


def _load(path: str) -> tuple[list[dict], int | None]:
  """A joint_pairs.json's rows and group size (None where it records none)."""
  try:
    with open(path) as f:
      data = json.load(f)
    rows = data['rows']
    for i, r in enumerate(rows):
      for key in ('reading', 'truth', 'alone', 'centre'):
        if key not in r:
          raise ValueError(f'row {i} has no {key!r}')
    size = data.get('flags', {}).get('group')
    size = int(size) if size and all('seq' in r for r in rows) else None
    # the summaries themselves on this file alone: a missing inner key is named
    # here, with the file, not later as a bare KeyError
    strata(rows, 0.0, 0.0)
    if size:
      by_group([(rows, size)])
  except KeyError as e:
    raise ValueError(f'{path}: not a joint_pairs.json (a row lacks {e})') from e
  except (OSError, ValueError, TypeError, AttributeError) as e:
    raise ValueError(f'{path}: not a joint_pairs.json ({e})') from e
  return rows, size


def main(args: Args) -> None:
  runs = [_load(path) for path in args.results]
  rows = [r for rs, _ in runs for r in rs]
  out = strata(rows, args.split, args.ratio_split)
  print(f'{len(rows)} recordings; one recording and its reading, mean error (SE)')
  print('| recordings | n | area weight | load ratio | range centre: area weight |')
  print('|---|---:|---|---|---|')
  for name, s in out.items():
    print(f"| {name} | {s['n']} | {s['area_weight']:.1f}% ({s['area_weight_se']:.1f}) | "
          f"{s['load_ratio']:.1f}% ({s['load_ratio_se']:.1f}) | "
          f"{s['centre_area_weight']:.1f}% |")  # fmt: skip
  pooled = None
  if all(size for _, size in runs):  # every file says how its groups were made
    pooled = by_group(runs)
    print('every recording, mean error (SE over groups)')
    print('| estimate | groups | recordings | wind | area weight | load ratio |')
    print('|---|---:|---:|---|---|---|')
    for who, s in pooled.items():
      print(f"| {who} | {s['groups']} | {s['n']} | "
            + ' | '.join(f"{s[n]:.1f}% ({s[n + '_se']:.1f})" for n in NAMES) + ' |')  # fmt: skip
  files.write_json(
    args.out, {'strata': out, 'by_group': pooled, 'results': list(args.results)}
  )
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
