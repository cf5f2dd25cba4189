"""Weighing a cloth against a known mass: a hem of coins in the fan (issue 39).

A sheet in a fan measures its load ratio, (drag law) x rho v^2 / (w g). With an
anemometer's reading of v, area weight w follows only as far as the
simulator's drag law is the world's: a law 20% off puts w 20% off, however
good the video (the mismatched physics' confident area-weight miss, BENCHMARKS
note 3). A second recording at the same fan setting, the fan untouched, with a
known mass taped along the free bottom edge (coins: a US nickel is 5.000 g, a
1-euro coin 7.50 g) is pushed by the same wind through the same law, and
weighs w against that mass: the law and the wind cancel in the pair.

This benchmark puts numbers on it with the protocol study's Fisher bound
(``experiments.studies.protocol``: the estimator's own simulator, MuJoCo C,
six depth-camera-like statistics of each clip with gust, sensor and set-up
noise): the prior's 90% width of log area weight over the posterior's, for
sets with and without a hem, with the drag law trusted (``--drag_sds`` 0) and
uncertain (a shared factor on the wind force, log sd 0.2: the bound's
``drag_sd``), the video alone and with every wind read to 2%. A bound, not
an estimate: ``benchmarks.joint_pairs --hem_mass`` runs the estimate itself
on hemmed recordings (it narrowed area weight far less). ``--stats``
reads the bound on fewer statistics, e.g. the sheet's mean position alone
as the estimate's shape distance does, and ``--clip`` at the
estimate's 3 s:

  python -m benchmarks.hem_weight --workdir=out/hem_weight_3s --clip=3 \
      --stats=centroid_out,centroid_up

  python -m benchmarks.hem_weight --workdir=out/hem_weight --workers=16
  python -m benchmarks.hem_weight --workdir=out/hem_weight --world=air_drag=0.1  # one part
  python -m benchmarks.hem_weight --workdir=/tmp/hw --preset=smoke   # CPU, < 1 min

Writes ``hem_weight.json`` and ``hem_weight.png`` to ``--workdir`` (and the
protocol study's own files and slope cache: a rerun resumes).
"""

from __future__ import annotations

import dataclasses
import os

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import cli, files  # noqa: E402
from experiments.studies import protocol  # noqa: E402

RESULT_FILE = 'hem_weight.json'
FIGURE_FILE = 'hem_weight.png'
PANELS = ('video', 'anemometer')

_SETS = (
  'sheet 2 m/s=sheet_100cm_2ms;'
  'sheet 2 m/s + hem 100 g, fan untouched=sheet_100cm_2ms&sheet_100cm_2ms_hem100g;'
  'sheet 2 m/s + hem 300 g, fan untouched=sheet_100cm_2ms&sheet_100cm_2ms_hem300g;'
  'sheet 2 m/s + hem 300 g, fan moved=sheet_100cm_2ms+sheet_100cm_2ms_hem300g;'
  'sheet 3.5 m/s=sheet_100cm_3.5ms;'
  'sheet 3.5 m/s + hem 300 g, fan untouched=sheet_100cm_3.5ms&sheet_100cm_3.5ms_hem300g;'
  'sheet 2 + 3.5 m/s=sheet_100cm_2ms+sheet_100cm_3.5ms;'
  'sheet 2 + 3.5 m/s, each + hem 300 g='
  'sheet_100cm_2ms&sheet_100cm_2ms_hem300g+sheet_100cm_3.5ms&sheet_100cm_3.5ms_hem300g'
)


@dataclasses.dataclass(frozen=True)
class Args:
  """The hem benchmark.

  Attributes:
    workdir: results and the protocol study's slope cache (resumed).
    drag_sds: the drag law's log standard deviations compared (comma-separated;
      0: trusted).
    figure: also copy the figure here ('' none).
    world: the other physics the bias is read on: '' for
      ``physsim.mismatch.WORLD``, else ``field=value`` pairs
      (comma-separated) of a ``physsim.Mismatch`` that differs from the
      estimator's in those alone (e.g. ``edge_solref_scale=2``).
    study: the protocol study's candidates, sets and noise (5 s clips).
  """

  workdir: str = cli.required()
  drag_sds: tuple[str, ...] = ('0', '0.2')
  figure: str = ''
  world: tuple[str, ...] = ()
  study: protocol.Config = protocol.Config(
    candidates=(
      'sheet_100cm_2ms_r9', 'sheet_100cm_2ms_hem100g_r9', 'sheet_100cm_2ms_hem300g_r9',
      'sheet_100cm_3.5ms_r9', 'sheet_100cm_3.5ms_hem300g_r9',
    ),
    convergence=(),
    sets=_SETS,
    clip=5.0,
  )  # fmt: skip


PRESETS = {
  'default': Args(),
  # the path end to end: one truth, a tiny sheet with and without a hem
  'smoke': Args(
    study=protocol.Config(
      bendings=('1',),
      candidates=('sheet_100cm_2ms_r5', 'sheet_100cm_2ms_hem100g_r5'),
      convergence=(),
      sets='sheet=sheet_100cm_2ms;sheet + hem=sheet_100cm_2ms&sheet_100cm_2ms_hem100g',
      draws=3,
      clip=0.5,
      warmup=0.25,
    )
  ),
}


def drag_values(values) -> list[float]:
  """``--drag_sds`` as numbers >= 0; a ValueError naming the flag."""
  try:
    out = [float(v) for v in values]
  except ValueError:
    out = []
  if not out or not all(np.isfinite(v) and v >= 0 for v in out):
    raise ValueError(f'--drag_sds={",".join(values)}: need numbers >= 0')
  return out


def biases(result: dict, config: protocol.Config, workdir: str, drag: float,
           world: physsim.Mismatch = physsim.mismatch.WORLD) -> dict:  # fmt: skip
  """Per (set, mode): the first-order bias of log area weight that recordings
  of another physics (``world``) cause in a fit with the estimator's
  simulator (``protocol.set_bias``), per bending truth."""
  slopes = {(r['candidate'], r['bending']): r for r in result['slopes']}
  sets = protocol.parse_sets(config.sets, list(config.candidates))
  prior = protocol.priors(config.material, config.reading)
  cache = os.path.join(workdir, protocol.CACHE_DIR)
  out = {}
  for label, members in sets.items():
    names, shared = zip(*map(protocol.shares_wind, members), strict=True)
    for mode in PANELS:
      cells = []
      for b in result['bendings']:
        rows = [slopes[(n, b)] for n in names]
        res = [
          protocol.world_residual(
            protocol.parse(n), b, result['area_weight'], config, cache, world
          )
          for n in names
        ]
        cells.append(
          protocol.set_bias(rows, res, prior, mode, shared, drag, config.stats)
        )
      out[(label, mode)] = cells
  return out


def world_of(items) -> physsim.Mismatch:
  """``--world`` as a ``physsim.Mismatch``; a ValueError naming the flag."""
  if not items:
    return physsim.mismatch.WORLD
  fields = {f.name for f in dataclasses.fields(physsim.Mismatch)}
  pairs = [item.partition('=') for item in items]
  keys = [k for k, _, _ in pairs]
  try:
    if not set(keys) <= fields or len(set(keys)) < len(keys):
      raise ValueError
    return physsim.Mismatch(
      **{k: int(v) if k == 'gust_modes' else float(v) for k, _, v in pairs}
    )
  except (TypeError, ValueError):
    raise ValueError(
      f'--world={",".join(items)}: need field=value pairs of {sorted(fields)}, '
      'each field once, finite and >= 0'
    ) from None


def rows(results: dict[float, dict], bias: dict[float, dict]) -> list[dict]:
  """One row per set, drag law and mode: area weight's narrowing (geometric
  mean over the truths, and their range), and on another physics its bias
  (mean over the truths, percent) in posterior sds."""
  out = []
  for drag, result in results.items():
    labels = list(dict.fromkeys(e['set'] for e in result['table']))
    for label in labels:
      for mode in PANELS:
        g, lo, hi = protocol.geomean_range(result['table'], label, mode, 'area_weight')
        cells = bias[drag][(label, mode)]
        out.append({
          'set': label, 'drag_sd': drag, 'mode': mode,
          'area_weight': g, 'low': lo, 'high': hi,
          'world_bias_pct': float(np.mean(
            [100 * np.expm1(c['area_weight_bias_log']) for c in cells])),
          'world_bias_sds': float(np.mean([c['area_weight_z'] for c in cells])),
        })  # fmt: skip
  return out


def markdown(table: list[dict]) -> str:
  drags = sorted({r['drag_sd'] for r in table})
  head = ' | '.join(f'{m}, drag law sd {d:g}' for d in drags for m in PANELS)
  lines = [f'| set | {head} |', '|---|' + '---:|' * (len(drags) * len(PANELS))]
  for label in dict.fromkeys(r['set'] for r in table):
    cells = []
    for d in drags:
      for m in PANELS:
        (r,) = [
          x for x in table if x['set'] == label and x['drag_sd'] == d and x['mode'] == m
        ]
        cells.append(
          f'{r["area_weight"]:.2f} ({r["low"]:.2f}-{r["high"]:.2f}); '
          f'{r["world_bias_pct"]:+.1f}% ({r["world_bias_sds"]:+.1f} sd)'
        )
    lines.append(f'| {label} | {" | ".join(cells)} |')
  return (
    'area weight: narrowing (range over truths); on another physics '
    '(physsim.mismatch.WORLD) the bias of a fit, percent (in posterior sds)\n'
    + '\n'.join(lines)
  )


def plot(table: list[dict], path: str, material: str) -> None:
  labels = list(dict.fromkeys(r['set'] for r in table))
  drags = sorted({r['drag_sd'] for r in table})
  fig, axes = plt.subplots(1, len(PANELS), figsize=(11, 0.45 * len(labels) + 1.8),
                           sharey=True)  # fmt: skip
  y = np.arange(len(labels))
  height = 0.8 / len(drags)
  for ax, mode in zip(axes, PANELS, strict=True):
    for k, d in enumerate(drags):
      sel = [next(r for r in table if r['set'] == s and r['drag_sd'] == d
                  and r['mode'] == mode) for s in labels]  # fmt: skip
      g = np.array([r['area_weight'] for r in sel])
      err = np.maximum(0, [g - [r['low'] for r in sel], [r['high'] for r in sel] - g])
      ax.barh(y - 0.4 + height * (k + 0.5), g, height=height, xerr=err, capsize=2,
              color=f'C{k}', label='drag law trusted' if d == 0
              else f'drag law uncertain (log sd {d:g})')  # fmt: skip
    ax.axvline(1, color='k', lw=0.8)
    ax.set_title({'video': 'video alone', 'anemometer': 'every wind read to 2%'}[mode])
    ax.set_xlabel("area weight: prior's 90% width / posterior's")
  axes[0].set_yticks(y, labels)
  axes[0].invert_yaxis()
  handles, names = axes[0].get_legend_handles_labels()
  fig.legend(handles, names, loc='lower center', ncol=len(drags), fontsize=9)
  fig.suptitle(f'{material}: a known mass at the hem weighs the cloth whatever the drag law\n'
               '(Cramer-Rao bound; bars: geometric mean over bending truths, whiskers: range)',
               fontsize=10)  # fmt: skip
  fig.tight_layout(rect=(0, 0.06, 1, 1))
  files.savefig(fig, path)
  plt.close(fig)


def main(args: Args) -> None:
  drags = drag_values(args.drag_sds)
  world = world_of(args.world)
  results = {
    d: protocol.run(dataclasses.replace(args.study, drag_sd=d), args.workdir)
    for d in drags
  }
  bias = {
    d: biases(r, dataclasses.replace(args.study, drag_sd=d), args.workdir, d, world)
    for d, r in results.items()
  }
  table = rows(results, bias)
  out = {
    'material': args.study.material,
    'rows': table,
    'config': dataclasses.asdict(args.study) | {'drag_sds': drags},
    'world': dataclasses.asdict(world),
    'simulation_seconds': max(r['simulation_seconds'] for r in results.values()),
  }
  files.write_json(os.path.join(args.workdir, RESULT_FILE), out)
  plot(table, os.path.join(args.workdir, FIGURE_FILE), args.study.material)
  if args.figure:
    os.makedirs(os.path.dirname(args.figure) or '.', exist_ok=True)
    plot(table, args.figure, args.study.material)
  print(markdown(table))
  print(f'wrote {args.workdir}/{RESULT_FILE} and {FIGURE_FILE}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
