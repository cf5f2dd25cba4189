"""The calibration study's runs: its networks trained, its recordings made and
estimated in one lockstep (resumable, shared by processes), and the finished
estimates read back or packed for an analysis on another machine."""

from __future__ import annotations

import json
import os

import jax
import numpy as np

import physsim
from experiments.pipeline import datasets as gen
from experiments.pipeline import demo as demo_lib
from experiments.pipeline import (
  distributed,
  embedding,
  estimation,
  files,
  layout,
  search,
)
from experiments.pipeline import recording as recording_lib
from experiments.pipeline import training as train_lib
from experiments.studies.calibration_config import (
  NETWORKS_FILE,
  Config,
  camera_sd_of,
  first_seq,
  network_dirs,
  network_of,
  network_seeds,
  study_configs,
  study_materials,
  told_pose,
  truths,
  with_reading,
)

# What the analysis reads of each estimate's posterior.npz, and how many
# recordings one packed file holds.
_PACKED = ('gp_mean', 'gp_var', 'floor', 'noise_sd')
PACKED_DIR = 'packed'
_PER_PACK = 50


def recorded_networks(workdir: str) -> dict | None:
  """The ``networks_record`` a study's workdir holds (written by its searches,
  else packed with its runs: ``pack_runs``), or None (older workdirs)."""
  for path in (os.path.join(workdir, NETWORKS_FILE),
               os.path.join(workdir, PACKED_DIR, NETWORKS_FILE)):  # fmt: skip
    if os.path.isfile(path):
      return recording_lib.read_json(path)
  return None


def networks_record(config: Config, workdir: str) -> dict:
  """The study's networks: their recipe (``embedding.network_recipe``, one
  for all: only the seeds differ), seeds and held-out triplet accuracies."""
  dirs = [os.path.join(network_dirs(config, workdir, k)[1], config.material)
          for k in range(config.networks)]  # fmt: skip
  recipes = [embedding.network_recipe(d) for d in dirs]
  for d, r in zip(dirs[1:], recipes[1:], strict=True):
    if embedding.recipe_differences(r, recipes[0]):
      raise ValueError(f'{d}: made with another recipe than {dirs[0]}')
  return {
    'recipe': recipes[0],
    'seeds': list(network_seeds(config)),
    'triplet_accuracy': [embedding.network_accuracy(d) for d in dirs],
  }


def simulate_and_estimate(
  config: Config, workdir: str, point: str = 'median', reading: str = 'none'
) -> list[dict]:
  """Trains the networks, makes the recordings and estimates each (resumable),
  reporting the estimates' ``point`` (the analysis forms its own points);
  writes ``networks.json`` (``networks_record``). With a ``reading``
  ('wind_speed' or 'area_weight'), each recording is estimated with a
  simulated reading of it as its prior (the one the analysis's measured mode
  draws for that recording).

  Under several processes (``distributed``) the processes share the data's
  and the recordings' simulations, process 0 trains the networks, each process
  estimates its share of the recordings, and process 0 gathers every result
  (the others return []).

  Returns:
    Per recording: ``{'seq', 'truth', 'workdir', 'network', 'result'}``
    (``network``: its network's seed).
  """
  _, rec_cfg, _, est = study_configs(config, point)
  model_roots = _train_networks(config, workdir, point)
  rows, paths = _make_recordings(config, workdir, rec_cfg)
  # Under several processes each reads and estimates its share alone; the
  # others' rows need only their truth (meta.json), for process 0's gather.
  mine = list(range(len(rows)))
  if jax.process_count() > 1:
    mine = distributed.share(mine)
  size = (rec_cfg.resolution,) * 2 if config.size == 'paper' else demo_lib.IMAGE_SIZE
  loaded = dict(zip(mine, recording_lib.load_recordings(
    [paths[i] for i in mine], fps=est.simulation.fps, size=size,
    frames=est.simulation.frames,
  ), strict=True))  # fmt: skip
  jobs, meta = _jobs(config, workdir, est, reading, rows, paths, loaded, model_roots)
  shared = f'{len(mine)} of ' if jax.process_count() > 1 else ''
  print(f'{shared}{len(rows)} recordings in lockstep', flush=True)
  ran = estimation.estimate_many(
    [jobs[i] for i in mine], figures=False
  )  # finished: read
  results = dict(zip(mine, ran, strict=True))
  if jax.process_count() > 1:
    distributed.barrier('calibration: estimates done')
    if not distributed.is_main():
      return []
    for i, m in enumerate(meta):  # the others' estimates, from their files
      if i not in results:
        results[i] = read_estimate(m['workdir'])
  out = []
  for i, m in enumerate(meta):
    res = results[i]
    if isinstance(res, Exception):
      print(f'recording {m["seq"]}: {res}', flush=True)
      continue
    out.append({**m, 'result': res})
  return out


def _train_networks(config: Config, workdir: str, point: str) -> list[str]:
  """Simulates each network's training set (every process its share) and
  trains it (process 0); writes ``networks.json``. Returns the networks'
  training-run folders ([] for a distance that embeds nothing)."""
  model_roots = []
  for k in range(len(network_seeds(config))):
    data_cfg, _, train_cfg, _ = study_configs(config, point, k)
    data_dir, model_root = network_dirs(config, workdir, k)
    gen.run(data_cfg, data_dir)
    if distributed.is_main():
      train_lib.run(train_cfg, data_dir, model_root)
    model_roots.append(model_root)
  if distributed.is_main() and model_roots:
    files.write_json(
      os.path.join(workdir, NETWORKS_FILE), networks_record(config, workdir)
    )
  return model_roots


def _make_recordings(config: Config, workdir: str, rec_cfg) -> tuple[list, list]:
  """Simulates the study's recordings (every process its share) at its
  truths. Returns (fabric, index row) of every valid recording, by fabric
  then sequence, and each one's folder."""
  rec_root = os.path.join(workdir, 'recordings')
  mats = study_materials(config)
  gen.run(rec_cfg, rec_root, params={m: truths(config, material=m) for m in mats})
  distributed.barrier('calibration: network and recordings made')
  index = physsim.dataset.open_dataset(rec_root)
  rows = [
    (material, row)
    for material in mats
    for row in sorted(
      index.filter(material=material, valid=True).rows, key=lambda r: r['seq_id']
    )
  ]
  return rows, [index.path(r) for _, r in rows]


def _jobs(config: Config, workdir: str, est, reading: str, rows: list,
          paths: list, loaded: dict, model_roots: list) -> tuple[dict, list]:  # fmt: skip
  """The search jobs of the recordings this process ``loaded`` (by row), and
  every recording's ``{'seq', 'material', 'truth', 'workdir', 'network'}``."""
  seeds = network_seeds(config)
  jobs, meta = {}, []
  for i, (material, r) in enumerate(rows):
    seq = first_seq(config, material) + int(r['seq_id'])
    wd = os.path.join(workdir, 'estimates', f'{seq:04d}')
    k = network_of(config, seq)
    rec = loaded.get(i)
    truth = rec.truth if rec is not None else recording_truth(paths[i])
    if rec is not None:
      # '' : no network (estimation.estimate_many compares depth frames directly)
      model_dir = os.path.join(model_roots[k], material) if model_roots else ''
      m, deg = camera_sd_of(config, est, seq)  # the error it carries
      job_est = with_reading(config, est.replace(material=material, camera_sd_m=m,
                             camera_sd_deg=deg), reading, truth, seq)  # fmt: skip
      # the camera its estimate is told, off by the error it carries
      rec = rec._replace(pose=told_pose(config, job_est, rec.pose, seq))
      jobs[i] = search.Job(job_est, rec, model_dir, wd)
    meta.append({'seq': seq, 'material': material, 'truth': truth,
                 'workdir': wd, 'network': seeds[k] if seeds else None})  # fmt: skip
  return jobs, meta


def recording_truth(path: str) -> dict | None:
  """A dataset sequence's ground truth, from its ``meta.json`` alone (no frames)."""
  return recording_lib.truth_of(
    physsim.dataset.read_json(os.path.join(path, 'meta.json'))
  )


def read_estimate(workdir: str) -> dict | Exception:
  """The ``estimate.json`` another process wrote in ``workdir``, or the error
  that says it is missing (that process printed why)."""
  path = os.path.join(workdir, layout.ESTIMATE_FILE)
  if not os.path.isfile(path):
    return FileNotFoundError(f'{path}: no estimate (its process printed why)')
  return physsim.dataset.read_json(path)


def saved_gp(run: dict) -> dict:
  """A recording's saved GP (what the analysis reads of ``posterior.npz``):
  packed with the run (``packed_runs``) or read from its estimate's folder."""
  if 'saved' in run:
    return run['saved']
  with np.load(os.path.join(run['workdir'], layout.POSTERIOR_FILE)) as z:
    return {k: z[k] for k in _PACKED}


def pack_runs(runs: list[dict], workdir: str) -> list[str]:
  """Writes what the analysis reads of ``runs`` (their truths and saved GPs,
  the GPs in float32) to ``<workdir>/packed/runs-NNN.npz``, a few files of
  ``_PER_PACK`` recordings, with ``networks.json``: copy that folder to
  analyse on another machine (``--analyse_only`` reads it when the workdir
  has no estimates). Returns the files written."""
  out = []
  for i in range(0, len(runs), _PER_PACK):
    chunk = runs[i : i + _PER_PACK]
    saved = [saved_gp(r) for r in chunk]
    arrays = {
      'seq': np.array([r['seq'] for r in chunk]),
      'material': np.array([r.get('material') or '' for r in chunk]),
      'truth': np.array([json.dumps(r['truth']) for r in chunk]),
      **{k: np.stack([np.asarray(z[k], np.float32) for z in saved]) for k in _PACKED},
    }  # fmt: skip
    path = os.path.join(workdir, PACKED_DIR, f'runs-{i // _PER_PACK:03d}.npz')
    files.write_atomic(path, lambda p, a=arrays: np.savez(p, **a))
    out.append(path)
  record = recorded_networks(workdir)
  if record is not None:
    files.write_json(os.path.join(workdir, PACKED_DIR, NETWORKS_FILE), record)
  return out


def packed_runs(workdir: str) -> list[dict]:
  """The runs ``pack_runs`` wrote to ``<workdir>/packed/`` ([] if none), each
  with its saved GP in memory (``'saved'``)."""
  root = os.path.join(workdir, PACKED_DIR)
  names = sorted(os.listdir(root)) if os.path.isdir(root) else []
  runs = []
  for name in names:
    if not (name.startswith('runs-') and name.endswith('.npz')):
      continue
    path = os.path.join(root, name)
    try:
      with np.load(path) as z:
        for j, seq in enumerate(z['seq']):
          mat = str(z['material'][j]) if 'material' in z.files else ''
          runs.append({
            'seq': int(seq), 'material': mat or None,
            'truth': json.loads(str(z['truth'][j])), 'workdir': None,
            'saved': {k: np.asarray(z[k][j], np.float64) for k in _PACKED},
          })  # fmt: skip
    except (OSError, ValueError, KeyError) as e:
      raise ValueError(f'{path}: not a file of packed runs ({e})') from e
  return runs


def saved_runs(workdir: str) -> list[dict]:
  """The finished estimates a study's workdir holds (``estimates/<seq>/``
  with ``estimate.json`` and ``posterior.npz``, else those packed by
  ``pack_runs``), as ``simulate_and_estimate`` returns them: the analysis can
  run on another machine than the searches.

  Raises:
    ValueError: no finished estimate there.
  """
  root = os.path.join(workdir, 'estimates')
  runs = []
  for seq in sorted(os.listdir(root)) if os.path.isdir(root) else []:
    wd = os.path.join(root, seq)
    est = os.path.join(wd, layout.ESTIMATE_FILE)
    if (
      seq.isdigit()
      and os.path.isfile(est)
      and os.path.isfile(os.path.join(wd, layout.POSTERIOR_FILE))
    ):
      e = recording_lib.read_json(est)
      runs.append({'seq': int(seq), 'material': e.get('material'), 'truth': e['truth'],
                   'workdir': wd})  # fmt: skip
  runs = runs or packed_runs(workdir)
  if not runs:
    raise ValueError(
      f'{root}: no finished estimates to analyse (nor packed ones in '
      f'{os.path.join(workdir, PACKED_DIR)})'
    )
  return runs
