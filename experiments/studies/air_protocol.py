"""Does the protocol's video measure the fabric's air? A study (issue 76).

Protocol sets of one fabric each: three fan settings between ``--winds``,
each recording read by a 2% anemometer, the fabric weighed (1%) and its
bending length read (3%), every fabric with its own air coefficient c drawn
log-uniform in ``--air_range`` and never told to the estimator. The
recordings are simulated in the evaluation recipe's world
(``physsim.MISMATCHES[--physics]``: fan off the normal, drag along the
cloth, damped bending, softer edges) with the wind's density times c, seen
by a camera of known pose through the depth sensor's noise. Each set is
estimated jointly twice, in one lockstep: with the air coefficient free
(the protocol's default, ``--air_coefficient=auto``) and held at ArcSim's 1
('fixed', today's model). Prints and writes:

- free: c's error and its 90%/50% intervals' coverage; each wind, the
  bending rigidity and the area weight against the truth, and how often
  their printed intervals held it (the protocol joint's coverage, measured
  on recordings of another physics);
- fixed: how often the fit check (``fit_check``: a reading the video
  disagrees with, or simulations farther than the gust floor) flags a set,
  for fabrics with c below 0.7 and within 0.9-1.1.

  python -m experiments.air_protocol --preset=smoke            # CPU, minutes
  python -m experiments.air_protocol --sets=40 --out=$OUT/air_protocol.json  # GPU

``--write_sets=N`` also writes the first N sets as a user would hand them
in (depth ``.npy`` in metres, a camera file, ``protocol.json`` with the
readings), so that ``experiments.estimate --protocol=...`` can be timed and
checked on them.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline import (
  calibration_tables,
  carried_errors,
  cli,
  estimation,
  files,
  joint,
  objective,
  protocol_checks,
  simulation,
)
from experiments.pipeline import recording as recording_lib
from experiments.studies import protocol_readings, told_cameras

# The protocol joint's quantities whose intervals the study checks.
QUANTITIES = ('bending_scale', 'area_weight', 'wind_speed', 'air_coefficient')
# The quantities whose printed intervals each set checks (``intervals_held``).
CHECKED = ('bending', 'area_weight', 'wind')


@dataclasses.dataclass(frozen=True)
class Study:
  """The sets and how they are estimated.

  Attributes:
    sets: protocol sets (fabrics).
    fans: fan settings (recordings) per set, 2 to 4: one in each equal share
      of ``winds`` (one recording with its readings is no joint: the
      calibration tables cover it).
    material: the fabric whose box the truths are drawn in.
    air_range: the air coefficients' log-uniform range.
    winds: the fan settings' range, m/s.
    physics: the recordings' world (``physsim.MISMATCHES``).
    estimate: the estimate's preset (``objective.PRESETS``).
    image: the recordings' frame size, pixels a side.
    seed: of the truths, cameras, gusts and readings.
    modes: the air coefficient's modes estimated ('free', 'fixed').
    write_sets: write the first this many sets as protocol folders under
      ``<workdir>/sets`` (0: none).
    pool: earlier runs' JSON files (``path`` or ``path:mode``) to summarise
      together instead of running (the sets of several seeds as one table).
    install: write the free mode's coverage as the shipped protocol check
      (``protocol_checks.PROTOCOL_CHECKS_FILE``), which a protocol joint's
      estimate then quotes.
    measured: the quantities whose coverage the install ships (the rest are
      named as not measured: e.g. one whose intervals changed since the sets
      ran).
    camera_sd_m: the camera shift each estimate carries (m, 1 sd per axis;
      an estimate of a user's recordings carries its intake's), each
      recording's told camera off by an error of that size
      (``told_cameras``); 0 with ``camera_sd_deg`` 0: cameras known exactly.
    camera_sd_deg: the same for the camera's tilt about the pins (degrees).
    camera_sd_spread: each recording's error drawn over exp(+-spread) of
      that (``told_cameras.spread_sd``), so the check holds for errors
      anywhere in that range; 0: every recording the one error.
    length_sd: the strip's bending-length reading's relative sd (a ruler's
      cantilever 3%; a depth reading's median about 1.8%).
    length_sd_spread: each set's strip reading's sd drawn as ``length_sd``
      x exp(spread x z), z standard normal clipped to +-2.5, as a depth
      reading's varies with the strip's length and pixels (0.55 spans the
      depth reader's 0.6-7%); 0: every set's ``length_sd``.
    length_dof: that reading's error law: Student's t of this many degrees
      of freedom (the depth reader's ``physsim.overhang_depth.DOF``), or 0,
      Gaussian (a ruler's).
    workdir: where the searches keep their files.
    out: JSON path ('' for none).
  """

  sets: int = 40
  fans: int = 3
  material: str = 'gray_interlock'
  air_range: tuple[float, ...] = (0.4, 1.25)
  winds: tuple[float, ...] = (1.5, 4.0)
  physics: str = cli.choice('mismatched', tuple(physsim.MISMATCHES))
  estimate: str = 'default'
  image: int = 64
  seed: int = 0
  modes: tuple[str, ...] = ('free', 'fixed')
  write_sets: int = 0
  pool: tuple[str, ...] = ()
  install: bool = False
  measured: tuple[str, ...] = QUANTITIES
  camera_sd_m: float = 0.0
  camera_sd_deg: float = 0.0
  camera_sd_spread: float = 0.0
  length_sd: float = 0.03
  length_sd_spread: float = 0.0
  length_dof: float = 0.0
  workdir: str = 'out/benchmarks/air_protocol'
  out: str = ''


PRESETS = {
  'default': Study(),
  'smoke': Study(sets=2, estimate='smoke', image=32, modes=('free',)),
}


def truths(args: Study) -> list[dict]:
  """Per set: bending (log-uniform), area weight (uniform) in the box, c
  (log-uniform in ``air_range``) and ``fans`` fan winds, one per equal share
  of the range."""
  rng = np.random.default_rng([args.seed, 41])
  space = physsim.search_space(args.material)
  lo, hi = args.winds
  share = (hi - lo) / args.fans
  out = []
  for _ in range(args.sets):
    b = math.exp(rng.uniform(*np.log(space.bending_scale)))
    w = rng.uniform(*space.area_weight)
    c = math.exp(rng.uniform(*np.log(args.air_range)))
    v = [lo + share * (k + rng.uniform(0.1, 0.9)) for k in range(args.fans)]
    out.append({'bending_scale': b, 'area_weight': w, 'air_coefficient': c, 'winds': v})
  return out


def record(args: Study, config, truth: dict, k: int) -> list:
  """The set's recordings, one per fan setting (``recording.Recording``, in
  memory)."""
  sim = config.simulation
  n = len(truth['winds'])
  mesh = physsim.square(sim.cloth_resolution, size=sim.cloth_size)
  world = physsim.MISMATCHES[args.physics]
  base = physsim.config_for_mesh(mesh, sim.fps, **world.sim_fields())
  air = dataclasses.replace(
    base, air_density=base.air_density * truth['air_coefficient']
  )
  cloth = physsim.build(mesh, sim.material, config=air)
  space = physsim.search_space(sim.material)
  key = jax.random.key(args.seed * 1000 + k)
  p = physsim.params.make(
    bending_scale=[truth['bending_scale']] * n, wind_speed=truth['winds'],
    area_weight=[truth['area_weight']] * n,
  )  # fmt: skip
  out = physsim.simulate(
    cloth, p, frames=sim.frames, fps=sim.fps, warmup=sim.warmup,
    wind=world.wind(sim.gusts), key=jax.random.fold_in(key, 1), space=space,
  )  # fmt: skip
  intr = physsim.Intrinsics(width=args.image, height=args.image)
  ranges = physsim.PoseRanges().for_cloth(sim.cloth_size)
  poses = physsim.sample_poses(jax.random.fold_in(key, 2), n, ranges)
  render = physsim.make_depth_renderer(mesh.faces, intr)
  recs = []
  for j in range(n):
    pose = jax.tree.map(lambda a, j=j: a[j], poses)
    depth = render(
      jnp.asarray(out.positions[j : j + 1]), jax.tree.map(lambda a: a[None, None], pose)
    )[0, 0]  # (T, H, W)
    keys = jax.random.split(jax.random.fold_in(key, 10 + j), depth.shape[0])
    noisy = jax.vmap(lambda kk, d: physsim.sensor.apply_noise(kk, d, intr))(keys, depth)
    truth_j = {
      'bending_scale': truth['bending_scale'], 'wind_speed': truth['winds'][j],
      'area_weight': truth['area_weight'], 'air_coefficient': truth['air_coefficient'],
    }  # fmt: skip
    recs.append(recording_lib.Recording(
      np.asarray(noisy, np.float32), sim.fps, intr, pose, f'set_{k:02d}/fan_{j}',
      truth_j,
    ))  # fmt: skip
  if not bool(np.all(out.valid)):
    raise ValueError(f'set {k}: a simulation blew up ({truth})')
  return recs


def strip_law(args: Study) -> protocol_readings.StripLaw:
  """The study's strip readings' law (``protocol_readings.StripLaw``)."""
  return protocol_readings.StripLaw(args.length_sd, args.length_sd_spread,
                                    args.length_dof)  # fmt: skip


def _flagged(result: dict) -> bool:
  check = result.get('fit_check') or {}
  p = check.get('predictive')
  return bool(check.get('conflicts')) or (p is not None and not p['fits'])


def summarise(rows: list[dict]) -> dict:
  """Per mode, the measures the module doc names."""
  out = {}
  for mode in sorted({r['mode'] for r in rows}):
    mine = [r for r in rows if r['mode'] == mode]
    s = {'sets': len(mine)}
    s['bending_factor_median'] = float(np.median([r['bending_factor'] for r in mine]))
    s['area_weight_pct_mean'] = float(np.mean([r['area_weight_pct'] for r in mine]))
    s['wind_pct_mean'] = float(np.mean([e for r in mine for e in r['wind_pct']]))
    if mode == 'free':
      s['air_pct_mean'] = float(np.mean([r['air_pct'] for r in mine]))
      for level in (90, 50):
        s[f'air_held_{level}'] = float(np.mean([r[f'air_in_{level}'] for r in mine]))
    held = [r['held'] for r in mine if 'held' in r]
    if held:  # each quantity's intervals over the sets that checked them
      s['held_sets'] = len(held)
      keys = sorted({k for h in held for k in h})
      s['held_n'] = {k: sum(k in h for h in held) for k in keys}
      s['held'] = {
        k: float(np.mean([x for h in held if k in h for x in np.atleast_1d(h[k])]))
        for k in keys
      }
    low = [r['flagged'] for r in mine if r['c'] < 0.7]
    near = [r['flagged'] for r in mine if 0.9 <= r['c'] <= 1.1]
    s['flagged_c_below_0.7'] = [int(sum(low)), len(low)]
    s['flagged_c_0.9_1.1'] = [int(sum(near)), len(near)]
    out[mode] = s
  return out


def _held(interval, truth) -> bool:
  lo, hi = interval
  return bool(lo <= truth <= hi)


def intervals_held(out: dict, truth: dict) -> dict:
  """Whether each printed interval of a joint (``combine_joint``'s) holds
  the truth: bending, area weight, and each recording's wind."""
  h = {}
  for level in (90, 50):
    key = f'interval_{level}'
    h[f'bending_{level}'] = _held(out['bending_scale'][key], truth['bending_scale'])
    h[f'area_weight_{level}'] = _held(out['area_weight'][key], truth['area_weight'])
    h[f'wind_{level}'] = [
      _held(r['wind_speed'][key], v)
      for r, v in zip(out['recordings'], truth['winds'], strict=True)
    ]
  return h


def write_set(folder: str, recs: list, shared: dict, winds: list) -> str:
  """One set as a user hands it in: per recording its depth (``.npy``,
  metres) and camera file (project form, with fps), and ``protocol.json``
  with the anemometer's, the scale's and the strip's readings. Returns the
  protocol file's path."""
  os.makedirs(folder, exist_ok=True)
  entries = []
  for j, (rec, (v, sd)) in enumerate(zip(recs, winds, strict=True)):
    depth, camera = f'fan_{j}.npy', f'fan_{j}_camera.json'
    files.write_atomic(
      os.path.join(folder, depth), lambda p, d=rec.depth: np.save(p, d)
    )
    files.write_json(os.path.join(folder, camera), {
      'intrinsics': rec.intrinsics.to_dict(), 'fps': rec.fps,
      'extrinsics': physsim.pose_to_dict(rec.pose),
    })  # fmt: skip
    entries.append({'recording': depth, 'camera_json': camera, 'world_up': 'z',
                    'wind_speed': v, 'wind_speed_sd': sd})  # fmt: skip
  path = os.path.join(folder, 'protocol.json')
  files.write_json(path, {'recordings': entries, 'fabric': shared})
  return path


def _plan(args: Study, base, sets: list[dict]) -> list[tuple]:
  """Every set recorded (the first ``write_sets`` written as a user's) and
  its joint's jobs per mode: ``(set, mode, workdir, jobs)``."""
  space = physsim.search_space(args.material)
  plan = []
  for k, truth in enumerate(sets):
    shared, winds = protocol_readings.readings(args.seed, truth, space, strip_law(args))
    recs = record(args, base, truth, k)
    if k < args.write_sets:
      write_set(os.path.join(args.workdir, 'sets', f'set_{k:02d}'), recs, shared, winds)
    recs, own = told(args, base, recs, k)
    for mode in args.modes:
      config = base.replace(air_coefficient=mode, **shared)
      wd = os.path.join(args.workdir, mode, f'set_{k:02d}')
      plan.append(
        (k, mode, wd, joint.joint_jobs(config, recs, '', wd, winds, overrides=own))
      )
    print(f'set {k}: recorded (c {truth["air_coefficient"]:.2f})', flush=True)
  return plan


def told(args: Study, base, recs: list, k: int) -> tuple[list, list[dict] | None]:
  """Set ``k``'s recordings as their estimates are told them, and each one's
  carried camera error (a joint's ``overrides``; None for cameras known
  exactly): recording j's error drawn over the range (``camera_sd_spread``)
  from (seed, k, j), its camera moved by an error of that size."""
  sd = (args.camera_sd_m, args.camera_sd_deg)
  if not any(sd):
    return recs, None
  pins = simulation.pin_centre(base.simulation)
  key = jax.random.fold_in(jax.random.key(args.seed), told_cameras.POSE_STREAM)
  out, own = [], []
  for j, rec in enumerate(recs):
    m, deg = told_cameras.spread_sd(
      sd, args.camera_sd_spread, [args.seed, told_cameras.SD_STREAM, k, j]
    )
    moved = told_cameras.moved_pose(
      jax.random.fold_in(jax.random.fold_in(key, k), j), rec.pose, (m, deg), pins
    )
    out.append(rec._replace(pose=moved))
    own.append({'camera_sd_m': m, 'camera_sd_deg': deg})
  return out, own


def score(k: int, mode: str, truth: dict, out: dict, results: list) -> dict:
  """One set's joint (``combine_joint``'s ``out``; its searches' ``results``)
  against its truth: the errors, which intervals held, and whether the fit
  check flagged any of its recordings."""
  row = {'set': k, 'mode': mode, 'c': truth['air_coefficient']}
  row['bending_factor'] = math.exp(
    abs(math.log(out['bending_scale']['median'] / truth['bending_scale']))
  )
  row['area_weight_pct'] = 100 * abs(
    out['area_weight']['median'] / truth['area_weight'] - 1
  )
  row['wind_pct'] = [
    100 * abs(r['wind_speed']['median'] / v - 1)
    for r, v in zip(out['recordings'], truth['winds'], strict=True)
  ]
  if 'air_coefficient' in out:
    a = out['air_coefficient']
    row['air'] = a['median']
    row['air_pct'] = 100 * abs(a['median'] / row['c'] - 1)
    for level in (90, 50):
      row[f'air_in_{level}'] = _held(a[f'interval_{level}'], row['c'])
  row['held'] = intervals_held(out, truth)
  row['flagged'] = any(_flagged(r) for r in results)
  row['printed'] = printed(out, truth)
  return row


def printed(out: dict, truth: dict) -> dict:
  """Each printed median and 90% / 50% interval beside its truth (each
  recording's wind in turn): what a later pooled run needs to fit and check
  a recalibration of the joint's intervals, which the held flags alone do
  not carry."""
  keep = lambda q, t: {  # noqa: E731
    'truth': t,
    **{k: q[k] for k in ('median', 'interval_90', 'interval_50')},
  }
  found = {
    'bending_scale': keep(out['bending_scale'], truth['bending_scale']),
    'area_weight': keep(out['area_weight'], truth['area_weight']),
    'wind_speed': [
      keep(r['wind_speed'], v)
      for r, v in zip(out['recordings'], truth['winds'], strict=True)
    ],
  }
  if 'air_coefficient' in out:
    found['air_coefficient'] = keep(out['air_coefficient'], truth['air_coefficient'])
  return found


def _row_line(row: dict) -> str:
  return (
    f'set {row["set"]} {row["mode"]}: c {row["c"]:.2f} -> '
    f'{row.get("air", float("nan")):.2f}, bending x{row["bending_factor"]:.2f}, '
    f'weight {row["area_weight_pct"]:.1f}%, wind {np.mean(row["wind_pct"]):.1f}%, '
    f'flagged {row["flagged"]}'
  )


def table(summary: dict) -> str:
  """The summary as two markdown tables: the errors and the fit check's
  flags; each printed interval's coverage."""
  lines = [
    '| mode | sets | c error | c 90% / 50% held | wind | bending | weight | '
    'flagged c<0.7 | flagged 0.9-1.1 |',
    '|---|---|---|---|---|---|---|---|---|',
  ]
  pct = lambda h, q: (  # noqa: E731
    f'{100 * h[f"{q}_90"]:.0f}% / {100 * h[f"{q}_50"]:.0f}%' if f'{q}_90' in h else '-'
  )
  for mode, s in summary.items():
    lines.append(
      f'| {mode} | {s["sets"]} | {s.get("air_pct_mean", float("nan")):.1f}% | '
      f'{pct(s, "air_held")} | '
      f'{s["wind_pct_mean"]:.1f}% | x{s["bending_factor_median"]:.2f} | '
      f'{s["area_weight_pct_mean"]:.2f}% | {s["flagged_c_below_0.7"]} | '
      f'{s["flagged_c_0.9_1.1"]} |'
    )
  lines += [
    '',
    '| mode | bending 90% / 50% held | area weight | wind |',
    '|---|---|---|---|',
  ]
  for mode, s in summary.items():
    h = s.get('held', {})
    cells = [pct(h, q) for q in ('bending', 'area_weight', 'wind')]
    lines.append(f'| {mode} | ' + ' | '.join(cells) + ' |')
  return '\n'.join(lines)


# What pooled runs must share with the study that pools them.
POOLED_ALIKE = (
  'material',
  'air_range',
  'winds',
  'physics',
  'estimate',
  'image',
  'fans',
  'camera_sd_m',
  'camera_sd_deg',
  'camera_sd_spread',
  'length_sd',
  'length_sd_spread',
  'length_dof',
)


def pooled(paths: tuple[str, ...], args: Study | None = None) -> list[dict]:
  """The rows of earlier runs' JSON files, ``path``, ``path:mode`` (that
  mode's rows only: e.g. a run's rows from before a change of one mode) or
  ``path:mode:q+q`` (those rows' interval checks of the quantities ``q`` of
  ``CHECKED`` only: a run from before a change of another quantity's
  interval); each run's settings (``POOLED_ALIKE``) must be ``args``'s."""
  rows = []
  for entry in paths:
    path, mode, keep = (entry.split(':', 2) + ['', ''])[:3]
    kept = set(keep.split('+')) if keep else set(CHECKED)
    if kept - set(CHECKED):
      raise ValueError(
        f'--pool: {entry}: {sorted(kept - set(CHECKED))} not in {CHECKED}'
      )
    try:
      with open(path) as f:
        found = json.load(f)
      ran, their_rows = found['args'], found['rows']
    except (OSError, ValueError, KeyError, TypeError) as e:
      raise ValueError(f'--pool: {path}: not a study JSON ({e})') from None
    for name in POOLED_ALIKE if args is not None else ():
      mine, default = getattr(args, name), getattr(Study(), name)
      theirs = ran.get(name, default)  # runs from before a setting kept its default
      theirs = tuple(theirs) if isinstance(mine, tuple) else theirs
      if theirs != mine:
        raise ValueError(f'--pool: {path} ran with {name}={theirs!r}, not {mine!r}')
    for r in their_rows:
      if mode and r.get('mode') != mode:
        continue
      if 'held' in r:
        held = {k: v for k, v in r['held'].items() if k.rpartition('_')[0] in kept}
        r = {**r, 'held': held}
      rows.append(r)
  return rows


def _base(args: Study):
  """The estimate's settings every set is estimated with (its readings aside)."""
  return objective.PRESETS[args.estimate].replace(
    material=args.material, distance='shape'
  )


def check_args(args: Study) -> None:
  """Refuses settings the study cannot run or install, before any set is
  recorded."""
  if not 2 <= args.fans <= 4:
    raise ValueError(
      f'--fans={args.fans}: need 2 to 4 fan settings a set (a joint of'
      ' recordings; one recording with its readings is calibrated by the tables)'
    )
  unknown = sorted(set(args.measured) - set(QUANTITIES))
  if unknown:
    raise ValueError(f'--measured: {unknown} not among {QUANTITIES}')
  told_cameras.check_spread(
    (args.camera_sd_m, args.camera_sd_deg), args.camera_sd_spread
  )
  strip_law(args).check()


def check_record(args: Study, summary: dict) -> dict:
  """The shipped protocol check (``protocol_checks.protocol_note`` reads
  it): the free mode's coverage of each of ``args.measured``, the others
  named as not measured, with the settings and readings the sets had."""
  check_args(args)
  free = summary.get('free')
  if not free or 'held' not in free:
    raise ValueError('--install: no free-mode sets with their intervals checked')
  held = {**free['held'], 'air_coefficient_90': free['air_held_90'],
          'air_coefficient_50': free['air_held_50']}  # fmt: skip
  key = lambda q: {'bending_scale': 'bending', 'wind_speed': 'wind'}.get(q, q)  # noqa: E731
  sd = (args.camera_sd_m, args.camera_sd_deg)
  config = _base(args).replace(camera_sd_m=sd[0], camera_sd_deg=sd[1])
  camera = carried_errors.table_words((*sd, args.camera_sd_spread))
  return {
    'mode': f'protocol joint, {args.fans} fan settings, air free',
    'recordings': args.fans,
    'n': free['sets'],
    'physics': args.physics, 'likelihood': config.scoring.likelihood,
    'sharpness': config.scoring.sharpness,
    'setting': f'{args.material.replace("_", " ")}, {args.estimate} estimate, '
               f'shape distance, {camera}',
    'config': {'estimate': config.flat(), 'camera_sd_spread': args.camera_sd_spread},
    'readings': {**protocol_readings.READ, 'bending_length': args.length_sd},
    'length_dof': args.length_dof,
    **({'length_sd_range': list(strip_law(args).range())}
       if args.length_sd_spread else {}),  # fmt: skip
    'coverage': {
      q: {
        **{f'interval_{lv}': held[f'{key(q)}_{lv}'] for lv in (90, 50)},
        'n': free['sets'] if q == 'air_coefficient'
             else free.get('held_n', {}).get(f'{key(q)}_90', free['held_sets']),
      }
      for q in QUANTITIES if q in args.measured
    },
    'unmeasured': [q for q in QUANTITIES if q not in args.measured],
  }  # fmt: skip


def run(args: Study) -> dict:
  """Records and estimates every set (one lockstep over all their searches),
  or with ``pool`` reads earlier runs' rows; prints each set's line and the
  tables; writes and returns the JSON."""
  t0 = time.perf_counter()
  check_args(args)
  if args.pool:
    rows, seconds = pooled(args.pool, args), {}
  else:
    base = _base(args)
    sets = truths(args)
    plan = _plan(args, base, sets)
    seconds = {'record': time.perf_counter() - t0}
    t1 = time.perf_counter()
    jobs = [j for *_, js in plan for j in js]
    done = estimation.estimate_many(jobs, figures=False)
    seconds['estimate'] = time.perf_counter() - t1
    t1 = time.perf_counter()
    rows, i = [], 0
    for k, mode, wd, js in plan:
      mine, i = done[i : i + len(js)], i + len(js)
      rows.append(score(k, mode, sets[k], joint.combine_joint(js, mine, wd), mine))
      print(_row_line(rows[-1]), flush=True)
    seconds['combine'] = time.perf_counter() - t1
  seconds['total'] = time.perf_counter() - t0
  summary = summarise(rows)
  print(table(summary))
  print(', '.join(f'{k} {v:.0f} s' for k, v in seconds.items()))
  out = {
    'args': dataclasses.asdict(args), 'summary': summary, 'rows': rows,
    'seconds': seconds, 'device': str(jax.devices()[0]),
  }  # fmt: skip
  if args.out:
    files.write_json(args.out, out)
  if args.install:
    path = protocol_checks.PROTOCOL_CHECKS_FILE
    shipped = (
      calibration_tables.read_calibration(path) if os.path.isfile(path) else None
    )
    files.write_json(
      path, protocol_checks.with_check(shipped, check_record(args, summary))
    )
    print(f'installed: {path} ({args.fans} fan settings)')
  return out
