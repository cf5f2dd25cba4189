"""Study: which epoch to ship, by triplet accuracy or by parameter retrieval?

Table 1's metric (triplet accuracy) picked epoch-1 networks whose estimates of
bending were worse (README, second paper-size run). ``model.retrieval`` scores
an epoch by what the estimate needs instead: do PSD-near simulations have near
parameters? This script checks, on the demo's small setting (a CPU is enough),
whether that choice gives better estimates:

1. the demo's training set; one PhySNet trained for ``--epochs`` with a quarter
   of the training simulations held out for validation, every epoch kept, each
   evaluated (validation triplet accuracy, validation and test retrieval);
2. the epochs each criterion picks on the validation simulations, and the
   last epoch;
3. ``--recordings`` real-like recordings (the demo's recording settings:
   finer mesh, sensor noise, 24 fps, an unseen camera, gusts), each estimated
   with each picked epoch (``experiments.estimate``, the demo's settings).

Prints a table and writes ``<workdir>/selection_study.json``. Everything
resumes from ``--workdir``.

  python -m benchmarks.selection_study --workdir=out/selection \
      --sequences=32 --epochs=10 --recordings=4
"""

import dataclasses
import json
import os
import shutil
import time

import numpy as np
from absl import logging

import model as model_lib
import physsim
from experiments.pipeline import cli, demo, embedding, files, search
from experiments.pipeline import datasets as gen
from experiments.pipeline import recording as recording_lib
from experiments.pipeline import training as train_lib
from experiments.pipeline.objective import NETWORK_DISTANCE
from model import checkpoint


@dataclasses.dataclass(frozen=True)
class Args:
  """The epoch-selection study, on the demo's settings (experiments/demo.py).

  Attributes:
    workdir: data and runs go here.
    material: the fabric.
    sequences: training simulations.
    backend: 'auto': MuJoCo Warp on a GPU, else C.
    epochs: epochs (every one is kept).
    recordings: real-like recordings.
    all_epochs: estimate with every epoch (else only the picked ones).
  """

  workdir: str = 'out/demo'
  material: str = 'gray_interlock'
  sequences: int = 24
  backend: str = cli.choice('auto', physsim.BACKENDS)
  epochs: int = 10
  recordings: int = 4
  all_epochs: bool = True


PRESETS = {
  'default': Args(),
  # checks the script on a CPU: a short training, one recording, the picked epochs
  'smoke': Args(
    workdir='out/selection_smoke',
    sequences=12,
    epochs=2,
    recordings=1,
    all_epochs=False,
  ),
}


def train_all_epochs(workdir: str, material: str, sequences: int, epochs: int, backend):
  """Trains the demo's network with validation, keeping every epoch; returns
  (run folder, eval rows)."""
  data_cfg, _, train_cfg, _ = demo.configs(material, sequences, 0, backend)
  root = os.path.join(workdir, 'data')
  gen.run(data_cfg, root)
  cfg = train_lib.replace(
    train_cfg, epochs=epochs, val_fraction=0.25, materials=(material,)
  )
  run_dir = os.path.join(workdir, 'model')
  data = train_lib.load_inputs(cfg, root, [material])
  train_lib.fit_run(cfg, root, run_dir, [material], data, max_to_keep=None)
  return run_dir, model_lib.read_evals(run_dir)


def export_epoch(run_dir: str, row: dict, out: str) -> str:
  """A run folder whose shipped params are the ``row`` epoch's (what the estimate loads)."""
  if os.path.isdir(os.path.join(out, model_lib.train.BEST_DIR)):
    return out
  _, params, _ = model_lib.load_network(run_dir, step=row['step'])
  os.makedirs(out, exist_ok=True)
  for f in (model_lib.train.CONFIG_FILE, embedding.INPUTS_FILE):
    shutil.copy(os.path.join(run_dir, f), os.path.join(out, f))
  with checkpoint.manager(out, 1, model_lib.train.BEST_DIR) as mngr:
    checkpoint.save(mngr, row['step'], params)
  return out


def picks(evals: list[dict]) -> dict[str, dict]:
  """``{criterion: eval row}``: the first epoch of the best validation score, and the last."""
  return {
    'triplet': max(evals, key=lambda r: r['val_triplet_accuracy']),
    'retrieval': min(evals, key=lambda r: r['val_retrieval']['error']),
    'last': evals[-1],
  }


def estimate_score(results: list[dict], who: str = 'estimate') -> dict:
  """Mean ``|log(value / truth)|`` per parameter over recordings, and their
  mean relative to the range centre's (1 = no better than the centre guess)."""
  out = {}
  for name in physsim.Params._fields:
    out[name] = float(
      np.mean([abs(np.log(r[who][name] / r['truth'][name])) for r in results])
    )
  centre = {
    n: float(
      np.mean([abs(np.log(r['range_centre'][n] / r['truth'][n])) for r in results])
    )
    for n in physsim.Params._fields
  }
  out['vs_centre'] = float(
    np.mean([out[n] / centre[n] for n in physsim.Params._fields])
  )
  return out


def spearman(a, b) -> float:
  """Rank correlation of two equal-length sequences (ties broken by order)."""
  ra, rb = (np.argsort(np.argsort(np.asarray(x, np.float64))) for x in (a, b))
  return float(np.corrcoef(ra, rb)[0, 1])


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  wd, material, sequences = args.workdir, args.material, args.sequences
  t0 = time.time()
  run_dir, evals = train_all_epochs(wd, material, sequences, args.epochs, args.backend)
  chosen = picks(evals)
  _, rec_cfg, _, est_cfg = demo.configs(material, sequences, 0, args.backend)
  # the network's PSD, not the estimate's default (the shape)
  est_cfg = est_cfg.replace(distance=NETWORK_DISTANCE)
  space = physsim.search_space(material)
  centre = dict(zip(physsim.Params._fields, map(float, space.center()), strict=True))
  rec_root = os.path.join(wd, 'recordings')
  n_rec = args.recordings
  gen.run(dataclasses.replace(rec_cfg, sequences=n_rec, batch_size=n_rec), rec_root)
  recordings, skipped = {}, {}
  for i in range(n_rec):
    rec_dir = physsim.dataset.sequence_dir(rec_root, material, f'{i:04d}')
    try:
      recordings[i] = recording_lib.load_recording(
        rec_dir,
        fps=est_cfg.simulation.fps,
        size=(demo._RES, demo._RES),
        frames=demo._FRAMES,
      )
    except ValueError as e:  # e.g. an unseen camera pose that never sees the cloth
      skipped[i] = str(e)
      print(f'recording {i} skipped: {e}')
  results = {}
  epochs = [r['epoch'] for r in (evals if args.all_epochs else chosen.values())]
  for epoch in sorted(set(epochs)):
    row = next(r for r in evals if r['epoch'] == epoch)
    model_dir = export_epoch(run_dir, row, os.path.join(wd, 'epochs', str(epoch)))
    for i, rec in recordings.items():
      out = os.path.join(wd, 'estimates', f'epoch{epoch}', f'{i:04d}')
      res = search.estimate(
        est_cfg.replace(seed=i), rec, model_dir, out, progress=False
      )
      value = {k: float(np.ravel(v['value'])[0]) for k, v in res['estimate'].items()}
      results.setdefault(epoch, []).append(
        {'estimate': value, 'truth': res['truth'], 'range_centre': centre}
      )
      print(f'epoch {epoch}, recording {i}: {json.dumps(res["errors"]["estimate"])}')

  per_epoch = []
  for r in evals:
    if r['epoch'] not in results:
      continue
    per_epoch.append({
      'epoch': r['epoch'],
      'val_triplet_accuracy': r['val_triplet_accuracy'],
      'val_retrieval': r['val_retrieval'],
      'test_triplet_accuracy': r.get('test_triplet_accuracy'),
      'test_retrieval': r.get('test_retrieval', {}),
      'estimate': estimate_score(results[r['epoch']]),
    })  # fmt: skip
  centre_score = estimate_score(next(iter(results.values())), 'range_centre')
  print(
    f'\n{material}, {sequences} simulations, {len(recordings)} real-like recordings, '
    f'{time.time() - t0:.0f} s. Errors are mean |log(value / truth)|; "vs centre" '
    'and retrieval "error" are means over the parameters relative to the range '
    'centre / a random reference (1 = no better).\n'
  )
  names = physsim.Params._fields
  print(
    '| epoch | picked by | val triplet acc | val retrieval | test retrieval | '
    + ' | '.join(f'estimate {n}' for n in names)
    + ' | estimate vs centre |'
  )
  print('|---:|---|---:|---:|---:|' + '---:|' * (len(names) + 1))
  for r in per_epoch:
    by = ', '.join(k for k, v in chosen.items() if v['epoch'] == r['epoch'])
    e = r['estimate']
    print(
      f'| {r["epoch"]} | {by} | {r["val_triplet_accuracy"]:.3f} | '
      f'{r["val_retrieval"]["error"]:.3f} | {r["test_retrieval"].get("error", np.nan):.3f} | '
      + ' | '.join(f'{e[n]:.3f}' for n in names)
      + f' | {e["vs_centre"]:.3f} |'
    )
  print(
    '| range centre | | | | | '
    + ' | '.join(f'{centre_score[n]:.3f}' for n in names)
    + ' | 1.000 |'
  )
  correlations = {}
  if len(per_epoch) >= 3:
    target = [r['estimate']['vs_centre'] for r in per_epoch]
    for key, get in (
      ('val_triplet_accuracy', lambda r: -r['val_triplet_accuracy']),
      ('val_retrieval', lambda r: r['val_retrieval']['error']),
      ('test_triplet_accuracy', lambda r: -(r['test_triplet_accuracy'] or 0.0)),
      ('test_retrieval', lambda r: r['test_retrieval'].get('error', np.nan)),
    ):
      correlations[key] = spearman([get(r) for r in per_epoch], target)
    print(
      '\nRank correlation across epochs with the estimate error (vs centre); '
      'positive = the criterion (accuracy negated) tracks the estimate error:'
    )
    for k, v in correlations.items():
      print(f'  {k}: {v:+.2f}')
  out = {
    'material': material,
    'sequences': sequences,
    'recordings': sorted(recordings),
    'skipped_recordings': skipped,
    'evals': evals,
    'per_epoch': per_epoch,
    'picks': {k: v['epoch'] for k, v in chosen.items()},
    'range_centre': centre_score,
    'correlations': correlations,
    'per_recording': {str(k): v for k, v in results.items()},
    'seconds': time.time() - t0,
  }
  path = os.path.join(wd, 'selection_study.json')
  files.write_json(path, out)
  print(f'\nwrote {path}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
