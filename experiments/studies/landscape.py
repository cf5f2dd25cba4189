"""The estimate's objective landscape around a known truth, and what physics can tell apart.

For a recording with ground truth (a dataset sequence folder) and a trained
PhySNet run, this evaluates the estimate's objective (``experiments.pipeline.objective``;
with ``--distance=shape`` no network is needed, and "PSD" below reads as the
shape's discrepancy, m^2):

  (a) along each parameter through the truth, the other two held at the truth;
  (b) over a grid of the (wind speed, area weight) plane at the true bending;

and, on the same grid's simulations without any network, the motion statistics
(``physsim.motion.motion_stats``: mean deflection, the centre's dominant
frequency, its flutter share) against the dimensionless load ratio
``rho v^2 / (w g)`` (air density 1 kg/m^3 as ArcSim, g = 9.81 m/s^2). Where a
statistic is a function of that ratio alone, the dynamics cannot separate wind
from area weight along the ratio's iso-lines; ``landscape.json`` gives, per
statistic and for the PSD, the variance share a cubic in log ratio explains and
the share gained by also knowing the wind.

``experiments/landscape.py`` is its command line. Writes ``landscape_1d.png``, ``landscape_wind_weight.png``, ``identifiability.png``
and ``landscape.json``. Simulations run in batches of ``batch`` candidates (one
MJX batch on a GPU); finished batches are kept in ``landscape_state.npz`` and a
rerun resumes from them.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import cli, embedding, evaluation, files, progress  # noqa: E402
from experiments.pipeline import objective as est  # noqa: E402
from experiments.pipeline import recording as recording_lib  # noqa: E402
from experiments.studies import separability  # noqa: E402

STATS = ('mean_deflection_m', 'centre_dominant_hz', 'flutter_fraction')
STATE_FILE = 'landscape_state.npz'


@dataclasses.dataclass(frozen=True)
class Config:
  """A landscape study.

  Attributes:
    objective: the estimate settings whose objective is mapped (simulation
      size, frames, gusts, backend, seed; ``material`` is the recording's).
    points_1d: values per parameter along its whole range (the truth added).
    grid: (wind speed, area weight) grid points per side.
    batch: candidates simulated per call.
  """

  objective: est.EstimateConfig = cli.nested(
    est.EstimateConfig().replace(distance=est.NETWORK_DISTANCE),
    skip=('simulation.material',),
  )
  points_1d: int = 15
  grid: int = 9
  batch: int = 16


PRESETS = {
  'default': Config(),
  # The demo's estimate settings at a few points: about a minute on a CPU.
  'smoke': Config(
    objective=est.EstimateConfig().replace(
      distance=est.NETWORK_DISTANCE, cloth_resolution=10, frames=16, warmup=0.5
    ),
    points_1d=5,
    grid=4,
    batch=8,
  ),
}


def points(config: Config, u_truth: np.ndarray) -> tuple[np.ndarray, dict]:
  """All unit-cube points of the study, in evaluation order.

  Args:
    config: the study.
    u_truth: (3,) the truth in unit coordinates.

  Returns:
    ``(U, parts)``: ``U`` is (N, 3); ``parts`` maps 'line_<i>' (one per
    parameter, its ``points_1d + 1`` points sorted along parameter i) and
    'grid' (``grid**2`` points, wind-major: row = wind index) to index arrays
    into ``U``.
  """
  u_truth = np.asarray(u_truth, np.float64)
  blocks, parts, n = [], {}, 0
  for i in range(3):
    line = np.unique(np.append(np.linspace(-1, 1, config.points_1d), u_truth[i]))
    block = np.tile(u_truth, (len(line), 1))
    block[:, i] = line
    blocks.append(block)
    parts[f'line_{i}'] = np.arange(n, n + len(block))
    n += len(block)
  g = np.linspace(-1, 1, config.grid)
  wind, weight = np.meshgrid(g, g, indexing='ij')
  block = np.tile(u_truth, (config.grid**2, 1))
  block[:, 1], block[:, 2] = wind.ravel(), weight.ravel()
  blocks.append(block)
  parts['grid'] = np.arange(n, n + len(block))
  return np.concatenate(blocks), parts


def ratio_r2(stat, wind_speed, area_weight) -> dict:
  """How much of a statistic the load ratio explains, and what wind adds.

  Least-squares fits of ``stat`` against a cubic in log ratio, then against
  that cubic plus a quadratic in log wind speed (so area weight enters too).

  Args:
    stat: (N,) values; non-finite ones are left out.
    wind_speed: (N,) m/s.
    area_weight: (N,) kg/m^2.

  Returns:
    ``{'r2_ratio', 'r2_ratio_and_wind', 'n'}`` (NaN when too few points).
  """
  y = np.asarray(stat, np.float64)
  r = separability.nested_r2(
    y,
    np.log(physsim.load_ratio(wind_speed, area_weight)),
    np.log(np.asarray(wind_speed, np.float64)),
  )
  return {
    'r2_ratio': r['r2_base'],
    'r2_ratio_and_wind': r['r2_added'],
    'n': int(np.isfinite(y).sum()),
  }


def _signature(
  config: Config, recording: recording_lib.Recording, model_dir: str
) -> str:
  return json.dumps(
    {
      'config': est.record(config),
      'recording': os.path.abspath(recording.source),
      'model': os.path.abspath(model_dir) if model_dir else '',
    },
    sort_keys=True,
  )


def evaluate_points(problem: est.Problem, U, batch, state_path, signature):
  """(N,) PSD and (N, len(STATS)) motion stats of unit points ``U``, resumable."""
  evaluate = evaluation.Evaluator()
  mesh, fps = evaluate.objective(problem).mesh, problem.config.simulation.fps
  n = len(U)
  psd = np.full(n, np.nan)
  stats = np.full((n, len(STATS)), np.nan)
  done = 0
  if os.path.exists(state_path):
    with np.load(state_path) as z:
      if str(z['signature']) != signature:
        raise ValueError(f'{state_path} belongs to another study; use a new workdir')
      done = int(z['done'])
      psd[:done], stats[:done] = z['psd'][:done], z['stats'][:done]
  with progress.Bar(n, 'simulations', 'sim') as bar:
    bar.skip(done)
    while done < n:
      u = U[done : done + batch]
      scores = evaluate([problem], [u], [done], positions=True)[0]
      y, positions, valid = scores.psd, scores.positions, scores.valid
      psd[done : done + len(u)] = y
      for j in range(len(u)):
        if valid[j]:
          s = physsim.motion.motion_stats(mesh, np.asarray(positions[j]), fps)
          stats[done + j] = [s[k] for k in STATS]
      done += len(u)
      bar.done(len(u))

      def write(p, done=done):
        with open(p, 'wb') as f:
          np.savez(f, signature=signature, done=done, psd=psd, stats=stats)

      files.write_atomic(state_path, write)
  return psd, stats


def run(
  config: Config,
  recording_dir: str,
  model_dir: str,
  workdir: str,
  image_size: int = 256,
) -> dict:
  """Runs (or resumes) the study; returns and writes ``landscape.json``.
  ``model_dir`` may be '' with the shape distance (frames at ``image_size``)."""
  t0 = time.time()
  config, rec, problem = _problem(config, recording_dir, model_dir, image_size)
  space = problem.space
  truth = physsim.params.make(**rec.truth)
  u_truth = np.asarray(physsim.to_unit(truth, space), np.float64).ravel()
  U, parts = points(config, u_truth)
  os.makedirs(workdir, exist_ok=True)
  psd, stats = evaluate_points(
    problem,
    U,
    config.batch,
    os.path.join(workdir, STATE_FILE),
    _signature(config, rec, model_dir),
  )
  P = np.stack([np.ravel(a) for a in physsim.from_unit(U, space)], 1)  # (N, 3)
  g = parts['grid']
  wind, weight = P[g, 1], P[g, 2]
  truth_ratio = float(
    physsim.load_ratio(rec.truth['wind_speed'], rec.truth['area_weight'])
  )
  line_0 = parts['line_0']
  result = {
    'recording': rec.source,
    'model': model_dir,
    'material': config.objective.simulation.material,
    'truth': rec.truth,
    'truth_ratio': truth_ratio,
    'psd_truth': float(psd[line_0][np.argmin(np.abs(U[line_0, 0] - u_truth[0]))]),
    'line': _lines(parts, psd, P, rec.truth),
    'grid': _grid(psd[g], wind, weight, config.grid),
    'identifiability': {
      'stats': {s: stats[g, j].tolist() for j, s in enumerate(STATS)},
      'ratio': physsim.load_ratio(wind, weight).tolist(),
      **{s: ratio_r2(stats[g, j], wind, weight) for j, s in enumerate(STATS)},
    },
    'failed_simulations': int(np.sum(~np.isfinite(psd))),
    'config': est.record(config),
    'seconds': time.time() - t0,
  }  # fmt: skip
  files.write_json(os.path.join(workdir, 'landscape.json'), result)
  plot_lines(result['line'], space, os.path.join(workdir, 'landscape_1d.png'))
  plot_grid(
    result['grid'], rec.truth, os.path.join(workdir, 'landscape_wind_weight.png')
  )
  plot_identifiability(
    result['identifiability'], wind, truth_ratio,
    os.path.join(workdir, 'identifiability.png'),
  )  # fmt: skip
  return result


def _problem(config: Config, recording_dir: str, model_dir: str, image_size: int):
  """(the config for the recording's fabric, the recording, its estimate
  problem).

  Raises:
    ValueError: a recording without ground truth.
  """
  net = embedding.for_distance(model_dir, config.objective.scoring.distance, image_size)
  meta = recording_lib.read_json(os.path.join(recording_dir, 'meta.json'))
  obj_config = config.objective.replace(
    material=meta.get('material', config.objective.simulation.material)
  )
  config = dataclasses.replace(config, objective=obj_config)
  rec = recording_lib.load_recording(
    recording_dir,
    fps=obj_config.simulation.fps,
    size=net.image_size,
    frames=obj_config.simulation.frames,
  )
  if rec.truth is None:
    raise ValueError(f'{recording_dir}: no ground truth (meta.json wind_speed, ...)')
  return config, rec, est.make_problem(obj_config, net, rec)


def _lines(parts: dict, psd: np.ndarray, P: np.ndarray, truth: dict) -> dict:
  """Per parameter, the PSD along its line through the truth (``P``: (N, 3)
  physical points) and where it is least."""
  lines = {}
  for i, name in enumerate(physsim.Params._fields):
    idx = parts[f'line_{i}']
    y = psd[idx]
    best = int(np.nanargmin(y)) if np.isfinite(y).any() else None
    lines[name] = {
      'values': P[idx, i].tolist(),
      'psd': y.tolist(),
      'argmin': None if best is None else float(P[idx[best], i]),
      'truth': float(truth[name]),
    }
  return lines


def _grid(grid_psd: np.ndarray, wind: np.ndarray, weight: np.ndarray,
          n: int) -> dict:  # fmt: skip
  """The PSD over the (wind, area weight) grid at the true bending, where it
  is least and how much of it the load ratio explains."""
  k = int(np.nanargmin(grid_psd)) if np.isfinite(grid_psd).any() else None
  return {
    'wind_speed': np.unique(wind).tolist(),
    'area_weight': np.unique(weight).tolist(),
    'psd': grid_psd.reshape(n, n).tolist(),  # [wind, weight]
    'argmin': None
    if k is None
    else {'wind_speed': float(wind[k]), 'area_weight': float(weight[k]),
          'ratio': float(physsim.load_ratio(wind[k], weight[k])), 'psd': float(grid_psd[k])},
    'psd_vs_ratio': ratio_r2(np.log(grid_psd), wind, weight),
  }  # fmt: skip


# -------------------------------------------------------------------- figures


def plot_lines(lines: dict, space, path: str) -> None:
  """PSD along each parameter through the truth (three panels)."""
  labels = ['bending scale', 'wind speed (m/s)', 'area weight (kg/m$^2$)']
  fig, axes = plt.subplots(1, 3, figsize=(13, 3.4))
  for ax, (name, line), label in zip(axes, lines.items(), labels, strict=True):
    ax.plot(line['values'], line['psd'], 'o-', color='k', ms=4)
    ax.axvline(line['truth'], color='r', lw=1, label='truth')
    ax.set(xlabel=label, ylabel='PSD', xlim=getattr(space, name))
    if name == 'bending_scale':
      ax.set_xscale('log')
    ax.legend(fontsize=8)
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def plot_grid(grid: dict, truth: dict, path: str) -> None:
  """log PSD over (wind speed, area weight) with iso-lines of v^2 / w."""
  v, w = np.asarray(grid['wind_speed']), np.asarray(grid['area_weight'])
  z = np.log10(np.asarray(grid['psd']))  # [wind, weight]
  fig, ax = plt.subplots(figsize=(6, 4.6))
  dv, dw = np.diff(v).mean() / 2, np.diff(w).mean() / 2
  im = ax.imshow(
    z.T, origin='lower', aspect='auto', cmap='viridis',
    extent=(v[0] - dv, v[-1] + dv, w[0] - dw, w[-1] + dw),
  )  # fmt: skip
  fig.colorbar(im, ax=ax, label='log$_{10}$ PSD')
  fv, fw = np.meshgrid(np.linspace(v[0], v[-1], 100), np.linspace(w[0], w[-1], 100))
  cs = ax.contour(
    fv, fw, physsim.load_ratio(fv, fw), levels=8, colors='w', linewidths=0.7
  )
  ax.clabel(cs, fontsize=7, fmt='%.1f')
  ax.plot(truth['wind_speed'], truth['area_weight'], 'r*', ms=14, label='truth')
  if grid['argmin'] is not None:
    a = grid['argmin']
    ax.plot(a['wind_speed'], a['area_weight'], 'wx', ms=10, label='grid minimum')
  ax.set(xlabel='wind speed (m/s)', ylabel='area weight (kg/m$^2$)',
         title='PSD; white: $\\rho v^2 / (w g)$')  # fmt: skip
  ax.legend(fontsize=8, loc='upper left')
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def plot_identifiability(ident: dict, wind, truth_ratio: float, path: str) -> None:
  """Each motion statistic against the load ratio, coloured by wind speed."""
  ratio = np.asarray(ident['ratio'])
  fig, axes = plt.subplots(1, len(STATS), figsize=(14, 3.8), layout='constrained')
  for ax, s in zip(axes, STATS, strict=True):
    sc = ax.scatter(ratio, ident['stats'][s], c=wind, cmap='plasma', s=22)
    ax.axvline(truth_ratio, color='r', lw=1)
    r = ident[s]
    ax.set(xscale='log', xlabel='$\\rho v^2 / (w g)$', ylabel=s,
           title=f'R$^2$ ratio {r["r2_ratio"]:.2f}, +wind {r["r2_ratio_and_wind"]:.2f}')  # fmt: skip
  fig.colorbar(sc, ax=axes, label='wind speed (m/s)')
  files.savefig(fig, path, dpi=90)
  plt.close(fig)
