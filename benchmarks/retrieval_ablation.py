"""Ablation: which embedding carries which parameter? Parameter retrieval, no estimates.

Parameter retrieval (``model.retrieval``) costs one embedding pass, so it can
compare embeddings that would take hours of estimates to compare. This trains
the demo's PhySNet on the demo's training set (CPU-sized) in several variants
(embedding size, depth input mode) and seeds, ships each run's epoch by
validation triplet accuracy (as Table 1 does), and reports how well the held-out
simulations' parameters are retrieved, each against a random reference
(1 = chance, 0 = exact). Prints a table and writes
``<workdir>/retrieval_ablation.json``; finished runs are reused.

  python -m benchmarks.retrieval_ablation --workdir=out/selection \\
      --sequences=32 --seeds=0,1,2
  # the paper's cloth, cameras and 3 s clips (one fabric, 64x64, MuJoCo C):
  python -m experiments.generate_dataset --preset=paper --materials=gray_interlock \\
      --resolution=64 --backend=c --out=out/paper64/data
  python -m benchmarks.retrieval_ablation --workdir=out/paper64 \\
      --dataset=out/paper64/data --image_size=64
"""

import dataclasses
import json
import os
import time

import numpy as np
from absl import logging

import model as model_lib
import physsim
from experiments.pipeline import cli, demo, files
from experiments.pipeline import datasets as gen
from experiments.pipeline import training as train_lib
from physsim import params as params_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """The retrieval ablation, on the demo's settings (experiments/demo.py).

  Attributes:
    workdir: data and runs go here.
    material: the fabric.
    sequences: training simulations.
    backend: 'auto': MuJoCo Warp on a GPU, else C.
    epochs: epochs per run.
    seeds: training seeds per variant.
    dataset: an existing dataset (default: the demo's, made under --workdir).
    image_size: input size (0: the demo's).
    only: run only the variants whose names start with one of these (e.g.
      paper,raw).
  """

  workdir: str = 'out/demo'
  material: str = 'gray_interlock'
  sequences: int = 24
  backend: str = cli.choice('auto', physsim.BACKENDS)
  epochs: int = 10
  seeds: tuple[int, ...] = (0, 1, 2)
  dataset: str = ''
  image_size: int = 0
  only: tuple[str, ...] = ()


PRESETS = {
  'default': Args(),
  # checks the script on a CPU: one variant and the raw pixels, one seed
  'smoke': Args(
    workdir='out/retrieval_smoke',
    sequences=12,
    epochs=2,
    seeds=(0,),
    only=('paper', 'raw pixels, relative'),
  ),
}
VARIANTS = {
  'paper (2-D, relative depth)': {},
  '8-D embedding': {'embed_dim': 8},
  '32-D embedding': {'embed_dim': 32},
  '2-D, metric depth': {'input_mode': 'metric'},
  '8-D, metric depth': {'embed_dim': 8, 'input_mode': 'metric'},
}
# No network: each frame's input pixels are its embedding. If even these do not
# retrieve a parameter, the videos do not show it (at this size), whatever is trained.
RAW = {
  'raw pixels, relative depth (no network)': 'relative',
  'raw pixels, metric depth (no network)': 'metric',
}


def raw_retrieval(cfg, root: str, material: str, data) -> dict:
  """``model.retrieval.score`` of the held-out simulations with the inputs'
  pixels as embeddings, on the split (and training part) a run of ``cfg`` uses."""
  x, y, g = data
  tc = train_lib.train_config(cfg, x.shape[-3:-1])
  train_idx, test_idx = model_lib.split_indices(tc, y, g)
  fit_idx, _ = model_lib.validation_split(tc, y, g, train_idx)
  videos = model_lib.retrieval.check_videos(
    train_lib.video_info(cfg, root, [material]), len(x)
  )
  emb = np.asarray(x, np.float32).reshape(len(x), -1)
  return model_lib.retrieval.score(emb, videos, test_idx, fit_idx)


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  wd, material, sequences = args.workdir, args.material, args.sequences
  t0 = time.time()
  data_cfg, _, train_cfg, _ = demo.configs(material, sequences, 0, args.backend)
  root = args.dataset or os.path.join(wd, 'data')
  if not args.dataset:
    gen.run(data_cfg, root)
  base = train_lib.replace(
    train_cfg, epochs=args.epochs, val_fraction=0.25, materials=(material,)
  )
  if args.image_size:
    base = dataclasses.replace(base, image_size=args.image_size)
  names = params_lib.FIELDS

  def chosen(variant: str) -> bool:
    return not args.only or any(variant.startswith(p) for p in args.only)

  rows, inputs = [], {}
  for variant, over in VARIANTS.items():
    if not chosen(variant):
      continue
    for seed in args.seeds:
      cfg = train_lib.replace(base, seed=seed, **over)
      mode = cfg.input_mode
      if mode not in inputs:
        inputs[mode] = train_lib.load_inputs(cfg, root, [material])
      run_dir = os.path.join(wd, 'ablation', f'{variant}-seed{seed}')
      _, row = train_lib.fit_run(
        cfg, root, run_dir, [material], inputs[mode], progress=False
      )
      r = row['test_retrieval']
      rows.append({
        'variant': variant,
        'seed': seed,
        'epoch': row['epoch'],
        'test_triplet_accuracy': row['test_triplet_accuracy'],
        'retrieval_error': r['error'],
        **{f'{n}_vs_chance': v for n, v in model_lib.retrieval.vs_chance(r).items()},
      })  # fmt: skip
      print(json.dumps(rows[-1]), flush=True)
  for variant, mode in RAW.items():
    if not chosen(variant):
      continue
    for seed in args.seeds:
      cfg = train_lib.replace(base, seed=seed, input_mode=mode)
      if mode not in inputs:
        inputs[mode] = train_lib.load_inputs(cfg, root, [material])
      r = raw_retrieval(cfg, root, material, inputs[mode])
      rows.append({
        'variant': variant,
        'seed': seed,
        'test_triplet_accuracy': float('nan'),
        'retrieval_error': r['error'],
        **{f'{n}_vs_chance': v for n, v in model_lib.retrieval.vs_chance(r).items()},
      })  # fmt: skip
      print(json.dumps(rows[-1]), flush=True)
  keys = ['test_triplet_accuracy', 'retrieval_error'] + [
    f'{n}_vs_chance' for n in names
  ]
  print(
    f'\n{material}, {root}, seeds {list(args.seeds)}, '
    f'{time.time() - t0:.0f} s; mean (min-max) over seeds at the epoch chosen by '
    'validation triplet accuracy; retrieval relative to a random reference '
    '(1 = chance)\n'
  )
  print(
    '| variant | held-out triplet acc | retrieval (all) | ' + ' | '.join(names) + ' |'
  )
  print('|---|' + '---:|' * (2 + len(names)))
  summary = {}
  for variant in filter(chosen, [*VARIANTS, *RAW]):
    vals = {k: [r[k] for r in rows if r['variant'] == variant] for k in keys}
    summary[variant] = {k: float(np.mean(v)) for k, v in vals.items()}
    cells = [f'{np.mean(v):.2f} ({min(v):.2f}-{max(v):.2f})' for v in vals.values()]
    print(f'| {variant} | ' + ' | '.join(cells) + ' |')
  out = {
    'material': material,
    'dataset': root,
    'image_size': base.image_size,
    'epochs': args.epochs,
    'variants': VARIANTS,
    'raw': RAW,
    'runs': rows,
    'mean': summary,
    'seconds': time.time() - t0,
  }
  path = os.path.join(wd, 'retrieval_ablation.json')
  files.write_json(path, out)
  print(f'\nwrote {path}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
