"""A dataset sweep's folder: ``dataset.json`` created or checked against the
config (a resume must match it), each sequence's ``meta.json``, the processes'
counts gathered, and a montage of each material's frames."""

from __future__ import annotations

import dataclasses
import json
import os

import jax
import numpy as np

import physsim
from experiments.pipeline import embedding, files
from experiments.pipeline.dataset_config import POSES, Config, cloth_mesh
from physsim import dataset

# Fields that do not change what is generated, so a resume may differ in them.
_FREE_FIELDS = ('workers',)


def identity(config: Config, backend: str) -> dict:
  d = dataclasses.asdict(config)
  d['materials'] = list(config.materials)
  d['backend'] = backend
  d['batching'] = 'across-materials'  # how gust keys map to sequences
  if config.rgb:  # older RGB datasets were all one grey
    d['rgb_colors'] = 'fabric'
  for k in _FREE_FIELDS:
    d.pop(k)
  if not config.min_coverage:  # datasets made before the re-draw match
    d.pop('min_coverage'), d.pop('pose_draws')
  if config.cloth_size == 1.0:  # ... and before the size was a setting
    d.pop('cloth_size')
  if config.physics == 'own':  # ... and before recordings of another physics
    d.pop('physics')
  if not config.hem_mass:  # ... and before a hem could be added
    d.pop('hem_mass')
  if physsim.scaled_edge_solref(cloth_mesh(config).shortest_edge, 1.0) == 1.0:
    d.pop('scaled_edges')  # the same edges either way, as before the setting
  return d


def open_workdir(workdir: str, config: Config, backend: str, params=None) -> dict:
  """Creates or checks ``dataset.json``; a resume must match the config."""
  os.makedirs(workdir, exist_ok=True)
  dataset.clean_tmp(workdir)
  ident = identity(config, backend)
  if params is not None:
    ident['params'] = {
      m: np.stack(list(p), 1).round(12).tolist() for m, p in params.items()
    }
  info_path = os.path.join(workdir, 'dataset.json')
  if os.path.isfile(info_path):
    info = dataset.read_json(info_path)
    old = info.get('config', {})
    diff = sorted(k for k in set(old) | set(ident) if old.get(k) != ident.get(k))
    if diff:
      raise ValueError(
        f'{info_path}: this folder holds a dataset made with a different config '
        f'({", ".join(f"{k}: {old.get(k)!r} -> {ident.get(k)!r}" for k in diff)}); '
        'use another --out or the same settings'
      )
    return info
  return dataset.write_dataset_info(
    workdir,
    seed=config.seed,
    config=ident,
    jax_backend=jax.default_backend(),
    pose_ranges=POSES[config.poses].to_dict(),
  )


def check_workdir(workdir: str, config: Config, backend: str, params=None) -> None:
  """What ``open_workdir`` checks, read-only (processes other than 0)."""
  info = dataset.read_json(os.path.join(workdir, 'dataset.json'))
  ident = identity(config, backend)
  if params is not None:
    ident['params'] = {
      m: np.stack(list(p), 1).round(12).tolist() for m, p in params.items()
    }
  if info.get('config') != json.loads(json.dumps(ident)):
    raise ValueError(f"{workdir}/dataset.json: another config than this process's")


def gathered_counts(workdir: str, materials) -> dict:
  """Every process's counts summed (``.counts.<i>.json``)."""
  total = {
    m: {'existing': 0, 'written': 0, 'valid': 0, 'invalid': 0} for m in materials
  }
  for i in range(jax.process_count()):
    part = dataset.read_json(os.path.join(workdir, f'.counts.{i}.json'))
    for m, c in part.items():
      for k, v in c.items():
        total[m][k] += v
  return total


def sequence_meta(config: Config, row: dict, intrinsics, mesh_name: str,
                   backend: str, poses, depth) -> dict:  # fmt: skip
  """A written sequence's ``meta.json``: its index row, the sweep's settings,
  its (C,) camera ``poses`` and, for a valid world (``depth`` (C, T, H, W);
  None for one that blew up), how many of its frames show no cloth."""
  return {
    **row,
    'fps': config.fps,
    'warmup_s': config.warmup,
    'intrinsics': intrinsics.to_dict(),
    'extrinsics': [
      physsim.pose_to_dict(physsim.Pose(poses.rotation[c], poses.position[c]))
      for c in range(config.cameras)
    ],
    'mesh': mesh_name,
    'garment': config.garment,
    'seed': config.seed,
    'backend': backend,
    'gust_intensity': config.gust_intensity,
    **({'physics': config.physics} if config.physics != 'own' else {}),
    **({'hem_mass': config.hem_mass} if config.hem_mass else {}),
    'noise': config.noise,
    **({'rgb_color': list(embedding.rgb_color(row['material']))} if config.rgb else {}),
    'empty_frames': None
    if depth is None
    else int(np.sum(~(depth > 0).any(axis=(-1, -2)))),
  }


def montage_path(workdir: str, material: str) -> str:
  return os.path.join(workdir, f'montage_{material}.png')


def montage(workdir: str, material: str, rows: list[dict], n: int = 6) -> str | None:
  """A grid of camera-0 frames (rows: sequences, columns: time), read from disk."""
  rows = [r for r in rows if r['valid']][:n]
  if not rows:
    return None
  seqs = [
    dataset.read_sequence(
      dataset.sequence_dir(workdir, material, r['seq_id']), cameras=[0], rgb=False
    )
    for r in rows
  ]
  t = seqs[0].depth.shape[1]
  cols = np.unique(np.linspace(0, t - 1, min(n, t)).round().astype(int))
  valid = np.concatenate([s.depth[0][cols][s.depth[0][cols] > 0] for s in seqs])
  lo, hi = np.percentile(valid, [1, 99]) if valid.size else (0.0, 1.0)
  plt = files.pyplot()
  cmap = plt.get_cmap('viridis').with_extremes(bad='white')
  fig, axes = plt.subplots(
    len(seqs), len(cols), figsize=(1.6 * len(cols) + 1.0, 1.6 * len(seqs) + 0.4),
    squeeze=False, layout='constrained',  # labels and colour bar inside the canvas
  )  # fmt: skip
  for i, (s, r) in enumerate(zip(seqs, rows, strict=True)):
    for j, c in enumerate(cols):
      ax = axes[i, j]
      d = s.depth[0, c]
      im = ax.imshow(np.ma.masked_equal(d, 0.0), cmap=cmap, vmin=lo, vmax=hi)
      ax.set(xticks=[], yticks=[])
      if i == 0:
        ax.set_title(f't={c / s.meta["fps"]:.2f} s', fontsize=7)
      if j == 0:
        ax.set_ylabel(
          f'{r["seq_id"]}\nb{r["bending_scale"]:.2g} w{r["wind_speed"]:.2g}\n'
          f'a{r["area_weight"]:.3g}',
          fontsize=6,
        )
  fig.colorbar(im, ax=axes, shrink=0.6, label='depth, m (white: invalid)')
  fig.suptitle(f'{material}, camera 0', fontsize=9)
  path = montage_path(workdir, material)
  files.savefig(fig, path, dpi=110)
  plt.close(fig)
  return path
