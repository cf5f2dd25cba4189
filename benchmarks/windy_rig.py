"""Issue 40's recording, remade from a committed recipe, and estimated four ways.

``experiments.pipeline.rig`` writes a recording as a user's rig would (the
floor out of view, a 3.52 m/s fan blowing the sheet back, 640x480 at 30 fps,
an OpenCV camera file in a z-up rig world; a finer, gustier simulation and
another depth-noise model than the estimator's). The estimate then runs on it
as a user runs it (``python -m experiments.estimate``), with up from:

* ``world_up``: ``--world_up=z`` (the rig's world axis);
* ``imu``: the camera file's ``"gravity"`` (0.5 degrees off, as an IMU is);
* ``none``: neither; must be refused in one line naming the flags;
* ``guessed``: neither, with ``--allow_guessed_up``; the 90% interval must
  hold the truth however wide;
* ``trusted``: ``--world_up=z`` with the placement trusted exactly
  (``--noalignment_sd``, the default before issue 40): what the intake's own
  error estimate guards against.

With ``--winds`` it makes one recording per wind (recording k with the
recipe's seed + k: other gusts, noise and IMU error) and summarises each mode
over them (mean and worst error, intervals that hold the truth);
``--recipe_fields`` changes the recipe (a study of which difference costs
what, e.g. ``--recipe_fields=gust_intensity=0.2``).

Prints a table and writes ``<workdir>/windy_rig.json``; reruns resume.

One run is a handful of recordings, too few to read a coverage: ``--pool``
adds up the rows of several, grouped by the tables each estimate quoted and by
whether each recording's fabric was drawn over the prior (``--fabric_draws``,
what the tables' coverage is averaged over) or was the recipe's own (the
prior's centre); beside each count its 90% Wilson interval, and the truth's
place in the 50% interval's half-widths (|truth - median| / the half-width on
the truth's side: 1 at its edge; a median near 1 is a calibrated 50%
interval's), drawn per recording so that a count's few misses can be told
from intervals too wide throughout.

  python -m benchmarks.windy_rig
  python -m benchmarks.windy_rig --modes=world_up,none --max_iter=2
  python -m benchmarks.windy_rig --preset=gpu --recipe=mismatched
  python -m benchmarks.windy_rig --workdir=out/intake_pool \
      --pool='benchmarks/results/camera_intake_claim_tables/*.json'
  python -m benchmarks.windy_rig --recipe=mismatched --modes=world_up \
      --pairs=7 --fabric_draws=400 --recipe_fields=seed=400 \
      --materials=white_tablecloth,gray_interlock,black_denim  # recordings to fit
      # tables on (experiments.calibrate --rig_runs)
  python -m benchmarks.windy_rig --workdir=out/factors --pool_by=run \
      --pool='benchmarks/results/intake_factors/?_*.json'  # one run a row
"""

from __future__ import annotations

import dataclasses
import glob
import json
import math
import os
import subprocess
import sys
import textwrap
import time
from concurrent import futures

import numpy as np

import physsim
from bo.calibration import binomial_interval
from bo.design import Z90
from experiments.pipeline import cli, files, objective, rig
from experiments.pipeline.recording import read_json

MODES = ('world_up', 'imu', 'none', 'guessed', 'trusted')
BACKENDS = ('c', 'auto', 'mjx', 'warp')


@dataclasses.dataclass(frozen=True)
class Args:
  """The windy rig study.

  Attributes:
    workdir: the recording, each estimate's workdir and log, the JSON.
    modes: which of world_up, imu, none, guessed, trusted (comma-separated).
    distance: the estimate's --distance.
    max_iter: the estimate's --max_iter (default: the estimate's own).
    smoke: a tiny recording and the estimate's smoke preset (a test's run).
    recipe: the recording's recipe: 'default' (the estimator's physics, a
      finer mesh, gustier, another noise model) or 'mismatched' (also a
      fan off the normal, another gust spectrum, drag, damping, stretchier
      edges: rig.MISMATCHED) or 'mismatched_b' (a second such world, each
      knob other: checks of what was fitted on the first).
    backend: the estimate's simulator.
    record_backend: the recording's simulator ('': the estimate's).
    winds: comma-separated winds, m/s: one recording each, the k-th with the
      recipe's seed + k ('': one recording at the recipe's wind).
    recipe_fields: comma-separated ``field=value`` changes to the recipe
      (``rig.with_fields``: numbers, and points as ``x:y:z``; e.g.
      ``gust_intensity=0.2,cloth_resolution=25`` or ``eye=-0.6:-1.4:1.6``).
    parallel: estimates run at once (processes).
    fabric_draws: -1: the recipe's fabric (its bending and area weight at the
      centre of the estimate's prior); else the seed of each recording's own fabric drawn as the
      calibration tables draw theirs (``rig.drawn_fabric``), so that a check of
      coverage is one of what the tables promise.
    pairs: instead of ``winds``, that many pairs of recordings drawn as the
      calibration tables draw theirs (``drawn_pairs``: each pair one fabric,
      each recording its own wind, all over the prior; needs
      ``fabric_draws``, their seed): recordings a calibration table can be
      fitted on (``experiments.calibrate --rig_runs``).
    materials: comma-separated fabrics, one per pair in turn ('': the
      recipe's).
    pool: comma-separated earlier ``windy_rig.json`` files or globs: instead
      of recording, their rows pooled by fabric and table (``pooled``) into
      the workdir's pooled.json and pooled.png.
    pool_by: with ``pool``, group the rows by fabric and table ('table') or
      by the file each came from ('run': recordings of one recipe change
      each, side by side).
  """

  workdir: str = 'out/benchmarks/windy_rig'
  modes: str = ','.join(MODES[:4])
  distance: str = 'shape'
  max_iter: int = objective.Search().max_iter
  smoke: bool = False
  recipe: str = cli.choice('default', tuple(rig.RECIPES))
  backend: str = cli.choice('c', BACKENDS)
  record_backend: str = cli.choice('', ('', *BACKENDS))
  winds: str = ''
  recipe_fields: str = ''
  parallel: int = 1
  fabric_draws: int = -1
  pairs: int = 0
  materials: str = ''
  pool: str = ''
  pool_by: str = cli.choice('table', ('table', 'run'))


PRESETS = {
  'default': Args(),
  'smoke': Args(smoke=True, modes='world_up,none', max_iter=1),
  # one GPU: six recordings of strong wind, estimated two at a time
  'gpu': Args(
    modes='world_up',
    backend='auto',
    record_backend='c',
    parallel=2,
    winds='3.0,3.25,3.52,3.75,4.0,4.5',
  ),
}


def _modes(text: str) -> list[str]:
  modes = [m for m in text.split(',') if m]
  bad = [m for m in modes if m not in MODES]
  if bad or not modes:
    raise ValueError(f'--modes={text}: need a comma-separated subset of {MODES}')
  return modes


def recordings(args: Args) -> list[tuple[str, rig.Recipe]]:
  """Each recording's folder name (under the workdir) and recipe."""
  recipe = rig.RECIPES[args.recipe]
  if args.smoke:
    changed = {
      f.name: getattr(recipe, f.name) for f in dataclasses.fields(recipe)
      if getattr(recipe, f.name) != getattr(rig.Recipe(), f.name)
    }  # fmt: skip
    recipe = dataclasses.replace(rig.SMOKE, **changed)
  recipe = rig.with_fields(recipe, args.recipe_fields)
  if args.pairs:
    return drawn_pairs(recipe, args)
  if not args.winds:
    return [('', recipe)]
  try:
    winds = [float(w) for w in args.winds.split(',') if w]
  except ValueError:
    winds = []
  if not winds or not all(0 < w < 20 for w in winds):
    raise ValueError(f'--winds={args.winds}: need comma-separated winds in (0, 20) m/s')
  out = []
  for k, w in enumerate(winds):
    r = dataclasses.replace(recipe, wind_speed=w, seed=recipe.seed + k)
    if args.fabric_draws >= 0:
      r = rig.drawn_fabric(r, np.random.default_rng([args.fabric_draws, k]))
    out.append((f'rec{k:02d}', r))
  return out


def drawn_pairs(recipe: rig.Recipe, args: Args) -> list[tuple[str, rig.Recipe]]:
  """``args.pairs`` pairs of recordings as ``calibration_config.truths``
  draws the tables' (pair ``j``: recordings ``2j`` and ``2j + 1``): each
  pair's bending and area weight, and each recording's wind, uniform in the
  unit cube of its fabric's search box; fabrics ``args.materials`` in turn;
  recording ``k`` with the recipe's seed + k (its own gusts, noise, IMU)."""
  if args.pairs < 0 or args.fabric_draws < 0:
    raise ValueError(
      f'--pairs={args.pairs} needs --fabric_draws=SEED (>= 0) and pairs >= 0'
    )
  mats = [m for m in args.materials.split(',') if m] or [recipe.material]
  for m in mats:
    try:
      physsim.search_space(m)
    except (KeyError, ValueError) as e:
      raise ValueError(f'--materials: no fabric {m!r} ({e})') from e
  out = []
  for j in range(args.pairs):
    mat = mats[j % len(mats)]
    u = np.random.default_rng([args.fabric_draws, j]).uniform(-1.0, 1.0, (2, 3))
    u[1, 0], u[1, 2] = u[0, 0], u[0, 2]  # one fabric, two fan settings
    p = physsim.from_unit(u, physsim.search_space(mat))
    for i in range(2):
      k = 2 * j + i
      r = dataclasses.replace(
        recipe, material=mat, seed=recipe.seed + k,
        bending_scale=float(p.bending_scale[i]), wind_speed=float(p.wind_speed[i]),
        area_weight=float(p.area_weight[i]),
      )  # fmt: skip
      out.append((f'rec{k:02d}', r))
  return out


def _flags(mode: str, paths: dict) -> list[str]:
  cam = paths['camera_imu' if mode == 'imu' else 'camera']
  extra = {
    'world_up': ['--world_up=z'],
    'guessed': ['--allow_guessed_up'],
    'trusted': ['--world_up=z', '--noalignment_sd'],
  }
  return [f'--camera_json={cam}', *extra.get(mode, [])]


def _estimate(
  args: Args, mode: str, paths: dict, where: str, truth: float, material: str
) -> dict:
  """One estimate as a user runs it (naming the fabric); its outcome, read
  from its files."""
  workdir = os.path.join(where, f'est_{mode}')
  command = [
    sys.executable, '-m', 'experiments.estimate', f'--recording={paths["depth"]}',
    *_flags(mode, paths), f'--workdir={workdir}', f'--distance={args.distance}',
    f'--material={material}',
    f'--backend={args.backend}', f'--max_iter={args.max_iter}',
    *(['--preset=smoke'] if args.smoke else []),
  ]  # fmt: skip
  env = dict(os.environ)
  if args.parallel > 1:  # estimates sharing a GPU: none may take most of it
    env.setdefault('XLA_PYTHON_CLIENT_PREALLOCATE', 'false')
  t0 = time.perf_counter()
  done = subprocess.run(command, capture_output=True, text=True, env=env)
  seconds = time.perf_counter() - t0
  log = os.path.join(where, f'est_{mode}.log')
  files.write_text(log, done.stdout + done.stderr)
  row = {'mode': mode, 'truth': truth, 'command': ' '.join(command[1:]),
         'exit': done.returncode, 'seconds': round(seconds, 1), 'log': log}  # fmt: skip
  if done.returncode != 0:
    lines = [x for x in done.stderr.strip().splitlines() if x]
    row['message'] = lines[-1] if lines else ''
    return row
  result = json.loads(open(os.path.join(workdir, 'estimate.json')).read())
  wind = result['estimate']['wind_speed']
  lo, hi = wind['interval_90']
  lo50, hi50 = wind['interval_50']
  note = result.get('calibration') or {}
  row.update(
    wind=wind['value'], median=wind['median'], interval_90=[lo, hi],
    error=abs(wind['value'] - truth) / truth, holds=bool(lo <= truth <= hi),
    interval_50=[lo50, hi50], holds_50=bool(lo50 <= truth <= hi50),
    narrowing_90=wind['narrowing_90'], alignment=result.get('alignment'),
    calibrated=bool(note.get('matches') and note.get('recalibrated')),
    calibration_differs=note.get('differs', []),
    calibration_setting=note.get('setting', ''),
  )  # fmt: skip
  return row


def table(rows: list[dict]) -> str:
  lines = [
    '| recording | up from | exit | truth | wind (m/s) | error | 90% interval | holds | narrower |',
    '|---|---|---|---|---|---|---|---|---|',
  ]  # fmt: skip
  for r in rows:
    head = (
      f'| {r.get("recording") or "-"} | {r["mode"]} | {r["exit"]} | {r["truth"]:.2f} |'
    )
    if r['exit'] != 0:
      lines.append(f'{head} refused: {r["message"]} | | | | |')
      continue
    lo, hi = r['interval_90']
    lines.append(
      f'{head} {r["wind"]:.2f} | {100 * r["error"]:.1f}% | [{lo:.2f}, {hi:.2f}] | '
      f'{"yes" if r["holds"] else "NO"} | x{r["narrowing_90"]:.1f} |'
    )
  return '\n'.join(lines)


def summary(rows: list[dict]) -> dict:
  """Per mode over the recordings: how many ran, were refused, mean and
  worst error, within 10%, intervals holding the truth."""
  out = {}
  for mode in dict.fromkeys(r['mode'] for r in rows):
    ran = [r for r in rows if r['mode'] == mode and r['exit'] == 0]
    errors = np.array([r['error'] for r in ran])
    # the posterior's median too: the point (least expected percent error)
    # leans low, toward the prior's, where the posterior is wide
    med = np.array(
      [abs(r['median'] - r['truth']) / r['truth'] for r in ran if 'median' in r]
    )
    out[mode] = {
      'recordings': sum(r['mode'] == mode for r in rows),
      'refused': sum(r['mode'] == mode and r['exit'] != 0 for r in rows),
      'mean_error': float(errors.mean()) if len(ran) else None,
      'max_error': float(errors.max()) if len(ran) else None,
      'within_10pct': int(np.sum(errors <= 0.10)),
      'holds_90': sum(bool(r['holds']) for r in ran),
      'holds_50': sum(bool(r.get('holds_50')) for r in ran),
      'calibrated': sum(bool(r.get('calibrated')) for r in ran),
      'median_mean_error': float(med.mean()) if len(med) else None,
      'median_within_10pct': int(np.sum(med <= 0.10)),
    }
  return out


def summary_table(stats: dict) -> str:
  lines = [
    '| up from | recordings | refused | mean error | worst | within 10% | 90% holds '
    '| 50% holds | calibrated | median: mean error | median within 10% |',
    '|---|---|---|---|---|---|---|---|---|---|---|',
  ]
  for mode, s in stats.items():
    ran = s['recordings'] - s['refused']
    pct = lambda x: '-' if x is None else f'{100 * x:.1f}%'  # noqa: E731
    lines.append(
      f'| {mode} | {s["recordings"]} | {s["refused"]} | {pct(s["mean_error"])} | '
      f'{pct(s["max_error"])} | {s["within_10pct"]}/{ran} | {s["holds_90"]}/{ran} | '
      f'{s["holds_50"]}/{ran} | {s["calibrated"]}/{ran} | '
      f'{pct(s["median_mean_error"])} | {s["median_within_10pct"]}/{ran} |'
    )
  return '\n'.join(lines)


def half_widths(row: dict) -> float:
  """|truth - median| in the 50% interval's half-widths on the truth's side."""
  lo, hi = row['interval_50']
  m, t = row['median'], row['truth']
  side = (hi - m) if t >= m else (m - lo)
  return abs(t - m) / side if side > 0 else math.inf


def width_50(row: dict) -> float:
  """The 50% interval's half-width over the median: how wide the estimate
  says it is, beside how far it is (``half_widths``); the calibration
  study reports its recordings' the same way (``half_width_50``)."""
  lo, hi = row['interval_50']
  return (hi - lo) / (2 * abs(row['median'])) if row['median'] else math.inf


def table_of_row(row: dict) -> str:
  """The tables a row's estimate quoted, by their cameras' words (tables of
  cameras off as the intake errs: 'intake errors, claims <range>')."""
  setting = row.get('calibration_setting') or 'no table'
  if 'intakes erred' in setting and '(claims ' in setting:
    return 'intake errors, claims ' + setting.split('(claims ')[-1].split(')')[0]
  return setting.split('cameras off by ')[-1].split(' (')[0]


def read_rows(paths: list[str]) -> list[dict]:
  """Every estimated row of the runs, with its run, fabric and table (an
  earlier pool among them skipped: its rows are the runs')."""
  rows = []
  for path in paths:
    try:
      run = read_json(path)
    except ValueError as e:
      raise ValueError(f'{path}: not a windy_rig.json ({e})') from e
    if isinstance(run, dict) and {'runs', 'groups', 'rows'} <= run.keys():
      continue  # an earlier pool (pooled.json), not a run
    if not isinstance(run, dict) or 'rows' not in run or 'settings' not in run:
      raise ValueError(f'{path}: not a windy_rig.json (no rows or settings)')
    drawn = int(run['settings'].get('fabric_draws', -1)) >= 0
    for r in run['rows']:
      if r.get('exit') == 0 and 'interval_50' in r:
        rows.append({**r, 'run': os.path.basename(path), 'drawn': drawn,
                     'table': table_of_row(r)})  # fmt: skip
  return rows


def pooled(rows: list[dict], by: str = 'table') -> list[dict]:
  """Per (fabric, table) group (``by`` 'run': per (file, table)) and over
  all: counts, intervals, errors."""
  groups = {}
  for r in rows:
    fabric = 'drawn over the prior' if r['drawn'] else "the recipe's own"
    key = (fabric, r['table']) if by == 'table' else (r['run'], r['table'])
    groups.setdefault(key, []).append(r)
  out = []
  for (fabric, table), rs in [*sorted(groups.items()), (('all', 'all'), rows)]:
    n = len(rs)
    k90, k50 = sum(bool(r['holds']) for r in rs), sum(bool(r['holds_50']) for r in rs)
    out.append({
      'fabric': fabric, 'table': table, 'n': n,
      'held_90': k90, 'held_90_ci': binomial_interval(k90, n, Z90),
      'held_50': k50, 'held_50_ci': binomial_interval(k50, n, Z90),
      'mean_error': float(np.mean([r['error'] for r in rs])) if n else None,
      'median_half_widths': float(np.median([half_widths(r) for r in rs])) if n else None,
      'median_width_50': float(np.median([width_50(r) for r in rs])) if n else None,
    })  # fmt: skip
  return out


def pool_table(groups: list[dict], by: str = 'table') -> str:
  lines = [
    f'| {"fabric" if by == "table" else "run"} | tables quoted | n | wind error | '
    '90% held [90% CI] | 50% held [90% CI] | median half-widths | '
    '50% half-width / median |',
    '|---|---|---|---|---|---|---|---|',
  ]
  for g in groups:
    ci = lambda c: f'[{100 * c[0]:.0f}, {100 * c[1]:.0f}%]'  # noqa: E731
    lines.append(
      f'| {g["fabric"]} | {g["table"]} | {g["n"]} | {100 * g["mean_error"]:.1f}% | '
      f'{g["held_90"]}/{g["n"]} {ci(g["held_90_ci"])} | '
      f'{g["held_50"]}/{g["n"]} {ci(g["held_50_ci"])} | '
      f'{g["median_half_widths"]:.2f} | {100 * g["median_width_50"]:.1f}% |'
    )
  return '\n'.join(lines)


def figure(rows: list[dict], path: str, by: str = 'table') -> None:
  """Each recording's truth in its 50% interval's half-widths, a row per
  group, with the 50% interval's edge (1) and where a Gaussian's 90% one
  would be (2.44)."""
  plt = files.pyplot()
  key_of = lambda r: (r['drawn'], r['table']) if by == 'table' else (r['run'],)  # noqa: E731
  keys = sorted({key_of(r) for r in rows})
  fig, ax = plt.subplots(figsize=(8, 0.8 * len(keys) + 1.4))
  for i, key in enumerate(keys):
    x = [min(half_widths(r), 4.0) for r in rows if key_of(r) == key]
    ax.plot(x, np.full(len(x), i), 'o', alpha=0.6)
  for edge, words in ((1.0, '50% edge'), (2.44, "a Gaussian's 90% edge")):
    ax.axvline(edge, color='gray', ls='--', lw=1)
    ax.text(edge, len(keys) - 0.4, f' {words}', fontsize=8, color='gray')
  ax.set_yticks(range(len(keys)))
  ax.set_yticklabels(
    [
      textwrap.fill(
        f'{"drawn" if k[0] else "centre"}: {k[1]}' if by == 'table' else k[0], 32
      )
      for k in keys
    ],  # fmt: skip
    fontsize=8,
  )
  ax.set_ylim(-0.6, len(keys) - 0.1)
  ax.set_xlim(0, 4.1)
  ax.set_xlabel(
    "|truth - median| / the 50% interval's half-width (capped at 4)", fontsize=9
  )
  ax.set_title("wind through the intake: each recording's truth", fontsize=10)
  fig.tight_layout()
  files.savefig(fig, path)
  plt.close(fig)


def pool_runs(args: Args) -> None:
  """``--pool``: earlier runs' rows pooled by fabric and table (``pooled``),
  printed, and written with each recording's place (pooled.png) to the
  workdir."""
  out = os.path.join(args.workdir, 'pooled.json')
  paths = sorted({p for pat in args.pool.split(',') if pat for p in glob.glob(pat)})
  if not paths:
    raise ValueError(f'--pool={args.pool!r}: no such files')
  rows = read_rows(paths)
  if not rows:
    raise ValueError(f'--pool={args.pool!r}: no estimated recordings in {paths}')
  groups = pooled(rows, args.pool_by)
  os.makedirs(args.workdir, exist_ok=True)
  keep = ('run', 'recording', 'truth', 'median', 'error', 'holds', 'holds_50',
          'drawn', 'table')  # fmt: skip
  files.write_json(out, {
    'runs': paths, 'groups': groups,
    'rows': [
      {k: r[k] for k in keep} | {'half_widths': half_widths(r), 'width_50': width_50(r)}
      for r in rows
    ],
  })  # fmt: skip
  figure(rows, os.path.join(args.workdir, 'pooled.png'), args.pool_by)
  print(pool_table(groups, args.pool_by))
  print(f'wrote {out} and pooled.png')


def main(args: Args) -> None:
  if args.pool:
    return pool_runs(args)
  modes = _modes(args.modes)
  recs = recordings(args)
  if args.parallel < 1:
    raise ValueError(f'--parallel={args.parallel}: need at least 1')
  os.makedirs(args.workdir, exist_ok=True)

  def one(named) -> list[dict]:
    """A recording (made or found) and its estimates, one mode after another."""
    name, recipe = named
    where = os.path.join(args.workdir, name)
    print(f'recording {name or "-"}: {recipe.truth}, seed {recipe.seed}, '
          f'{recipe.cloth_resolution}^2 vertices', flush=True)  # fmt: skip
    paths = rig.write(
      recipe, os.path.join(where, 'recording'), args.record_backend or args.backend
    )
    rows = []
    for mode in modes:
      row = _estimate(args, mode, paths, where, recipe.wind_speed, recipe.material)
      print(
        f'== {name or "-"} {mode}: exit {row["exit"]}, {row["seconds"]} s', flush=True
      )
      rows.append({'recording': name, 'seed': recipe.seed, **row})
    return rows

  # recordings side by side (their simulations and estimates overlap)
  with futures.ThreadPoolExecutor(args.parallel) as pool:
    rows = [r for rs in pool.map(one, recs) for r in rs]
  stats = summary(rows)
  report = {
    'recipe': dataclasses.asdict(recs[0][1]),
    'recordings': [{'name': n, **r.truth, 'seed': r.seed} for n, r in recs],
    'settings': dataclasses.asdict(args), 'summary': stats, 'rows': rows,
  }  # fmt: skip
  out = os.path.join(args.workdir, 'windy_rig.json')
  files.write_json(out, report)
  print(table(rows))
  print(summary_table(stats))
  print(f'wrote {out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
