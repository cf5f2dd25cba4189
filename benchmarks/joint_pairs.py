"""Area weight from several fan settings, each with an anemometer reading.

Makes ``--pairs`` groups of ``--group`` real-like recordings of one fabric
(the ``generate_dataset --preset=eval`` recipe at the network's image size; a
group shares bending and area weight and draws a wind per recording, as
``experiments.calibrate`` draws its pairs: ``calibration.truths``), gives each
recording a simulated anemometer reading (``measurements.simulated_reading``,
``--reading_sd``) and estimates every group jointly: all recordings' searches
in lockstep (``joint.joint_jobs``, one ``estimation.estimate_many``), each
steered by its reading, then each group's joint posterior
(``joint.combine_joint``).
Prints, over the recordings, the mean error of area weight, wind and the load
ratio from one recording with its reading (each joint's ``alone``), from the
group's first k recordings jointly (posterior median, 2 <= k < group) and from
the whole group (posterior median and its reported point), beside the range
centre's, and the joint points' bias; writes JSON. ``--distance`` picks the
discrepancy (``shape``: where the sheet hangs); ``--gusts`` and
``--cloth_resolution`` set the simulations' gust intensity and mesh (the
recordings' own: 0.3 and 33); ``--seconds`` the clips' length and
``--fan_winds`` the range the recordings' winds are drawn from (a user's
gentle fan settings; by default the whole search box). The shape distance
needs no network (no ``--model``: frames at ``--image_size``). A GPU at paper
size:

  python -m benchmarks.joint_pairs --distance=energy \\
      --model=out/table1/physnet_depth/simulation/gray_interlock \\
      --workdir=/tmp/pairs --pairs=6 [--group=3]
  python -m benchmarks.joint_pairs --distance=shape --workdir=/tmp/pairs_shape --pairs=6
  python -m benchmarks.joint_pairs --distance=shape --workdir=/tmp/pairs_mm --pairs=16 \
      --group=3 --fan_winds=1,3.5 --physics=mismatched   # another physics's recordings

``--hem_mass=0.3``: each pair is one sheet filmed twice at one fan setting,
the second time with that many kg taped along its free hem (a second sweep
of the same truths with ``datasets.Config.hem_mass``, its own cameras and
gusts), estimated as a protocol file with ``"fan"`` and ``"hem_mass"`` is:
one wind for both (``posterior.joint``'s ``fans``), the hem simulated in the
second's search; ``--reading_sd=0`` gives no anemometer (the video alone).
Read from the same searches: the pair with a wind each (``fans_apart``) and
the plain sheet alone.
"""

from __future__ import annotations

import dataclasses
import os

import jax
import numpy as np
from absl import logging

import physsim
from experiments.pipeline import (
  cli,
  datasets,
  embedding,
  estimation,
  files,
  measurements,
  objective,
)
from experiments.pipeline import joint as joint_lib
from experiments.pipeline import recording as recording_lib
from experiments.studies import calibration

_ESTIMATE_FIELDS = tuple(f.name for f in dataclasses.fields(objective.EstimateConfig))


@dataclasses.dataclass(frozen=True)
class Args:
  """The joint-pairs benchmark. ``--preset`` picks the estimate settings
  (``objective.PRESETS``: default, paper, smoke); the flags below that say
  "the preset's" override one of them.

  Attributes:
    model: the fabric's trained network (none with --distance=shape).
    image_size: pixels a side of the frames without a network (>= 16).
    workdir: recordings and estimates go here (required).
    material: the fabric.
    pairs: groups of recordings (fabrics).
    group: recordings per group (fan settings, >= 2).
    seed: truths, readings and searches.
    reading_sd: the anemometer's relative standard error.
    distance: the discrepancy (empty: the preset's).
    likelihood: the posterior's likelihood (empty: the preset's).
    sharpness: the likelihood's constant (0: the preset's; >= 0).
    gusts: the simulations' gust intensity (0: the preset's; >= 0).
    backend: simulator (empty: the preset's).
    cloth_resolution: the simulations' cloth vertices per side (0: the
      preset's; the recordings have 33).
    smoke: CPU-sized recordings (checks the script).
    seconds: each recording's length, s (0: the recipe's; >= 0).
    fan_winds: lo,hi m/s: draw each recording's wind here (empty: the search
      box).
    physics: the recordings' physics: 'own' (the estimator's simulator) or
      'mismatched' (``physsim.mismatch.WORLD``; the estimates keep their own).
    hem_mass: kg at the hem of each pair's second recording, which shares
      the first's fan setting (0: pairs of fan settings; needs --group=2).
    estimate: the preset's estimate settings (no flags of their own).
  """

  model: str = ''
  image_size: int = 256
  workdir: str = cli.required()
  material: str = 'gray_interlock'
  pairs: int = 6
  group: int = 2
  seed: int = 0
  reading_sd: float = 0.02
  distance: str = cli.choice('', ['', *objective.DISTANCES])
  likelihood: str = cli.choice('', ['', *objective.LIKELIHOODS])
  sharpness: float = 0.0
  gusts: float = 0.0
  backend: str = ''
  cloth_resolution: int = 0
  smoke: bool = False
  seconds: float = 0.0
  fan_winds: tuple[str, ...] = ()
  physics: str = cli.choice('own', tuple(physsim.MISMATCHES))
  hem_mass: float = 0.0
  estimate: objective.EstimateConfig = cli.nested(
    objective.EstimateConfig(), skip=_ESTIMATE_FIELDS
  )


PRESETS = {k: Args(estimate=v) for k, v in objective.PRESETS.items()}
NAMES = ('wind_speed', 'area_weight', 'load_ratio')
FLAG_NAMES = ('model', 'image_size', 'material', 'pairs', 'group', 'seed', 'reading_sd', 'preset',
              'distance', 'likelihood', 'sharpness', 'gusts', 'cloth_resolution', 'backend',
              'seconds', 'fan_winds', 'physics', 'hem_mass')  # fmt: skip
_LOWER = {'image_size': 16, 'group': 2, 'sharpness': 0.0, 'gusts': 0.0,
          'cloth_resolution': 0, 'seconds': 0.0, 'reading_sd': 0.0,
          'hem_mass': 0.0}  # fmt: skip


def _preset(args: Args) -> str:
  """The name of the preset whose estimate settings ``args`` carry."""
  return next(k for k, v in objective.PRESETS.items() if v == args.estimate)


def _recordings(args: Args, workdir: str, size: int) -> list[list[dict]]:
  """The groups' recordings (made or resumed), group-major."""
  study = calibration.Config(material=args.material, pairs=args.pairs, seed=args.seed)
  truths = calibration.truths(study, group=args.group)
  if args.fan_winds:  # the user's fan settings: winds drawn in a narrower range
    lo, hi = _fan_winds(args)
    rng = np.random.default_rng([args.seed, 11])
    truths = truths._replace(wind_speed=rng.uniform(lo, hi, truths.wind_speed.shape))
  if args.hem_mass:  # one fan setting a pair: the first's wind for both
    v = truths.wind_speed.reshape(args.pairs, args.group)
    truths = truths._replace(wind_speed=np.repeat(v[:, :1], args.group, 1).ravel())
    return _hem_pairs(args, workdir, size, truths)
  n = args.group * args.pairs
  cfg = _sweep(args, size, n)
  root = os.path.join(workdir, 'recordings')
  datasets.run(cfg, root, params={args.material: truths})
  index = physsim.dataset.open_dataset(root)
  rows = {int(r['seq_id']): r for r in index.filter(material=args.material).rows}
  out = []
  for p in range(args.pairs):
    group = [rows.get(args.group * p + k) for k in range(args.group)]
    if all(r is not None and r['valid'] for r in group):  # a group needs all
      out.append([{'seq': int(r['seq_id']), 'path': index.path(r)} for r in group])
    else:
      print(f'group {p}: a recording was not kept (camera coverage); left out')
  return out


def _sweep(args: Args, size: int, n: int, **kw) -> datasets.Config:
  """The recordings' dataset sweep of ``n`` sequences (``kw``: its changes)."""
  cfg = datasets.PRESETS['smoke' if args.smoke else 'eval']
  cfg = dataclasses.replace(
    cfg, materials=(args.material,), sequences=n, resolution=size,
    batch_size=min(n, 64), physics=args.physics,
    **({'backend': args.backend} if args.backend else {}),
    **{'seed': 6000 + args.seed, **kw},
  )  # fmt: skip
  if args.seconds:  # a longer (or shorter) clip of the same scenes
    cfg = dataclasses.replace(cfg, frames=round(args.seconds * cfg.fps))
  return cfg


def _hem_pairs(args: Args, workdir: str, size: int, truths) -> list[list[dict]]:
  """Each pair's plain sheet and its hemmed twin, of one truth (the pair's
  first): two sweeps, the second with the hem, another seed (its own cameras
  and gusts), each resumed where it stands."""
  first = jax.tree.map(lambda a: a[:: args.group], truths)
  out = {}
  for name, kw in (('recordings', {}),
                   ('recordings_hem', {'hem_mass': args.hem_mass, 'seed': 7000 + args.seed})):  # fmt: skip
    root = os.path.join(workdir, name)
    datasets.run(_sweep(args, size, args.pairs, **kw), root,
                 params={args.material: first})  # fmt: skip
    index = physsim.dataset.open_dataset(root)
    out[name] = {int(r['seq_id']): (r, index.path(r))
                 for r in index.filter(material=args.material).rows}  # fmt: skip
  groups = []
  for p in range(args.pairs):
    pair = [out[name].get(p) for name in ('recordings', 'recordings_hem')]
    if all(x is not None and x[0]['valid'] for x in pair):
      # seq: the pair's index in the group-major numbering of the readings
      groups.append(
        [{'seq': args.group * p + k, 'path': x[1]} for k, x in enumerate(pair)]
      )
    else:
      print(f'pair {p}: a recording was not kept (camera coverage); left out')
  return groups


def _fan_winds(args: Args) -> tuple[float, float]:
  """``--fan_winds`` as (lo, hi) m/s, inside the fabric's search box."""
  box = physsim.search_space(args.material).wind_speed
  try:
    lo, hi = (float(v) for v in args.fan_winds)
  except ValueError:
    lo = hi = float('nan')
  if not (box[0] <= lo < hi <= box[1]):
    raise ValueError(
      f'--fan_winds={",".join(args.fan_winds)}: need lo,hi m/s with '
      f'{box[0]:g} <= lo < hi <= {box[1]:g} (the search box)'
    )
  return lo, hi


def _error(est: float, truth: float) -> float:
  return float(100 * abs(est / truth - 1))


def _first_k_medians(jobs, k: int, space, shared_bias=None) -> list[dict]:
  """Posterior medians of each of the first ``k`` recordings' (wind, area
  weight, load ratio) under their joint posterior (``posterior.joint`` of
  their saved likelihoods, ``joint_lib.joint_posterior``; one wind each)."""
  joint, _ = joint_lib.joint_posterior(
    jobs[:k], jax.random.key(jobs[0].config.seed), shared_bias
  )
  out = []
  for u in joint['samples']:
    p = physsim.from_unit(u, space)
    ratio = physsim.load_ratio(p.wind_speed, p.area_weight)
    out.append({
      'wind_speed': float(np.median(p.wind_speed)),
      'area_weight': float(np.median(p.area_weight)),
      'load_ratio': float(np.median(ratio)),
    })  # fmt: skip
  return out


def _config(args: Args) -> objective.EstimateConfig:
  """The estimate's settings: the preset's with the flags that override it,
  every flag checked before any work."""
  for name, low in _LOWER.items():
    if not getattr(args, name) >= low:
      raise ValueError(f'--{name}={getattr(args, name)}: need at least {low}')
  config = args.estimate.replace(
    material=args.material,
    **({'backend': args.backend} if args.backend else {}),
    **({'distance': args.distance} if args.distance else {}),
    **({'likelihood': args.likelihood} if args.likelihood else {}),
    **({'sharpness': args.sharpness} if args.sharpness else {}),
    **({'gusts': args.gusts} if args.gusts else {}),
    **({'cloth_resolution': args.cloth_resolution} if args.cloth_resolution else {}),
  )  # fmt: skip
  config.check()  # e.g. the synthetic likelihood without the shape distance
  if args.fan_winds:
    _fan_winds(args)  # a bad range refused before any work
  if args.hem_mass and args.group != 2:
    raise ValueError(
      f'--hem_mass pairs a sheet with its hemmed twin: --group=2, got {args.group}'
    )
  if args.seconds:  # compare the whole clip
    config = config.replace(frames=round(args.seconds * config.simulation.fps))
  return config


def _plan(args: Args, config, net, groups: list[list[dict]]) -> list[tuple]:
  """Per group: (group, recordings, readings, workdir, its searches)."""
  fans = ['pair', 'pair'] if args.hem_mass else None
  overrides = [{}, {'hem_mass': args.hem_mass}] if args.hem_mass else None
  nets = {args.model: net} if args.model else None  # restored once
  plan = []
  for group in groups:
    recs, winds = [], []
    for r in group:
      rec = recording_lib.load_recording(
        r['path'],
        fps=config.simulation.fps,
        size=net.image_size,
        frames=config.simulation.frames,
      )
      recs.append(rec)
      if args.reading_sd:  # one fan setting, one reading: the pair's first's
        seq = group[0]['seq'] if args.hem_mass else r['seq']
        m = measurements.simulated_reading(
          'wind_speed', rec.truth, args.reading_sd, args.seed, seq
        )
        winds.append((m.wind_speed, m.wind_speed_sd))
    wd = os.path.join(args.workdir, f'pair_{group[0]["seq"] // args.group:02d}')
    # the calibrated pair's model: the fabric takes the air as ArcSim's sheet
    fixed = config.replace(air_coefficient='fixed')
    jobs = joint_lib.joint_jobs(fixed, recs, args.model, wd, winds or None, nets=nets,
                                overrides=overrides, fans=fans)  # fmt: skip
    plan.append((group, recs, winds, wd, jobs))
  return plan


def _row(group, k: int, rec, winds, out: dict, guess: dict) -> dict:
  """Recording ``k`` of a group: its truth, reading, the points of it alone
  and of the joint, their errors and the range centre's, the joint's cover."""
  t = dict(rec.truth)
  t['load_ratio'] = float(physsim.load_ratio(t['wind_speed'], t['area_weight']))
  alone = out['recordings'][k]['alone']
  joint = {
    'wind_speed': out['recordings'][k]['wind_speed'],
    'area_weight': out['area_weight'],
    'load_ratio': out['recordings'][k]['load_ratio'],
  }
  one = {n: alone[n]['value'] for n in NAMES[:2]}
  one['load_ratio'] = physsim.load_ratio(one['wind_speed'], one['area_weight'])
  # the points themselves beside their errors, for their bias (signed error)
  points = {
    'alone': {n: float(one[n]) for n in NAMES},
    'joint': {n: float(joint[n]['bayes']) for n in NAMES},
  }
  return {
    'seq': group[k]['seq'],
    'truth': t,
    'reading': list(winds[k]) if winds else None,
    **{f'{who}_point': p for who, p in points.items()},
    **{who: {n: _error(p[n], t[n]) for n in NAMES} for who, p in points.items()},
    'joint_median': {n: _error(joint[n]['median'], t[n]) for n in NAMES},
    'centre': {n: _error(guess[n], t[n]) for n in NAMES},
    'joint_covered_90': {
      n: bool(joint[n]['interval_90'][0] <= t[n] <= joint[n]['interval_90'][1])
      for n in NAMES
    },
    # how much each narrows the 90% interval (prior width over posterior's)
    'narrowing_90': {
      'alone': {n: alone[n]['narrowing_90'] for n in NAMES[:2]},
      'joint': {n: joint[n]['narrowing_90'] for n in NAMES[:2]},
    },
  }  # fmt: skip


def _rows(args: Args, plan, results, space) -> list[dict]:
  """Every kept recording's row; a group whose search failed is left out."""
  fans = ['pair', 'pair'] if args.hem_mass else None
  centre = space.center()
  guess = {
    'wind_speed': float(centre.wind_speed), 'area_weight': float(centre.area_weight),
    'load_ratio': float(physsim.load_ratio(centre.wind_speed, centre.area_weight)),
  }  # fmt: skip
  ks = range(2, args.group)  # fewer than the whole group
  rows = []
  for g, (group, recs, winds, wd, jobs) in enumerate(plan):
    done = results[g * args.group : (g + 1) * args.group]
    try:
      out = joint_lib.combine_joint(jobs, done, wd, fans)
    except ValueError as e:  # a search failed: the others still count
      print(f'group {g}: left out ({e})')
      continue
    first = {k: _first_k_medians(jobs, k, space) for k in ks}
    if fans:  # the same searches with a wind each (no fan shared)
      apart = _first_k_medians(jobs, args.group, space, out['shared_bias'])
    for k, rec in enumerate(recs):
      row = _row(group, k, rec, winds, out, guess)
      t = row['truth']
      for j in ks:  # the group's first j recordings, jointly
        if k < j:
          row[f'first_{j}'] = {n: _error(first[j][k][n], t[n]) for n in NAMES}
      if fans:
        row['fans_apart'] = {n: _error(apart[k][n], t[n]) for n in NAMES}
        row['hem_mass'] = out['recordings'][k].get('hem_mass', 0.0)
      rows.append(row)
  if not rows:
    raise ValueError('every group failed')
  return rows


def _labels(args: Args) -> dict:
  """The table's rows: each estimate's key in a row, and its label."""
  labels = {'alone': 'one recording and its reading'}
  labels.update(
    {
      f'first_{j}': f'the first {j}, jointly (posterior median)'
      for j in range(2, args.group)
    }
  )
  if args.hem_mass:
    labels['fans_apart'] = 'the pair, a wind each (posterior median)'
  labels.update({
    'joint_median': f'all {args.group}, jointly (posterior median)',
    'joint': f'all {args.group}, jointly (reported point)',
    'centre': 'range centre',
  })  # fmt: skip
  return labels


def _summary(rows: list[dict], labels: dict) -> dict:
  """Mean errors per estimate, the joint's coverage, narrowing and bias."""
  summary = {}
  for who in labels:
    have = [r[who] for r in rows if who in r]
    summary[who] = {n: float(np.mean([h[n] for h in have])) for n in NAMES}
    summary[who]['n'] = len(have)
  summary['joint_covered_90'] = {
    n: float(np.mean([r['joint_covered_90'][n] for r in rows])) for n in NAMES
  }
  summary['narrowing_90'] = {
    who: {
      n: float(np.mean([r['narrowing_90'][who][n] for r in rows])) for n in NAMES[:2]
    }
    for who in ('alone', 'joint')
  }
  # bias: the mean signed log error of the group's point, percent
  summary['joint_bias'] = {
    n: float(100 * np.mean([np.log(r['joint_point'][n] / r['truth'][n]) for r in rows]))
    for n in NAMES
  }
  return summary


def _print(args: Args, config, rows, groups, labels: dict, summary: dict) -> None:
  print(f'{len(rows)} recordings in {len(groups)} groups of {args.group}, '
        f'{args.material}, distance {config.scoring.distance}, '
        + (f'readings with {100 * args.reading_sd:g}% error' if args.reading_sd
           else 'no readings')
        + (f'; each pair one fan setting, the second with {1000 * args.hem_mass:g} g '
           'at its hem' if args.hem_mass else '')
        + '; mean errors')  # fmt: skip
  print('| estimate | recordings | wind | area weight | load ratio |')
  print('|---|---:|---|---|---|')
  for who, label in labels.items():
    s = summary[who]
    print(f'| {label} | {s["n"]} | '
          + ' | '.join(f'{s[n]:.1f}%' for n in NAMES) + ' |')  # fmt: skip
  nar = summary['narrowing_90']
  print("90% intervals' narrowing (prior width over posterior width), one recording / "
        'the group: ' + ', '.join(f"{n} x{nar['alone'][n]:.2f} / x{nar['joint'][n]:.2f}"
                                  for n in NAMES[:2]))  # fmt: skip
  print('joint points, mean signed log error (bias): '
        + ', '.join(f"{n} {summary['joint_bias'][n]:+.1f}%" for n in NAMES))  # fmt: skip
  cov = summary['joint_covered_90']
  print('joint 90% intervals held the truth: '
        + ', '.join(f'{n} {100 * cov[n]:.0f}%' for n in NAMES))  # fmt: skip


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax logs every restore at INFO
  config = _config(args)
  net = embedding.for_distance(args.model, config.scoring.distance, args.image_size)
  space = physsim.search_space(args.material)
  groups = _recordings(args, args.workdir, net.image_size[0])
  if not groups:
    raise ValueError('no group of recordings was kept')
  plan = _plan(args, config, net, groups)
  # Every group's searches in lockstep: one simulation batch for all.
  results = estimation.estimate_many([j for *_, jobs in plan for j in jobs])
  rows = _rows(args, plan, results, space)
  labels = _labels(args)
  summary = _summary(rows, labels)
  _print(args, config, rows, groups, labels, summary)
  files.write_json(
    os.path.join(args.workdir, 'joint_pairs.json'),
    {
      'rows': rows,
      'summary': summary,
      'flags': {
        k: _preset(args) if k == 'preset' else _json(getattr(args, k))
        for k in FLAG_NAMES
      },
    },
  )


def _json(value):
  """A setting as the JSON records it (a list flag as a list)."""
  return list(value) if isinstance(value, tuple) else value


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
