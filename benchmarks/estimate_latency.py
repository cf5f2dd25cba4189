"""One recording's estimate alone: its time after compile, for a few
settings, or beside the same recording estimated in a lockstep.

Each setting runs the same estimate 1 + ``--repeats`` times in one process: the
first pays the compiles (MJX, renderer, network, GP buffers), the others are
timed (the table shows their median run; all are in the JSON). Searches are
not bitwise repeatable on a GPU, so runs of one setting may differ in length.
Prints a table and writes JSON.

  python -m benchmarks.estimate_latency --recording=/tmp/eval/fabrics/gray_interlock/0000 \
      --material=gray_interlock --model=/tmp/t1/physnet_depth/simulation/gray_interlock \
      --out=out/estimate_latency.json
  python -m benchmarks.estimate_latency --preset=shape \
      --recording=/tmp/eval/fabrics/gray_interlock/0000   # no network

``--against=WORKDIR``: a calibration study (``experiments.calibrate``)
estimates its recordings in one lockstep (``estimation.estimate_many``: one
device program per step for all); each of ``--seqs`` is estimated again alone
in this process, with the settings and seed its estimate ran with (its
``estimate.json``), and the table gives per quantity the median and 90%
interval of each, and each single estimate's time (the first includes the
compile). ``--image_size`` must be the one the study read its recordings at
(``calibration.image_size``: 256 at the paper's size, 32 at the demo's):

  python -m benchmarks.estimate_latency --against=/tmp/cal_paper \
      --seqs=0000,0010 --out=$OUT/single_vs_batched.json
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import time

from absl import logging

import physsim
from experiments.pipeline import cli, embedding, estimation, evaluation, files, layout
from experiments.pipeline import objective as objective_lib
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import recording as recording_lib

# name -> (objective.PRESETS name, EstimateConfig overrides, estimate()
# keywords); names without commas, as --settings is a list.
SETTINGS = {
  # the estimate's default: the shape distance, no network, frames at --image_size
  'default': ('default', {}, {}),
  'gp_on_gpu': ('default', {}, dict(gp_on_cpu=False)),  # GP on JAX's default device
  'q16': ('default', dict(q=16, n_init=32), {}),
  # the default's budget before 2026-11-29: 48 + 3 x 24 simulations, four steps
  'q24': ('default', dict(q=24, n_init=48, max_iter=3), {}),
  'smoke': ('smoke', {}, {}),  # a CPU-sized search (checks the script)
  # through the trained network (--model): the PSD between embeddings
  'psd': ('default', dict(distance=objective_lib.NETWORK_DISTANCE), {}),
  'psd_smoke': ('smoke', dict(distance=objective_lib.NETWORK_DISTANCE), {}),
  # the paper's argmin (PSD; q=4, n_init=8, <= 30 iterations)
  'paper': ('paper', {}, {}),
  # the shape distance named (the default's; older commands)
  'shape': ('default', dict(distance='shape'), {}),
  'shape_smoke': ('smoke', dict(distance='shape'), {}),
}


@dataclasses.dataclass(frozen=True)
class Args:
  """The estimate-latency benchmark.

  Attributes:
    recording: a dataset sequence folder (required without --against).
    material: its fabric.
    model: its trained network (required for a setting that embeds: psd,
      psd_smoke, paper; the shape distance reads the frames without one).
    image_size: pixels a side the shape distance reads the frames at.
    out: JSON result.
    settings: which settings (``SETTINGS``).
    backend: simulator (physsim.rollout).
    repeats: timed runs after the compile run (the table shows their median;
      a timed run can still compile shapes the first run's search did not
      reach).
    against: a calibration study's workdir with finished estimates: estimate
      --seqs of them alone, beside their lockstep estimates.
    seqs: with --against, the recordings (their estimates' folder names).
  """

  recording: str = ''
  material: str = 'gray_interlock'
  model: str = ''
  image_size: int = 256
  out: str = 'out/benchmarks/estimate_latency.json'
  settings: tuple[str, ...] = ('default', 'q24', 'gp_on_gpu')
  backend: str = cli.choice('auto', physsim.BACKENDS)
  repeats: int = 1
  against: str = ''
  seqs: tuple[str, ...] = ('0000', '0010')


PRESETS = {
  'default': Args(),
  'paper': Args(settings=('paper',)),
  'smoke': Args(settings=('smoke',), backend='c'),
  'shape': Args(settings=('shape',)),
}


def _summary(result: dict) -> dict:
  return {
    f: [result['estimate'][f]['median'], *result['estimate'][f]['interval_90']]
    for f in posterior_lib.FIELDS
  }


def against_lockstep(args: Args) -> None:
  """Each of ``args.seqs`` of the study ``args.against`` estimated alone,
  beside its estimate in the study's lockstep; a table and JSON (a list)."""
  evaluator = evaluation.Evaluator()
  rows = []
  for seq in args.seqs:
    batched = recording_lib.read_json(
      os.path.join(args.against, 'estimates', seq, layout.ESTIMATE_FILE)
    )
    est = objective_lib.EstimateConfig.from_flat(batched['config'])
    recording = recording_lib.load_recording(
      batched['recording'], fps=est.simulation.fps,
      size=(args.image_size, args.image_size), frames=est.simulation.frames,
    )  # fmt: skip
    t0 = time.perf_counter()
    alone = estimation.estimate(
      est, recording, '',
      os.path.join(args.against, 'alone', seq), progress=False, evaluator=evaluator,
    )  # fmt: skip
    rows.append({
      'seq': seq, 'material': batched['material'],
      'seconds': time.perf_counter() - t0,
      'objective_s': alone.get('seconds_in_objective'),
      'search_s': alone.get('seconds_in_search'),
      'alone': _summary(alone), 'batched': _summary(batched),
      'recordings_in_batch': batched.get('recordings_in_batch'),
    })  # fmt: skip
  files.write_json(args.out, rows)
  print('| recording | quantity | alone: median [90%] | in the batch | seconds alone |')
  print('|---|---|---|---|---|')
  for r in rows:
    for f in posterior_lib.FIELDS:
      a, b = r['alone'][f], r['batched'][f]
      print(f'| {r["seq"]} {r["material"]} | {f} | {a[0]:.3g} [{a[1]:.3g}, {a[2]:.3g}] '
            f'| {b[0]:.3g} [{b[1]:.3g}, {b[2]:.3g}] | {r["seconds"]:.1f} |')  # fmt: skip
  print(json.dumps({'out': args.out}))


def _setting_row(args: Args, name: str) -> dict:
  """One setting's runs: the first compiles, the median of the rest."""
  preset, overrides, kwargs = SETTINGS[name]
  config = objective_lib.PRESETS[preset].replace(
    material=args.material, backend=args.backend,
    **overrides,
  )  # fmt: skip
  shape = config.scoring.distance == 'shape'
  if not shape and not args.model:
    raise ValueError(f'--settings={name} embeds frames: it needs --model')
  model = '' if shape else args.model
  net = (
    None if shape else embedding.load_embedding(model)
  )  # the shape distance reads the frames at --image_size
  rec = recording_lib.load_recording(
    args.recording, fps=config.simulation.fps,
    size=(args.image_size,) * 2 if shape else net.image_size,
    frames=config.simulation.frames,
    rgb=net is not None and net.modality == 'rgb',
  )  # fmt: skip
  runs = []
  evaluator = evaluation.Evaluator()  # one compile per setting, reused by its runs
  for _ in range(1 + args.repeats):  # the first run compiles
    with tempfile.TemporaryDirectory() as tmp:
      t0 = time.perf_counter()
      r = estimation.estimate(
        config, rec, model, tmp, progress=False, evaluator=evaluator,
        **kwargs,
      )  # fmt: skip
      runs.append({
        'seconds': time.perf_counter() - t0,
        'objective_s': r['seconds_in_objective'],
        'search_s': r.get('seconds_in_search', float('nan')),
        'evaluations': r['evaluations'],
        'iterations': r['iterations'],
        'errors': r.get('errors', {}).get('estimate'),
      })  # fmt: skip
  timed = sorted(runs[1:], key=lambda x: x['seconds'])
  median = timed[(len(timed) - 1) // 2]  # a run that happened (lower median)
  return {
    'setting': name,
    'overrides': {**overrides, **kwargs},
    'first_s': runs[0]['seconds'],
    'after_compile_s': median['seconds'],
    'objective_s': median['objective_s'],
    'search_s': median['search_s'],
    'evaluations': median['evaluations'],
    'iterations': median['iterations'],
    'errors': median['errors'],
    'timed_runs': runs[1:],
  }


def _print(rows: list[dict]) -> None:
  base = rows[0]['after_compile_s']
  print(
    f'| setting | first run s | after compile s | vs {rows[0]["setting"]} | '
    'in the fused objective s | outside it s (share) | of which search s | '
    'the rest (results, figures) s | evals | iterations |'
  )
  print('|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    t = r['after_compile_s']
    out = t - r['objective_s']
    print(
      f'| {r["setting"]} | {r["first_s"]:.1f} | {t:.1f} | {t / base:.2f}x | '
      f'{r["objective_s"]:.1f} | {out:.1f} ({100 * out / t:.0f}%) | '
      f'{r["search_s"]:.1f} | {out - r["search_s"]:.1f} | {r["evaluations"]} | '
      f'{r["iterations"]} |'
    )


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax logs every checkpoint at INFO
  if args.against:
    return against_lockstep(args)
  if not args.recording:
    raise ValueError('missing --recording (or --against=a calibration workdir)')
  unknown = sorted(set(args.settings) - set(SETTINGS))
  if unknown or not args.settings:
    raise ValueError(f'unknown --settings {unknown}; known: {list(SETTINGS)}')
  rows = []
  for name in args.settings:
    rows.append(_setting_row(args, name))
    print(json.dumps(rows[-1]), flush=True)
  _print(rows)
  files.write_json(
    args.out,
    {'recording': args.recording, 'backend': args.backend, 'rows': rows},
  )  # fmt: skip
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
