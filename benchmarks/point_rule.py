"""The point estimates of finished estimates, with and without the rule for
uninformed quantities.

An estimate without a matching calibration reports, for a quantity its video
did not inform (posterior 90% interval at least ``bo.calibration.UNINFORMED``
of the prior's width), the prior's own least-error point instead of the
posterior's (``experiments.pipeline.posterior``). This script reads the
summaries saved in ``tables.json`` files (made before or after that rule) and
prints, per file and quantity, the mean error of the posterior's own point,
of the point under the rule, and of the range centre, with how many estimates
the rule touched. No simulation: seconds on a CPU.

  python -m benchmarks.point_rule --tables=out/tables/tables.json --out=rule.json
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

import bo
import physsim
from experiments.pipeline import cli, files
from experiments.pipeline import posterior as posterior_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """The point-rule comparison.

  Attributes:
    tables: tables.json files (comma-separated; required).
    out: JSON path.
  """

  tables: tuple[str, ...] = cli.required(())
  out: str = 'out/benchmarks/point_rule.json'


PRESETS = {'default': Args()}
NAMES = (*posterior_lib.FIELDS, 'load_ratio')


def _error(value: float, truth: float, name: str) -> float:
  if name == 'bending_scale':
    return float(np.exp(abs(np.log(value / truth))))
  return float(100 * abs(value / truth - 1))


def _mean(errors, name: str) -> float:
  if name == 'bending_scale':
    return float(np.exp(np.mean(np.log(errors))))
  return float(np.mean(errors))


def points(estimate: dict) -> dict:
  """Per quantity ``(truth, posterior's own point, point under the rule,
  range centre, uninformed)`` of one finished estimate."""
  space = physsim.search_space(estimate['material'])
  measured = posterior_lib.Measured(**estimate['config']['measured'])
  prior = posterior_lib.prior_points(space, measured)
  truth = dict(estimate['truth'])
  truth['load_ratio'] = float(
    physsim.load_ratio(truth['wind_speed'], truth['area_weight'])
  )
  guess = dict(zip(posterior_lib.FIELDS, map(float, space.center()), strict=True))
  guess['load_ratio'] = float(
    physsim.load_ratio(guess['wind_speed'], guess['area_weight'])
  )
  out = {}
  for name in NAMES:
    s = estimate['load_ratio'] if name == 'load_ratio' else estimate['estimate'][name]
    uninformed = 1.0 / s['narrowing_90'] >= bo.calibration.UNINFORMED
    if 'bayes' not in s:
      raise ValueError(f'{name}: no least-error point (an estimate older than it)')
    if s.get('bayes_weight', 1.0) != 1.0:  # the file keeps only the shrunk point
      raise ValueError(f"{name}: point weight {s['bayes_weight']}, not the posterior's")
    ruled = prior[name] if uninformed else s['bayes']
    out[name] = (truth[name], s['bayes'], ruled, guess[name], uninformed)
  return out


def main(args: Args) -> None:
  report = {}
  for path in args.tables:
    with open(path) as f:
      estimates = json.load(f)['estimates']
    try:
      rows = [points(e) for e in estimates.values() if 'truth' in e and 'estimate' in e]
    except ValueError as e:
      raise ValueError(f'{path}: {e}') from e
    if not rows:
      raise ValueError(f'{path}: no finished estimates with a truth')
    report[path] = {}
    print(f'{path}: {len(rows)} estimates')
    print('| quantity | posterior point | with the rule | range centre | uninformed |')
    print('|---|---|---|---|---|')
    for name in NAMES:
      t, own, ruled, centre, unin = (
        np.array([r[name][i] for r in rows]) for i in range(5)
      )
      e = {
        k: _mean([_error(v, tt, name) for v, tt in zip(vals, t, strict=True)], name)
        for k, vals in (('posterior', own), ('rule', ruled), ('centre', centre))
      }
      e['uninformed'] = int(unin.sum())
      report[path][name] = e
      fmt = (
        (lambda v: f'x{v:.2f}') if name == 'bending_scale' else (lambda v: f'{v:.1f}%')
      )
      print(f'| {name} | {fmt(e["posterior"])} | {fmt(e["rule"])} | '
            f'{fmt(e["centre"])} | {e["uninformed"]} of {len(rows)} |')  # fmt: skip
    print()
  files.write_json(args.out, report)
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
