"""How wide a joint estimate's area weight must stay when its recordings share
the simulator's error: fitted on one set of groups, checked on another.

``benchmarks.joint_pairs --physics=mismatched`` estimates groups of three
gentle fan settings, each with a 2% anemometer reading, recorded under
another physics (``physsim.mismatch.WORLD``); its joint posterior multiplies
the recordings' evidence as if their errors were independent, and where the
simulator differs from the world the same way in every recording, the joint
area weight narrows onto a shifted value. This script re-reads those groups'
saved likelihoods (each recording's log likelihood and log prior on the
posterior grid, packed from a ``joint_pairs`` workdir by ``--pack``, small
enough to bring back from a GPU machine) and recombines each group with
a shared discrepancy of sd ``s`` in log area weight
(``posterior.joint(shared_bias_sd=s)``) for each ``s`` of ``--sds``; the first
``--calibrate`` runs choose the smallest ``s`` whose raw 90% intervals hold
the area weight in at least 90% of their groups, and the others check it.

  python -m benchmarks.shared_bias --pack=/tmp/jmm --out=$OUT/jmm7_fields.npz
  python -m benchmarks.shared_bias \
      --runs=out/jmm/joint_pairs.json,out/jmm/joint_pairs8.json \
      --fields=out/jmm/jmm7_fields.npz,out/jmm/jmm8_fields.npz --calibrate=1 \
      --out=$OUT/shared_bias.json
"""

from __future__ import annotations

import dataclasses
import glob
import json
import math
import os

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, files
from experiments.pipeline import posterior as posterior_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """The runs and the sds tried.

  Attributes:
    runs: ``joint_pairs.json`` files (comma-separated).
    fields: each run's packed likelihoods (``.npz``), in the same order.
    calibrate: how many of the first runs choose the sd (the rest check it).
    sds: shared discrepancies tried, sd of log area weight.
    draws: posterior draws per group.
    pack: a ``joint_pairs`` workdir: only pack its recordings' likelihoods
      into ``out`` (.npz) and stop.
    out: JSON path (with ``pack``: the .npz).
  """

  runs: tuple[str, ...] = ()
  fields: tuple[str, ...] = ()
  calibrate: int = 1
  sds: tuple[float, ...] = (0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.12, 0.15)
  draws: int = 4000
  pack: str = ''
  out: str = 'out/benchmarks/shared_bias.json'


PRESETS = {'default': Args()}


def pack(workdir: str, out: str) -> int:
  """Writes each recording's log likelihood and log prior (float32) of a
  ``joint_pairs`` workdir (``pair_<g>/recording_<k>/posterior.npz``, recording
  seq = g x group + k) to ``out``; returns how many."""
  with open(os.path.join(workdir, 'joint_pairs.json')) as f:
    size = int(json.load(f)['flags']['group'])
  seqs, ll, lp, grid = [], [], [], None
  for path in sorted(
    glob.glob(os.path.join(workdir, 'pair_*', 'recording_*', 'posterior.npz'))
  ):
    g = int(path.split('pair_')[1].split(os.sep)[0])
    k = int(path.split('recording_')[1].split(os.sep)[0])
    with np.load(path) as z:
      seqs.append(g * size + k)
      ll.append(z['log_lik'].astype(np.float32))
      lp.append(z['log_prior'].astype(np.float32))
      grid = z['grid']
  if not seqs:
    raise ValueError(f'--pack={workdir}: no pair_*/recording_*/posterior.npz there')
  files.write_atomic(out, lambda p: np.savez_compressed(
    p, seq=np.array(seqs), log_lik=np.stack(ll), log_prior=np.stack(lp), grid=grid
  ))  # fmt: skip
  return len(seqs)


def groups_of(run_path: str, fields_path: str) -> list[dict]:
  """Each group's recordings: their truths, log likelihoods and priors."""
  with open(run_path) as f:
    run = json.load(f)
  size = int(run['flags']['group'])
  material = run['flags']['material']
  with np.load(fields_path) as z:
    by_seq = {
      int(s): (z['log_lik'][i], z['log_prior'][i]) for i, s in enumerate(z['seq'])
    }
    grid = tuple(int(g) for g in z['grid'])
  out = {}
  for r in run['rows']:
    g = int(r['seq']) // size
    out.setdefault(g, []).append(r)
  groups = []
  for g, rows in sorted(out.items()):
    rows = sorted(rows, key=lambda r: r['seq'])
    if len(rows) != size or any(r['seq'] not in by_seq for r in rows):
      continue
    groups.append({
      'group': g, 'material': material, 'grid': grid,
      'area_weight': rows[0]['truth']['area_weight'],
      'log_liks': [by_seq[r['seq']][0] for r in rows],
      'log_priors': [by_seq[r['seq']][1] for r in rows],
    })  # fmt: skip
  return groups


def area_weight(group: dict, sd: float, draws: int, seed: int) -> dict:
  """The group's joint area weight at shared discrepancy ``sd``."""
  space = physsim.search_space(group['material'])
  j = posterior_lib.joint(
    group['log_liks'], group['grid'], group['log_priors'],
    jax.random.key(seed), n=draws, shared_bias_sd=sd,
    area_weight_range=space.area_weight,
  )  # fmt: skip
  w = posterior_lib.physical(j['samples'][0], space)[:, 2]
  t = group['area_weight']
  q = np.quantile(w, [0.05, 0.25, 0.5, 0.75, 0.95])
  return {
    'median': float(q[2]), 'error_pct': float(100 * abs(q[2] / t - 1)),
    'held_90': bool(q[0] <= t <= q[4]), 'held_50': bool(q[1] <= t <= q[3]),
    'width_90_pct': float(100 * (q[4] - q[0]) / q[2]),
  }  # fmt: skip


def summarise(rows: list[dict]) -> dict:
  return {
    'groups': len(rows),
    'error_pct': float(np.mean([r['error_pct'] for r in rows])),
    'held_90': float(np.mean([r['held_90'] for r in rows])),
    'held_50': float(np.mean([r['held_50'] for r in rows])),
    'width_90_pct': float(np.median([r['width_90_pct'] for r in rows])),
  }


def main(args: Args) -> None:
  if args.pack:
    print(f'packed {pack(args.pack, args.out)} recordings into {args.out}')
    return
  if not args.runs or len(args.runs) != len(args.fields):
    raise ValueError(
      '--runs and --fields: one packed fields file per run, at least one'
    )
  if not 0 < args.calibrate <= len(args.runs):
    raise ValueError(f'--calibrate={args.calibrate}: between 1 and {len(args.runs)}')
  for s in args.sds:
    if not (math.isfinite(s) and s >= 0):
      raise ValueError(f'--sds: {s} is not a finite sd >= 0')
  runs = [groups_of(r, f) for r, f in zip(args.runs, args.fields, strict=True)]
  table = {}
  for sd in args.sds:
    per = [
      [area_weight(g, sd, args.draws, seed=1000 * k + g['group']) for g in groups]
      for k, groups in enumerate(runs)
    ]
    cal = [r for rows in per[: args.calibrate] for r in rows]
    chk = [r for rows in per[args.calibrate :] for r in rows]
    table[sd] = {
      'calibration': summarise(cal), **({'check': summarise(chk)} if chk else {}),
      'runs': per,
    }  # fmt: skip
    line = f'sd {sd:.2f}: calibration {_row(table[sd]["calibration"])}'
    if chk:
      line += f'; check {_row(table[sd]["check"])}'
    print(line, flush=True)
  chosen = next(
    (sd for sd in args.sds if table[sd]['calibration']['held_90'] >= 0.9), None
  )
  print(f'chosen: {chosen} (the smallest whose 90% intervals held >= 90% of the '
        'calibration groups)')  # fmt: skip
  files.write_json(args.out, {
    'args': dataclasses.asdict(args), 'chosen': chosen,
    'table': {str(k): v for k, v in table.items()},
  })  # fmt: skip


def _row(s: dict) -> str:
  return (
    f'{s["groups"]} groups, area weight {s["error_pct"]:.1f}%, 90% held '
    f'{100 * s["held_90"]:.0f}%, 50% {100 * s["held_50"]:.0f}%, 90% width '
    f'{s["width_90_pct"]:.1f}%'
  )


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
