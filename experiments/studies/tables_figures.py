"""The tables' figures: the paper's Figure 4 (true and estimated bending
matrices) and every candidate the searches scored against the truth (the
PSD landscape as sampled)."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import files  # noqa: E402


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
