"""Would a fabric's own tables, fitted on recordings of another physics, widen
its intervals where they run short? Leave one check seed out.

The shipped paper-size tables are fitted on the estimator's own physics over
all seven fabrics; on ``physsim.mismatch.WORLD`` one fabric's intervals can
hold less often than the rest's (white tablecloth: its wind's 90% held 72% in
the first run of the pooled check, its load ratio's 78% in a second run of
the same recordings on the GPU). An estimate says so (``report.fabric_check``),
but prints the shipped intervals. This study asks whether widening them with
the fabric's own levels would hold, before anything ships: for each check
seed held out, each fabric's levels (``bo.calibration.levels`` of its video
ranks on the other seeds' recordings, 24 of them) are joined to the shipped
ones, each interval end the wider of the two (never narrower than shipped),
and the held-out seed's recordings of that fabric are read with them. Three
rules: the shipped tables alone; every fabric's own joined in; a fabric's own
joined in only for the quantities whose 90% intervals ran short on the other
seeds beyond chance (the 95% binomial interval of their coverage under 90%,
as ``report.fabric_check`` flags them). Per rule: how often the 90% and 50%
intervals held over all held-out recordings and per fabric, the wind's
confident misses (more than 25% off outside the 90% interval) and the
intervals' mean width.

  python -m benchmarks.fabric_levels \
      --checks=out/mm/chk1,out/mm/chk2,out/mm/chk3,out/mm/chk4 --out=$OUT/fabric_levels

Each check folder holds a ``--check --physics=mismatched`` run's ``packed/``
(``benchmarks.pooled_check``'s module doc makes them; its seed is read from
its ``check.json``).
"""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np

import bo
import physsim
from experiments.pipeline import cli, files, report
from experiments.studies import calibration as cal_lib
from experiments.studies import calibration_check as check_lib

MODE = 'video'
RULES = ('shipped', 'every fabric', 'short fabrics')
WIND = cal_lib.FIELDS.index('wind_speed')


@dataclasses.dataclass(frozen=True)
class Args:
  """The study's inputs.

  Attributes:
    checks: check folders (each with ``packed/`` and ``check.json``), one per
      seed.
    calibration: the calibration file whose tables are checked ('' for the
      shipped paper-size shape calibration).
    out: output folder (JSON).
  """

  checks: tuple[str, ...] = ()
  calibration: str = ''
  out: str = 'out/fabric_levels'


PRESETS = {'default': Args()}


def seed_scores(folder: str, shipped: dict) -> tuple[int, list[dict]]:
  """(the check's seed, its recordings' video scores under the shipped
  likelihood) of a check folder."""
  check = physsim.dataset.read_json(os.path.join(folder, check_lib.CHECK_FILE))
  seed = int(check['seed'])
  made = check['config']  # the check's own settings, as it ran
  if made.get('physics') != 'mismatched':
    raise ValueError(
      f'{folder}: a check of {made.get("physics")!r} physics, not mismatched'
    )
  config = dataclasses.replace(
    cal_lib.PRESETS['paper'], physics='mismatched', seed=seed,
    pairs=int(made['pairs']), materials=tuple(made['materials']),
  )  # fmt: skip
  runs = cal_lib.saved_runs(folder)
  scores = cal_lib.posteriors(
    config, runs, shipped['likelihood'], float(shipped['sharpness']),
    model_error=float(shipped.get('model_error', 0.0)),
  )[MODE]  # fmt: skip
  return seed, scores


def joined(shipped: np.ndarray, own: np.ndarray, columns) -> np.ndarray:
  """The shipped levels (len(PROBS), fields) with ``own``'s joined in for
  ``columns``: each lower level the lower of the two, each upper the higher,
  the median the shipped one (an interval never narrower than shipped)."""
  out = shipped.copy()
  probs = np.asarray(bo.calibration.PROBS)
  for i in columns:
    lo, hi = probs < 0.5, probs > 0.5
    out[lo, i] = np.minimum(shipped[lo, i], own[lo, i])
    out[hi, i] = np.maximum(shipped[hi, i], own[hi, i])
  return out


def short_columns(scores: list[dict], levels: np.ndarray) -> list[int]:
  """The quantities whose 90% intervals, read at ``levels``, held these
  recordings less often than 90% beyond chance (95% binomial interval)."""
  s = cal_lib.summarise([{**x, 'levels': levels} for x in scores], None, bayes=False)
  out = []
  for i, f in enumerate(cal_lib.FIELDS):
    k = round(s[f]['interval_90'] * s['n'])
    if bo.calibration.binomial_interval(k, s['n'])[1] < 0.9:
      out.append(i)
  return out


def held_out(by_seed: dict[int, list[dict]], shipped_levels: np.ndarray) -> dict:
  """Per rule, the held-out recordings each read with its fabric's levels
  fitted on the other seeds."""
  out = {r: [] for r in RULES}
  for seed, scores in by_seed.items():
    rest = [x for s, v in by_seed.items() if s != seed for x in v]
    for material in sorted({x['material'] for x in scores}):
      mine = [x for x in scores if x['material'] == material]
      train = [x for x in rest if x['material'] == material]
      own = cal_lib.recalibration(train)
      rules = {
        'shipped': shipped_levels,
        'every fabric': joined(shipped_levels, own, range(len(cal_lib.FIELDS))),
        'short fabrics': joined(
          shipped_levels, own, short_columns(train, shipped_levels)
        ),
      }
      for rule, levels in rules.items():
        out[rule] += [{**x, 'levels': levels, 'held_out_seed': seed} for x in mine]
  return out


def _widths(rows: list[dict]) -> dict:
  """Mean 90% interval width per quantity, over the prior box's (log for
  bending)."""
  probs = bo.calibration.PROBS
  out = {}
  for i, f in enumerate(cal_lib.FIELDS):
    w = []
    for x in rows:
      vals = cal_lib._at(x['qf'], x['levels'])  # noqa: SLF001 - the study's own reading
      lo, hi = vals[probs.index(0.05), i], vals[probs.index(0.95), i]
      w.append(np.log(hi / lo) if f == 'bending_scale' else (hi - lo) / x['truth'][i])
    out[f] = float(np.mean(w))
  return out


def rule_summary(rows: list[dict]) -> dict:
  s = cal_lib.summarise(rows, None)
  by = {}
  for m in sorted({x['material'] for x in rows}):
    t = cal_lib.summarise([x for x in rows if x['material'] == m], None, bayes=False)
    by[m] = {f: [t[f]['interval_90'], t[f]['interval_50']] for f in cal_lib.FIELDS}
  return {
    'n': s['n'],
    **{f: {k: s[f][k] for k in ('interval_90', 'interval_50')} for f in cal_lib.FIELDS},
    'wind_confident_misses': s['wind_speed']['confident_misses'],
    'wind_confident_misses_expected': s['wind_speed']['confident_misses_expected'],
    'mean_relative_width_90': _widths(rows),
    'by_material_90_50': by,
  }


def table(out: dict) -> str:
  head = ['rule', 'n', *(f'{f} 90% / 50%' for f in cal_lib.FIELDS),
          'wind misses (expected)', 'white tablecloth 90%: wind, load ratio']  # fmt: skip
  lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
  for rule in RULES:
    r = out['rules'][rule]
    wt = r['by_material_90_50'].get('white_tablecloth')
    lines.append(
      f'| {rule} | {r["n"]} | '
      + ' | '.join(
        f'{100 * r[f]["interval_90"]:.0f}% / {100 * r[f]["interval_50"]:.0f}%'
        for f in cal_lib.FIELDS
      )
      + f' | {r["wind_confident_misses"]} ({r["wind_confident_misses_expected"]:.1f}) | '
      + (
        f'{100 * wt["wind_speed"][0]:.0f}%, {100 * wt["load_ratio"][0]:.0f}%'
        if wt
        else '-'
      )
      + ' |'
    )
  return '\n'.join(lines)


def main(args: Args) -> None:
  if len(args.checks) < 2:
    raise ValueError('--checks: give at least two check folders (one per seed)')
  path = args.calibration or report.SHAPE_PAPER_CALIBRATION_FILE
  shipped = physsim.dataset.read_json(path)
  rc = shipped['recalibration']
  levels = np.asarray(rc['modes'][MODE])
  by_seed = {}
  for folder in args.checks:
    seed, scores = seed_scores(folder, shipped)
    if seed in by_seed:
      raise ValueError(f'--checks: two folders of seed {seed}')
    weights = rc.get('weights', {}).get(MODE, {})
    by_seed[seed] = [{**x, 'weights': weights} for x in scores]
  rows = held_out(by_seed, levels)
  out = {
    'args': dataclasses.asdict(args),
    'calibration': path,
    'seeds': sorted(by_seed),
    'rules': {r: rule_summary(v) for r, v in rows.items()},
  }
  os.makedirs(args.out, exist_ok=True)
  files.write_json(os.path.join(args.out, 'fabric_levels.json'), out)
  print(table(out))
  print(
    json.dumps(
      {r: v['mean_relative_width_90'] for r, v in out['rules'].items()}, indent=1
    )
  )


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
