"""The paper's Table 1: PhySNet and SDN on depth and RGB, per material, plus similarity maps.

``experiments/table1.py`` is its command line. For every material, four
networks (PhySNet and SDN, each on depth and on RGB frames) are trained with
``experiments.pipeline.training`` under two splits, in
``<workdir>/<network>_<modality>/<split>/<material>``; finished runs are reused
(not retrained, their data not even loaded) and interrupted ones resume.

Each table cell is ``A / B`` in percent, both from the evaluation row that
``model.fit`` writes to ``metrics.jsonl`` (``model.train.evaluate``) for the
network it ships: the last epoch's, or with ``--val_fraction`` the epoch with
the best validation triplet accuracy on held-out *training* simulations
(``model.selected_eval``; the test simulations play no part in the choice):

* A, ``test_triplet_accuracy`` under the 'simulation' split (the honest test):
  ``test_fraction`` of the material's simulations (parameter sets = labels) are
  held out whole; among the held-out items only, ``eval_triplets`` random
  triplets (anchor; positive of the anchor's label; negative of another label)
  are drawn, and A is the share with ``|e_a - e_p|^2 < |e_a - e_n|^2`` (a tie
  counts as wrong). Chance is 50%. It asks whether the embedding groups frames
  of parameter sets it never saw.
* B, ``test_knn_accuracy`` under the paper's 'random' split: ``test_fraction``
  of the items are held out at random, so test items come from simulations
  seen in training; each test item gets the majority label of its ``knn_k``
  (5; fewer if the training set is smaller) nearest training embeddings
  (Euclidean; ties to the nearer neighbour), and B is the share labelled
  right. Chance is about 1 / (number of labels).
  This is the closest reading of the paper's (undefined) "clustering accuracy".

Items are single frames for PhySNet and ``sdn_frames``-frame clips of one
camera for SDN. The paper's numbers are printed beside ours for reference.

Also writes ``similarity_map_<material>.png``: the held-out simulations' frames
embedded by the PhySNet (depth, simulation split) network, coloured by their
label's wind speed (a marker per held-out label), over the faded training
frames.
"""

from __future__ import annotations

import dataclasses
import os

import matplotlib

matplotlib.use('Agg')
import jax  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import model as model_lib  # noqa: E402
from experiments.pipeline import cli, distributed, files  # noqa: E402
from experiments.pipeline import training as train_lib  # noqa: E402
from physsim import dataset  # noqa: E402
from physsim import params as params_lib  # noqa: E402

# (network, modality) in the paper's column order.
COLUMNS = (('physnet', 'depth'), ('sdn', 'rgb'), ('physnet', 'rgb'), ('sdn', 'depth'))
COLUMN_NAMES = {
  ('physnet', 'depth'): 'PhySNet (depth)',
  ('sdn', 'rgb'): 'SDN (RGB)',
  ('physnet', 'rgb'): 'PhySNet (RGB)',
  ('sdn', 'depth'): 'SDN (depth)',
}
SPLITS = ('simulation', 'random')
TABLE_FILE = 'table1.md'
JSON_FILE = 'table1.json'
# The paper's Table 1 ("Clustering Accuracy", %), quoted in COLUMNS order.
PAPER_TABLE1 = {
  'white_tablecloth': (80, 91, 89, 90),
  'black_denim': (88, 89, 86, 97),
  'gray_interlock': (83, 86, 84, 92),
  'sparkle_fleece': (77, 82, 78, 92),
  'ponte_roma': (79, 84, 80, 93),
  'pink_nylon': (80, 83, 77, 93),
  'red_violet': (80, 87, 78, 92),
}
_MARKERS = 'osD^vP*Xph<>'


@dataclasses.dataclass(frozen=True)
class Config:
  """The Table 1 experiment.

  Attributes:
    train: settings shared by every run (its materials, network, modality and
      split are set per run).
    materials: fabric names; empty = every material in the dataset.
    columns: '<network>_<modality>' columns to train; empty = all four.
    splits: splits to train, 'simulation' and/or 'random'; empty = both. With ``columns`` and ``splits``
      several processes (one per GPU) share the runs; a last run without
      them reuses every finished run and writes the table.
    train_only: train, but write no table or maps (a share of the runs).
  """

  train: train_lib.Config = cli.nested(
    train_lib.PRESETS['paper'],
    skip=('materials', 'all_materials', 'network', 'modality', 'fit.split'),
  )
  materials: tuple[str, ...] = ()
  columns: tuple[str, ...] = ()
  splits: tuple[str, ...] = ()
  train_only: bool = False


PRESETS = {
  'paper': Config(),
  # Half held out, so a 4-simulation smoke dataset leaves two labels on each side.
  'smoke': Config(
    train=dataclasses.replace(
      train_lib.PRESETS['smoke'],
      fit=dataclasses.replace(train_lib.PRESETS['smoke'].fit, test_fraction=0.5),
    )
  ),
}


def _split_dir(workdir: str, network: str, modality: str, split: str) -> str:
  return os.path.join(workdir, f'{network}_{modality}', split)


def run_dir(
  workdir: str, network: str, modality: str, split: str, material: str
) -> str:
  return os.path.join(_split_dir(workdir, network, modality, split), material)


def _check_labels(config: Config, index: dataset.DatasetIndex, material: str) -> None:
  """ValueError unless the simulation split leaves >= 2 labels on each side."""
  n = len({r['label'] for r in index.filter(material=material, valid=True).rows})
  f = config.train.fit.test_fraction
  n_test = int(np.clip(round(f * n), 1, max(n - 1, 1)))
  if n_test < 2 or n - n_test < 2:
    raise ValueError(
      f'{index.root}: material {material!r} has {n} valid simulations; with '
      f'test_fraction={f} the simulation split holds out {n_test}, but triplets '
      'need >= 2 labels held out and >= 2 for training (generate more '
      '--sequences or change test_fraction)'
    )


def _run_config(config: Config, material: str, network: str, modality: str, split: str):
  # Retrieval needs held-out simulations: random-split runs select by triplets.
  select_by = 'triplet' if split == 'random' else config.train.fit.select_by
  return dataclasses.replace(
    config.train,
    materials=(material,),
    all_materials=False,
    network=network,
    modality=modality,
    fit=dataclasses.replace(config.train.fit, split=split, select_by=select_by),
  )


def train_all(
  config: Config, root: str, workdir: str, *, progress: bool = True
) -> dict[str, dict[str, dict[str, dict]]]:
  """Trains (or reuses) every run.

  Args:
    config: experiment config.
    root: dataset root (made with ``--rgb``).
    workdir: parent of the run folders.
    progress: show tqdm bars.

  Returns:
    ``{material: {column name: {split: last eval row}}}``.
  """
  index = dataset.open_dataset(root)
  materials = config.materials or index.materials
  for m in materials:
    if m not in index.materials:
      raise ValueError(
        f'{root}: no material {m!r} (materials: {list(index.materials)})'
      )
    _check_labels(config, index, m)
  jobs = [
    (m, network, modality, split)
    for m in materials
    for network, modality in selected_columns(config)
    for split in SPLITS
    if not config.splits or split in config.splits
  ]
  # Under several processes each trains a contiguous share (the splits of a
  # material and column share their inputs); the others' runs are left out
  # until they finish.
  mine = set(distributed.share(jobs))
  out, data = {}, {}
  for m, network, modality, split in jobs:
    name = COLUMN_NAMES[network, modality]
    cfg = _run_config(config, m, network, modality, split)
    folder = run_dir(workdir, network, modality, split, m)
    row = train_lib.finished_eval(cfg, root, folder, [m])
    if row is None and (m, network, modality, split) not in mine:
      continue
    if row is None:
      if (m, network, modality) not in data:  # both splits share the inputs
        data = {(m, network, modality): train_lib.load_inputs(cfg, root, [m])}
      inputs = data[m, network, modality]
      print(f'{m} / {name} / {split}: training on {inputs[0].shape}', flush=True)
      _, row = train_lib.fit_run(cfg, root, folder, [m], inputs, progress=progress)
    else:
      print(f'{m} / {name} / {split}: finished run reused', flush=True)
    out.setdefault(m, {}).setdefault(name, {})[split] = row
  return out


def _pct(row: dict, key: str) -> str:
  return f'{100.0 * row[key]:.1f}' if key in row else 'n/a'


def cell(runs: dict) -> str:
  """``'A / B'`` (percent) from ``{split: eval row}``; 'n/a' where a metric is missing."""
  a = _pct(runs.get('simulation', {}), 'test_triplet_accuracy')
  b = _pct(runs.get('random', {}), 'test_knn_accuracy')
  return f'{a} / {b}'


def selected_columns(config: Config) -> list[tuple[str, str]]:
  """The ``(network, modality)`` columns ``config.columns`` asks for (all four
  when empty), in the paper's order."""
  return [
    c for c in COLUMNS if not config.columns or f'{c[0]}_{c[1]}' in config.columns
  ]


def column_names(config: Config) -> list[str]:
  """The table's column names (`selected_columns`)."""
  return [COLUMN_NAMES[c] for c in selected_columns(config)]


def _table(rows: list[tuple[str, list[str]]], names: list[str]) -> list[str]:
  lines = ['| Material | ' + ' | '.join(names) + ' |']
  lines.append('|---|' + '---:|' * len(names))
  lines += [f'| {m} | ' + ' | '.join(cells) + ' |' for m, cells in rows]
  return lines


def _epoch_note(t: model_lib.TrainConfig) -> str:
  if not t.val_fraction:
    return f'Last epoch ({t.epochs}) of each run.'
  stop = (
    f', stopping after {t.patience} epochs without a better one' if t.patience else ''
  )
  by = (
    'triplet accuracy'
    if t.select_by == 'triplet'
    else 'parameter retrieval (simulation split; triplet accuracy under the random split)'
  )
  return (
    f'Epoch of each run (at most {t.epochs}) chosen by {by} on '
    f'{t.val_fraction:g} of its training part held out for validation the way its '
    f'test set was (whole simulations, or random items under the random split){stop}.'
  )


def format_table(results: dict, root: str, config: Config) -> str:
  """The markdown of Table 1 (ours, the metric definitions, and the paper's, whose
  four columns are always shown)."""
  names = column_names(config)
  t = config.train.fit
  knn_k = model_lib.TrainConfig().knn_k
  lines = [
    f'# Table 1: clustering accuracy (dataset `{root}`)',
    '',
    'Each cell: triplet accuracy on held-out simulations / k-NN label accuracy '
    "under the paper's random split, in percent.",
    '',
  ]
  lines += _table(
    [(m, [cell(r.get(n, {})) for n in names]) for m, r in results.items()], names
  )
  lines += [
    '',
    f'- Triplet accuracy (first number): split by simulation, {t.test_fraction:g} of '
    "a material's parameter sets held out whole; among held-out items only, "
    'random triplets (anchor, positive of its label, negative of another label); '
    'the share with |e_a - e_p|^2 < |e_a - e_n|^2 (ties wrong). Chance 50%.',
    f'- k-NN accuracy (second number): random per-item split, {t.test_fraction:g} '
    'held out (test items come from simulations seen in training); each test '
    f'item takes the majority label of its k = min({knn_k}, training items) nearest '
    'training embeddings (ties: the nearer); the share labelled right. Chance '
    'about 1 / number of labels.',
    '- Items: frames for PhySNet, '
    f'{config.train.sdn.num_frames}-frame single-camera clips for SDN. '
    + _epoch_note(t)
    + ' n/a: the test set could not support the metric.',
  ]
  lines += _retrieval_table(results, names)
  paper = [(m, [f'{v}' for v in PAPER_TABLE1[m]]) for m in results if m in PAPER_TABLE1]
  if paper:
    lines += [
      '',
      "## The paper's Table 1 (clustering accuracy, %; protocol not stated)",
      '',
    ]
    lines += _table(paper, [COLUMN_NAMES[c] for c in COLUMNS])
  return '\n'.join(lines) + '\n'


def retrieval_cell(row: dict) -> str:
  """``'E (b / w / a)'``: a run's test retrieval error against chance, and each
  parameter's mean |log ratio|, or 'n/a'."""
  r = row.get('test_retrieval')
  if not r:
    return 'n/a'
  per = ' / '.join(f'{r[f]:.2f}' for f in params_lib.FIELDS)
  return f'{r["error"]:.2f} ({per})'


def _retrieval_table(results: dict, names: list[str]) -> list[str]:
  """Parameter retrieval of the held-out simulations (``model.retrieval``), when logged."""
  runs = {
    m: [r.get(n, {}).get('simulation', {}) for n in names] for m, r in results.items()
  }
  logged = [
    x['test_retrieval'] for xs in runs.values() for x in xs if x.get('test_retrieval')
  ]
  if not logged:
    return []
  chance = logged[0]['chance']
  rows = [(m, [retrieval_cell(x) for x in xs]) for m, xs in runs.items()]
  return [
    '',
    '## Parameter retrieval on the held-out simulations (`model.retrieval`)',
    '',
    'Each held-out clip (one simulation, one camera) retrieves the PSD-nearest '
    'training clip of its camera. Cell: mean over the parameters of the error '
    'relative to a random reference (0 = exact, 1 = chance), then the mean '
    '|log(retrieved / true)| of bending scale / wind speed / area weight. Chance '
    'for the first material: '
    + ' / '.join(f'{chance[f]:.2f}' for f in params_lib.FIELDS)
    + '.',
    '',
    *_table(rows, names),
  ]


def _label_params(index: dataset.DatasetIndex, material: str) -> dict[int, tuple]:
  return {
    r['label']: (r['bending_scale'], r['wind_speed'], r['area_weight'])
    for r in index.filter(material=material, valid=True).rows
  }


def _to_2d(emb: np.ndarray) -> tuple[np.ndarray, str]:
  """2-D points: the embedding itself, or its first two principal components."""
  if emb.shape[1] == 2:
    return emb, 'embedding'
  centred = emb - emb.mean(axis=0)
  _, _, vt = np.linalg.svd(centred, full_matrices=False)
  return centred @ vt[:2].T, 'embedding PC'


def _savefig_atomic(fig, path: str) -> None:
  files.savefig(fig, path, dpi=130)


def similarity_map(config: Config, root: str, workdir: str, material: str) -> str:
  """Scatter plot of the held-out simulations in the PhySNet (depth) embedding.

  Args:
    config: experiment config.
    root: dataset root.
    workdir: parent of the run folders (the PhySNet depth simulation run is read).
    material: which material.

  Returns:
    The PNG's path, ``<workdir>/similarity_map_<material>.png``.
  """
  cfg = _run_config(config, material, 'physnet', 'depth', 'simulation')
  network, params, tconfig = model_lib.load_network(
    run_dir(workdir, 'physnet', 'depth', 'simulation', material)
  )
  x, y, g = train_lib.load_inputs(cfg, root, [material])
  train_idx, test_idx = model_lib.split_indices(tconfig, y, g)
  emb = model_lib.embed(network.apply, params, x, tconfig.eval_batch_size)
  pts, axis = _to_2d(emb)
  label_params = _label_params(dataset.open_dataset(root), material)
  wind = np.array([label_params[int(v)][1] for v in y])
  norm = matplotlib.colors.Normalize(wind.min(), max(wind.max(), wind.min() + 1e-6))
  cmap = plt.get_cmap('viridis')
  fig, ax = plt.subplots(figsize=(6.4, 5.0))
  ax.scatter(*pts[train_idx].T, c=wind[train_idx], cmap=cmap, norm=norm, s=8,
             alpha=0.3, linewidths=0, label='training frames')  # fmt: skip
  for i, lab in enumerate(np.unique(y[test_idx])):
    sel = test_idx[y[test_idx] == lab]
    b, w, a = label_params[int(lab)]
    ax.scatter(*pts[sel].T, c=wind[sel], cmap=cmap, norm=norm, s=18,
               marker=_MARKERS[i % len(_MARKERS)], edgecolors='k', linewidths=0.3,
               label=f'{lab}: bend x{b:.2g}, wind {w:.2f} m/s, {a:.3f} kg/m$^2$')  # fmt: skip
  fig.colorbar(
    matplotlib.cm.ScalarMappable(norm, cmap), ax=ax, label='wind speed (m/s)'
  )
  ax.set(xlabel=f'{axis} 1', ylabel=f'{axis} 2',
         title=f'{material}: PhySNet (depth), held-out simulations')  # fmt: skip
  ax.legend(fontsize=6, loc='best', title='label (held out)', title_fontsize=6)
  fig.tight_layout()
  path = os.path.join(workdir, f'similarity_map_{material}.png')
  _savefig_atomic(fig, path)
  plt.close(fig)
  return path


def collect(config: Config, workdir: str) -> tuple[dict, list[str]]:
  """The runs under ``workdir`` as they stand, training and loading nothing.

  For collecting a run cut short (a device budget, a crash): every run folder
  with an eval row gives its selected row (``model.selected_eval``); a run
  that neither reached its own ``config.json``'s epochs nor stopped early is
  listed as cut.

  Returns:
    ``({material: {column name: {split: eval row}}}, ['<material> / <column> /
    <split>: cut at epoch E of N', ...])``.
  """
  results: dict = {}
  cut = []
  for network, modality in selected_columns(config):
    name = COLUMN_NAMES[network, modality]
    for split in SPLITS:
      if config.splits and split not in config.splits:
        continue
      base = _split_dir(workdir, network, modality, split)
      for m in sorted(os.listdir(base)) if os.path.isdir(base) else []:
        folder = os.path.join(base, m)
        evals = model_lib.read_evals(folder)
        if (config.materials and m not in config.materials) or not evals:
          continue
        saved = model_lib.config_io.read_json(
          os.path.join(folder, model_lib.train.CONFIG_FILE)
        )
        if not model_lib.ended(evals, saved['epochs'], saved.get('patience', 0)):
          cut.append(
            f'{m} / {name} / {split}: cut at epoch {evals[-1]["epoch"]} of '
            f'{saved["epochs"]}'
          )
        results.setdefault(m, {}).setdefault(name, {})[split] = model_lib.selected_eval(
          evals
        )
  return dict(sorted(results.items())), cut


def report(config: Config, root: str, workdir: str) -> dict:
  """Writes ``table1.md`` and ``table1.json`` of the runs as they stand
  (``collect``), cut runs marked; trains nothing and draws no maps."""
  results, cut = collect(config, workdir)
  if not results:
    raise ValueError(f'{workdir}: no run with an eval row')
  text = format_table(results, root, config)
  if cut:
    text += '\nRuns cut short (their best epoch so far is shown):\n\n' + ''.join(
      f'- {c}\n' for c in cut
    )
  dataset.write_text_atomic(os.path.join(workdir, TABLE_FILE), text)
  dataset.write_json_atomic(
    os.path.join(workdir, JSON_FILE),
    {'dataset': root, 'results': results, 'cut': cut, 'paper': PAPER_TABLE1},
  )
  print(text)
  return {'results': results, 'markdown': text, 'cut': cut}


def run(config: Config, root: str, workdir: str, *, progress: bool = True) -> dict:
  """Trains what is missing, writes ``table1.md``, ``table1.json`` and the maps.

  Args:
    config: experiment config.
    root: dataset root (made with ``--rgb``).
    workdir: output folder.
    progress: show tqdm bars.

  Returns:
    ``{'results': {material: {column: {split: eval row}}}, 'markdown': str,
    'maps': {material: png path}}``; the maps need the PhySNet (depth)
    simulation-split column, and are empty without it.
  """
  os.makedirs(workdir, exist_ok=True)
  for c in config.columns:
    if c not in {f'{n}_{m}' for n, m in COLUMNS}:
      raise ValueError(f'column {c!r}: choose from physnet/sdn x depth/rgb')
  for sp in config.splits:
    if sp not in SPLITS:
      raise ValueError(f'split {sp!r}: choose from {SPLITS}')
  results = train_all(config, root, workdir, progress=progress)
  distributed.barrier('table1: training done')
  if not distributed.is_main():
    return {'results': results, 'markdown': '', 'maps': {}}
  if jax.process_count() > 1:  # the other processes' runs are on disk now
    results = train_all(config, root, workdir, progress=progress)
  if config.train_only:
    return {'results': results, 'markdown': '', 'maps': {}}
  # The maps show the PhySNet (depth) simulation-split runs: only when trained here.
  has_maps = ('physnet', 'depth') in selected_columns(config) and (
    'simulation' in (config.splits or SPLITS)
  )
  maps = {m: similarity_map(config, root, workdir, m) for m in results if has_maps}
  text = format_table(results, root, config)
  dataset.write_text_atomic(os.path.join(workdir, TABLE_FILE), text)
  dataset.write_json_atomic(
    os.path.join(workdir, JSON_FILE),
    {'dataset': root, 'results': results, 'paper': PAPER_TABLE1},
  )
  print(text)
  return {'results': results, 'markdown': text, 'maps': maps}
