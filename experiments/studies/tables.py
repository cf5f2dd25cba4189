"""Reproduce the paper's Table 2 (fabrics) and Table 3 (garments), with baselines.

Every recording of a real-like evaluation set (``experiments.make_eval_set``)
is estimated with each requested network (trained by ``experiments.table1``,
simulation split: ``<models>/<net>_<modality>/simulation/<fabric>``); garments
use the network of their fabric, as in the paper. For each fabric or garment
the tables give the mean percent error of wind speed and area weight and the
bending-scale error as a factor (which the paper could not measure), beside the
error of the trivial estimate (the centre of the search range) and the paper's
PhySNet-depth numbers. Failed estimates are marked F; a method without a trained
network for a fabric (no ``config.json`` in its run folder) is skipped there and
shown as '-'. The method ``shape`` needs no network: it estimates with
``--distance=shape`` (where the sheet hangs, ``physsim.shape``) from depth
frames at ``shape_image_size``. RGB methods need an evaluation set with colour frames (what
``make_eval_set`` writes).

``experiments/tables.py`` is its command line. Writes ``tables.md``, ``tables.json``, ``bending_surfaces_<method>.png`` (the
paper's Figure 4: true and estimated 3x5 bending matrices) and
``psd_candidates_<method>.png`` (the PSD of every candidate the searches scored
against each parameter, relative to the truth: the landscape as sampled; for
lines through the truth, ``experiments.studies.landscape``). Each estimate
resumes from its own folder. All estimates run in lockstep in this process
(``estimation.estimate_many``): every recording's candidates of an iteration are
scored together, which on a GPU costs about what one estimate does.
Under several processes (``experiments.pipeline.distributed``: one per GPU,
or a cluster) each takes a contiguous share of the estimates, and process 0
writes the tables once every process has finished its share. The tables'
numbers and markdown are in ``tables_report``, its figures in ``tables_figures``.
"""

from __future__ import annotations

import dataclasses
import json
import os

import jax
import numpy as np

import physsim
from experiments.pipeline import (
  cli,
  distributed,
  embedding,
  estimation,
  eval_set,
  files,  # noqa: F401 - the tests write their files through tables.files
  measurements,
  search,
)
from experiments.pipeline import objective as objective_lib
from experiments.pipeline import recording as recording_lib
from experiments.pipeline.objective import NETWORK_DISTANCE, EstimateConfig
from experiments.studies import table1
from experiments.studies.tables_figures import (
  bending_surfaces,
  candidate_landscapes,
  plot_candidate_landscapes,
)
from experiments.studies.tables_report import (
  ERROR_NAMES,  # noqa: F401 - the tables' names, importable from here as before
  ERRORS,  # noqa: F401
  PAPER,  # noqa: F401
  format_overall,
  format_tables,
  overall,
  rescore,
  summarise,
)
from physsim import dataset

# The paper's four methods, as <network>_<modality> run folders of table1.
METHODS = ('physnet_depth', 'physnet_rgb', 'sdn_depth', 'sdn_rgb')


def for_networks(estimate: EstimateConfig) -> EstimateConfig:
  """``estimate`` with the networks' distance where it has the shape (a
  preset's default): the tables compare what the networks read, unless told
  another distance."""
  if estimate.scoring.distance == 'shape':
    return estimate.replace(distance=NETWORK_DISTANCE)
  return estimate


# No network: the shape distance on the depth frames.
SHAPE_METHOD = 'shape'


@dataclasses.dataclass(frozen=True)
class Config:
  """Tables 2 and 3.

  Attributes:
    methods: networks to evaluate, '<network>_<modality>' run folders of table1,
      or 'shape' (no network: ``--distance=shape``).
    shape_image_size: pixels a side of the depth frames the 'shape' method
      reads (no network sets it).
    estimate: settings of every estimate (material and garment come from
      each recording).
    report_only: write the tables of what has finished; run nothing.
    wind_reading_sd: with > 0, every recording is estimated as if the wind had
      also been measured (an anemometer): a reading drawn around its truth with
      this relative standard error (``measurements.simulated_reading``) enters
      the search as a prior, so the search spends its simulations on that
      slice. Needs recordings with a truth.
    area_weight_reading_sd: the same for area weight (a scale and a ruler).
    reading_seed: seed of the simulated readings (recording ``seq_id`` k
      gets the reading ``experiments.calibrate`` and
      ``benchmarks/measured_modes.py`` (at c465b0e) draw for recording k with this seed).
      Recording k of every evaluation set gets the same relative error for
      one seed: pooling several sets, give each its own.
    camera_error_m: with > 0, every recording's camera is given misplaced, as
      an alignment would place it: its pose shifted by a random error of this
      size, metres (1 sd per axis; ``physsim.shape.misplaced_pose``), drawn
      from (reading_seed, recording seq_id). The estimate's own
      ``camera_sd_m`` / ``camera_sd_deg`` say whether it models such an error.
    camera_error_deg: the same for a rotation about the pins, degrees (1 sd
      per axis).
  """

  methods: tuple[str, ...] = METHODS
  shape_image_size: int = 256
  estimate: EstimateConfig = cli.nested(
    EstimateConfig().replace(distance=NETWORK_DISTANCE),
    skip=('simulation.material', 'simulation.garment'),
  )
  report_only: bool = False
  wind_reading_sd: float = 0.0
  area_weight_reading_sd: float = 0.0
  reading_seed: int = 0
  camera_error_m: float = 0.0
  camera_error_deg: float = 0.0

  def __post_init__(self):
    for name in ('wind_reading_sd', 'area_weight_reading_sd'):
      v = getattr(self, name)
      if not 0.0 <= v < 1.0:
        raise ValueError(f'--{name}={v}: a relative standard error in [0, 1)')
    lo, hi = embedding.IMAGE_SIZES
    if not lo <= self.shape_image_size <= hi:
      raise ValueError(
        f'--shape_image_size={self.shape_image_size}: need {lo}-{hi} pixels a side'
      )
    if (self.wind_reading_sd > 0) + (self.area_weight_reading_sd > 0) > 1:
      raise ValueError(
        'simulate one reading at a time (--wind_reading_sd or --area_weight_reading_sd)'
      )


def simulated_measurement(config: Config, rec: dict, truth: dict | None):
  """The ``measurements.Measured`` a recording is estimated with under
  ``config``'s simulated readings (none: nothing measured)."""
  readings = {'wind_speed': config.wind_reading_sd,
              'area_weight': config.area_weight_reading_sd}  # fmt: skip
  for name, sd in readings.items():
    if sd > 0:
      if not truth:
        raise ValueError(
          f'{rec["path"]}: a simulated reading needs the truth (meta.json)'
        )
      return measurements.simulated_reading(
        name, truth, sd, config.reading_seed, int(rec['seq_id'])
      )
  return measurements.Measured()


def misplaced_camera(config: Config, rec: dict, recording, estimate: EstimateConfig):
  """``recording`` with its camera moved by ``config``'s simulated alignment
  error (unchanged without one)."""
  if not (config.camera_error_m or config.camera_error_deg):
    return recording
  if recording.pose is None:
    raise ValueError(f'{rec["path"]}: no camera pose to misplace')
  key = jax.random.fold_in(jax.random.key(config.reading_seed), int(rec['seq_id']))
  pose = physsim.shape.misplaced_pose(
    key, recording.pose, config.camera_error_m, config.camera_error_deg,
    objective_lib.pin_centre(estimate.simulation),
  )  # fmt: skip
  return recording._replace(pose=jax.tree.map(np.asarray, pose))


def recordings(eval_root: str) -> list[dict]:
  """Every valid recording of the evaluation set, with its set and fabric."""
  out = []
  for name in ['fabrics', *eval_set.GARMENT_FABRICS]:
    root = os.path.join(eval_root, name)
    if not os.path.isdir(root):
      continue
    index = dataset.open_dataset(root)
    for r in index.filter(valid=True).rows:
      out.append(
        {
          'set': name,
          'fabric': r['material'],
          'garment': '' if name == 'fabrics' else name,
          'seq_id': r['seq_id'],
          'path': index.path(r),
        }
      )
  if not out:
    raise ValueError(f'{eval_root}: no recordings (run experiments/make_eval_set.py)')
  return out


def _model_dir(models: str, method: str, fabric: str) -> str:
  """The fabric's network under ``models``; several roots (``'a,b'``) name
  an ensemble of their networks (``embedding.load_embedding``)."""
  if method == SHAPE_METHOD:
    return ''  # no network
  net, modality = method.split('_')
  return ','.join(
    table1.run_dir(root, net, modality, 'simulation', fabric)
    for root in embedding.members(models)
  )


def _out_dir(workdir: str, rec: dict, method: str) -> str:
  name = rec['garment'] or rec['fabric']
  return os.path.join(workdir, method, rec['set'], f'{name}-{rec["seq_id"]}')


def _key(rec: dict, method: str) -> tuple:
  return (method, rec['set'], rec['garment'] or rec['fabric'], rec['seq_id'])


def _batched(jobs, models: str, workdir: str, config: Config) -> dict:
  """Runs ``jobs`` (pairs of recording and method) in lockstep in this
  process; returns {key: result or {'failed': why}}."""
  results, batch, keys = {}, [], []
  nets = {}
  for rec, method in jobs:
    key, model_dir = _key(rec, method), _model_dir(models, method, rec['fabric'])
    ec = config.estimate.replace(
      material=rec['fabric'], garment=rec['garment'],
      **({'distance': 'shape'} if method == SHAPE_METHOD else {}),
    )  # fmt: skip
    try:
      if model_dir not in nets:
        nets[model_dir] = embedding.for_distance(
          model_dir, ec.scoring.distance, config.shape_image_size
        )
      net = nets[model_dir]
      recording = recording_lib.load_recording(
        rec['path'], fps=ec.simulation.fps, size=net.image_size,
        frames=ec.simulation.frames,
        rgb=net.modality == 'rgb',
      )  # fmt: skip
      recording = misplaced_camera(config, rec, recording, ec)
      measured = simulated_measurement(config, rec, recording.truth)
      if measured != measurements.Measured():
        ec = ec.replace(measured=measured)
    except (ValueError, OSError) as e:
      results[key] = {'failed': str(e)}
      continue
    batch.append(search.Job(ec, recording, model_dir, _out_dir(workdir, rec, method)))
    keys.append(key)
  for key, res in zip(keys, estimation.estimate_many(batch, nets=nets), strict=True):
    results[key] = res if isinstance(res, dict) else {'failed': str(res)}
  return results


def run_all(config: Config, eval_root: str, models: str, workdir: str) -> dict:
  """Runs (or reuses) every estimate of this shard; returns {key: result} of
  every finished or failed one (other shards' unfinished ones are left out)."""
  for m in config.methods:
    if m not in (*METHODS, SHAPE_METHOD):
      raise ValueError(
        f'method {m!r}: the estimate supports {(*METHODS, SHAPE_METHOD)}'
      )
  recs = recordings(eval_root)
  jobs, missing = [], set()
  for r in recs:  # by set (mesh) first: see the shards below
    for m in config.methods:
      model_dir = _model_dir(models, m, r['fabric'])
      if m == SHAPE_METHOD or all(
        os.path.isfile(os.path.join(d, 'config.json'))
        for d in embedding.members(model_dir)
      ):
        jobs.append((r, m))
      elif model_dir not in missing:
        missing.add(model_dir)
        print(f'{m}: no network at {model_dir}; its cells stay -', flush=True)
  results, mine = {}, []
  # Contiguous shares: jobs come sorted by set, so a process sees few meshes
  # (each mesh is a simulation batch of its own per iteration).
  share = set(distributed.share(range(len(jobs))))
  for i, (r, m) in enumerate(jobs):
    done = os.path.join(_out_dir(workdir, r, m), 'estimate.json')
    if os.path.isfile(done):
      with open(done) as f:
        results[_key(r, m)] = json.load(f)
    elif i in share:
      mine.append((r, m))
  if config.report_only:
    print(f'{len(mine)} estimates unfinished (not run: --report_only)', flush=True)
    return results
  if mine:
    print(f'{len(mine)} estimates in lockstep', flush=True)
    results.update(_batched(mine, models, workdir, config))
  return results


def run(config: Config, eval_root: str, models: str, workdir: str) -> str:
  """Runs this process's share of the estimates; process 0 then writes the
  tables of every finished one (returns '' in the others)."""
  os.makedirs(workdir, exist_ok=True)
  results = run_all(config, eval_root, models, workdir)
  distributed.barrier('tables: estimates done')
  if not distributed.is_main():
    return ''
  if jax.process_count() > 1:  # the other processes' results are on disk
    results = run_all(
      dataclasses.replace(config, report_only=True), eval_root, models, workdir
    )
  return write_report({k: rescore(v) for k, v in results.items()}, config, workdir)


def from_json(paths) -> dict:
  """The rescored estimates of one or more ``tables.json`` runs wrote (runs of
  different methods on the same evaluation set merge into one table)."""
  out = {}
  for path in paths:
    with open(path) as f:
      estimates = json.load(f).get('estimates')
    if not isinstance(estimates, dict):
      raise ValueError(f'{path}: no "estimates" (not a tables.json)')
    for k, v in estimates.items():
      key = tuple(k.split('/'))
      if key in out:
        raise ValueError(f'{path}: estimate {k} is also in an earlier file')
      out[key] = rescore(v)
  return out


def write_report(results: dict, config: Config, workdir: str) -> str:
  """Writes the tables, the JSON and the figures of finished estimates."""
  summary = summarise(results, config.methods)
  table = overall(results, config.methods)
  md = format_tables(summary, config.methods) + '\n\n' + format_overall(table)
  readings = {
    'wind': config.wind_reading_sd,
    'area weight': config.area_weight_reading_sd,
  }
  for name, sd in readings.items():
    if sd > 0:
      md = (
        f'Every estimate with a simulated {name} reading ({100 * sd:g}% relative '
        f'error, seed {config.reading_seed}) as its prior.\n\n' + md
      )
  if config.camera_error_m or config.camera_error_deg:
    md = (
      f'Every recording with its camera misplaced by a simulated alignment error '
      f'({100 * config.camera_error_m:g} cm, {config.camera_error_deg:g} degrees '
      f'per axis, seed {config.reading_seed}).\n\n' + md
    )
  dataset.write_text_atomic(os.path.join(workdir, 'tables.md'), md + '\n')
  dataset.write_json_atomic(
    os.path.join(workdir, 'tables.json'),
    {
      'config': objective_lib.record(config),
      'summary': {'/'.join(k): v for k, v in summary.items()},
      'overall': {'/'.join(k): v for k, v in table.items()},
      'estimates': {'/'.join(k): v for k, v in results.items()},
    },
  )
  for m in config.methods:
    bending_surfaces(results, m, os.path.join(workdir, f'bending_surfaces_{m}.png'))
    plot_candidate_landscapes(
      candidate_landscapes(results, m, workdir), m,
      os.path.join(workdir, f'psd_candidates_{m}.png'),
    )  # fmt: skip
  print(md)
  return md
