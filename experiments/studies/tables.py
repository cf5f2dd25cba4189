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
writes the tables once every process has finished its share.
"""

from __future__ import annotations

import dataclasses
import json
import os

import matplotlib

matplotlib.use('Agg')
import jax  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import (
  cli,
  distributed,
  embedding,
  estimation,  # noqa: E402
  eval_set,
  files,
  measurements,
  report,
  search,
)  # fmt: skip
from experiments.pipeline import objective as objective_lib  # noqa: E402
from experiments.pipeline import recording as recording_lib  # noqa: E402
from experiments.pipeline.objective import NETWORK_DISTANCE, EstimateConfig  # noqa: E402
from experiments.studies import table1  # noqa: E402
from physsim import dataset  # noqa: E402

# The paper's PhySNet-depth results (percent error of wind speed, area weight).
PAPER = {
  'white_tablecloth': (6.5, 8.6),
  'gray_interlock': (9.6, 19.6),
  'black_denim': (5.4, 5.5),
  'ponte_roma': (35.0, 0.4),
  'sparkle_fleece': (34.6, 0.0),
  'red_violet': (16.7, 6.3),
  'pink_nylon': (12.6, 2.6),
  'tshirt': (3.1, 17.1),
  'shirt': (34.2, 1.5),
  'jeans': (21.7, 0.6),
}
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
ERRORS = ('wind_speed_pct', 'area_weight_pct', 'bending_factor', 'load_ratio_pct')
ERROR_NAMES = ('wind %', 'area weight %', 'bending factor', 'load ratio %')


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
      this relative standard error (``posterior.simulated_reading``) enters
      the search as a prior, so the search spends its simulations on that
      slice. Needs recordings with a truth.
    area_weight_reading_sd: the same for area weight (a scale and a ruler).
    reading_seed: seed of the simulated readings (recording ``seq_id`` k
      gets the reading ``experiments.calibrate`` and
      ``benchmarks/measured_modes.py`` draw for recording k with this seed).
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
  """The ``posterior.Measured`` a recording is estimated with under
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


def rescore(result: dict) -> dict:
  """The result with its ``errors`` recomputed by today's ``estimate.errors``
  from its estimate and truth (so older runs gain newer error measures)."""
  if 'truth' not in result or 'estimate' not in result:
    return result
  best = physsim.Params(
    *(result['estimate'][f]['value'] for f in physsim.Params._fields)
  )
  space = physsim.search_space(result['material'])
  return {**result, 'errors': report.errors(best, result['truth'], space)}


def _values(rows, source, err):
  return [r['errors'][source][err] for r in rows if err in r['errors'][source]]


def _mean(rows, source, err):
  vals = _values(rows, source, err)
  return report.mean_error(vals, err) if vals else float('nan')


def summarise(results: dict, methods) -> dict:
  """{(method, set name): {'n', 'failed', estimate/range_centre means}}."""
  groups = {}
  for (method, _, name, _), res in results.items():
    groups.setdefault((method, name), []).append(res)
  out = {}
  for (method, name), rows in sorted(groups.items()):
    ok = [r for r in rows if 'errors' in r]
    s = {'n': len(rows), 'failed': len(rows) - len(ok)}
    for source in ('estimate', 'range_centre'):
      s[source] = {e: _mean(ok, source, e) for e in ERRORS} if ok else None
    out[(method, name)] = s
  return out


def _group(key: tuple) -> str:
  return 'fabrics' if key[1] == 'fabrics' else 'garments'


def overall(results: dict, methods) -> dict:
  """Per method and group (fabrics, garments), over every recording: the mean
  and median of each error, and on how many recordings the method beats the
  range centre. ``('range centre', group)`` holds the trivial estimate's
  errors over the distinct recordings."""
  rows, centre = {}, {}
  for key, res in sorted(results.items()):
    if key[0] not in methods:
      continue
    rows.setdefault((key[0], _group(key)), []).append(res)
    if 'errors' in res:
      centre.setdefault(_group(key), {})[key[1:]] = res
  out = {}
  for (method, group), rs in rows.items():
    ok = [r for r in rs if 'errors' in r]
    s = {'n': len(rs), 'failed': len(rs) - len(ok)}
    for e in ERRORS:
      pairs = [
        (r['errors']['estimate'][e], r['errors']['range_centre'][e])
        for r in ok
        if e in r['errors']['estimate']
      ]
      s[e] = {
        'mean': _mean(ok, 'estimate', e),
        'median': float(np.median(_values(ok, 'estimate', e))) if pairs else None,
        'beats_centre': sum(a < b for a, b in pairs),
        'of': len(pairs),
      }
    out[(method, group)] = s
  for group, recs in centre.items():
    rs = list(recs.values())
    out[('range centre', group)] = {
      'n': len(rs),
      'failed': 0,
      **{
        e: {
          'mean': _mean(rs, 'range_centre', e),
          'median': float(np.median(_values(rs, 'range_centre', e))),
        }
        for e in ERRORS
      },
    }
  return out


def format_overall(table: dict) -> str:
  """Markdown of ``overall``: one row per method and group."""
  lines = [
    '### All recordings',
    '',
    '| method | set | n | '
    + ' | '.join(f'{n}: mean / median' for n in ERROR_NAMES)
    + ' | beats range centre on (wind / area weight / bending / load ratio) |',
    '|---' * (3 + len(ERRORS) + 1) + '|',
  ]
  for (method, group), s in sorted(
    table.items(), key=lambda kv: (kv[0][1], kv[0][0] == 'range centre', kv[0][0])
  ):
    num = lambda e, v: f'x{v:.2f}' if e == 'bending_factor' else f'{v:.1f}'
    cells = [
      num(e, s[e]['mean'])
      + ('' if s[e]['median'] is None else f' / {num(e, s[e]["median"])}')
      for e in ERRORS
    ]
    beats = (
      ' / '.join(f'{s[e]["beats_centre"]}' for e in ERRORS)
      + f' of {s[ERRORS[0]]["of"]}'
      if 'beats_centre' in s[ERRORS[0]]
      else ''
    )
    failed = f' ({s["failed"]} F)' if s['failed'] else ''
    lines.append(
      f'| {method} | {group} | {s["n"]}{failed} | '
      + ' | '.join(cells)
      + f' | {beats} |'
    )
  lines += [
    '',
    'Bending: geometric mean / median of the factor. Load ratio: rho v^2 / (w g) '
    'from the estimated wind and area weight against the true one (a static sheet '
    'constrains only this combination of the two).',
  ]
  return '\n'.join(lines)


def _fmt(s, source):
  if s[source] is None:
    return 'F | F | F'
  v = s[source]
  return (
    f'{v["wind_speed_pct"]:.1f} | {v["area_weight_pct"]:.1f} | '
    f'x{v["bending_factor"]:.2f}'
  )


def format_tables(summary: dict, methods) -> str:
  lines = []
  sets = (
    ('Table 2: fabrics', [f for f in physsim.FABRICS]),
    ('Table 3: garments', list(eval_set.GARMENT_FABRICS)),
  )
  for title, names in sets:
    names = [n for n in names if any((m, n) in summary for m in methods)]
    if not names:
      continue
    lines += [f'### {title}', '']
    head = '| | ' + ' | '.join(
      f'{m}: wind % | area weight % | bending factor' for m in methods
    )
    head += ' | range centre: wind % | area weight % | bending factor'
    head += ' | paper PhySNet-depth: wind % | area weight % |'
    lines.append(head)
    lines.append('|---' * (1 + 3 * len(methods) + 3 + 2) + '|')
    for n in names:
      cells = []
      centre = None
      for m in methods:
        s = summary.get((m, n))
        if s is None:
          cells.append('- | - | -')
          continue
        tag = f' ({s["failed"]}/{s["n"]} F)' if s['failed'] else ''
        cells.append(_fmt(s, 'estimate') + tag)
        centre = centre or (s if s['range_centre'] else None)
      pw, pa = PAPER.get(n, (float('nan'),) * 2)
      lines.append(
        f'| {n} | '
        + ' | '.join(cells)
        + f' | {_fmt(centre, "range_centre") if centre else "- | - | -"}'
        + f' | {pw} | {pa} |'
      )
    lines.append('')
  lines.append(
    "Mean over each fabric's or garment's recordings: percent error |est - true| / "
    'true of wind speed and area weight; bending as the factor exp|log(est / true)| '
    '(>= 1, geometric mean). "range centre" is the trivial estimate at the centre of '
    'the search box (log-centre for bending). F: every candidate blew up or the run '
    'failed.'
  )
  return '\n'.join(lines)


def bending_surfaces(results: dict, method: str, path: str) -> None:
  """The paper's Figure 4: true and estimated 3x5 bending matrices per fabric."""
  fabrics = sorted(
    {k[2] for k in results if k[0] == method and k[1] == 'fabrics'},
    key=list(physsim.FABRICS).index,
  )
  if not fabrics:
    return
  cols = min(4, len(fabrics))
  rows = -(-len(fabrics) // cols)
  fig = plt.figure(figsize=(4 * cols, 3.4 * rows))
  ang = physsim.materials.BENDING_ANGLES
  curv = np.arange(5) * 5.0  # ArcSim samples, 1/m
  gx, gy = np.meshgrid(curv, ang)
  for i, fab in enumerate(fabrics):
    ax = fig.add_subplot(rows, cols, i + 1, projection='3d')
    base = physsim.load_material(physsim.fabric(fab).material).bending
    res = [
      r
      for k, r in results.items()
      if k[:3] == (method, 'fabrics', fab) and 'truth' in r
    ][:1]
    if not res:
      continue
    r = res[0]
    true = base * r['truth']['bending_scale']
    est = np.asarray(r['bending_matrix_Nm'])
    ax.plot_wireframe(gx, gy, np.log10(true), color='k', lw=0.8, label='true')
    ax.plot_surface(gx, gy, np.log10(est), alpha=0.6, cmap='viridis')
    ax.set(
      title=fab, xlabel='curvature (1/m)', ylabel='angle (deg)', zlabel='log10 N m'
    )
    ax.title.set_fontsize(9)
  fig.suptitle(f'bending matrices, true (wire) vs estimated (surface), {method}')
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def candidate_landscapes(results: dict, method: str, workdir: str) -> dict:
  """Every candidate a method's searches scored, placed against the truth.

  Reads each finished estimate's ``bo_state.npz`` (no simulation). Returns
  ``{fabric or garment: [(ratio (n, 3), rel (n,)) per recording]}``: ``ratio``
  is ``log10(value / truth)`` of bending scale, wind speed and area weight (0 =
  the truth), ``rel`` the candidate's PSD over the search's best (>= 1; NaN
  where its simulation failed).
  """
  out: dict = {}
  for key, r in sorted(results.items()):
    if key[0] != method or 'truth' not in r:
      continue
    state = os.path.join(workdir, key[0], key[1], f'{key[2]}-{key[3]}', 'bo_state.npz')
    if not os.path.isfile(state):
      continue
    with np.load(state) as z:
      x, y = np.asarray(z['X'], np.float64), np.asarray(z['Y'], np.float64)
    values = physsim.from_unit(x, physsim.search_space(r['material']))
    truth = [r['truth'][f] for f in physsim.Params._fields]
    ratio = np.stack(
      [np.log10(np.ravel(v) / t) for v, t in zip(values, truth, strict=True)], 1
    )
    out.setdefault(key[2], []).append((ratio, y / np.nanmin(y)))
  return out


def plot_candidate_landscapes(landscapes: dict, method: str, path: str) -> None:
  """The PSD along each parameter, as the searches sampled it: one row per
  fabric or garment, one column per parameter, one colour per recording."""
  if not landscapes:
    return
  names = list(landscapes)
  labels = ('bending scale', 'wind speed', 'area weight')
  fig, axes = plt.subplots(
    len(names), 3, figsize=(11, 2.1 * len(names)), sharey=True, squeeze=False
  )
  for row, name in zip(axes, names, strict=True):
    for j, (ratio, rel) in enumerate(landscapes[name]):
      for i, ax in enumerate(row):
        ax.semilogy(ratio[:, i], rel, '.', ms=4, color=f'C{j}')
    for i, ax in enumerate(row):
      ax.axvline(0.0, color='k', lw=0.8)
      ax.set_title(f'{name}: {labels[i]}', fontsize=8)
  for i, ax in enumerate(axes[-1]):
    ax.set_xlabel(f'log10({labels[i]} / truth)')
  for ax in axes[:, 0]:
    ax.set_ylabel('PSD / best')
  fig.suptitle(f'{method}: every candidate the searches scored (truth at 0)')
  fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / fig.get_figheight()))  # room for the title
  files.savefig(fig, path, dpi=80)
  plt.close(fig)


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
