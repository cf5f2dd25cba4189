"""Where the demo's sim-to-real gap comes from: one real-like difference at a time.

The demo's recording differs from its training data in six ways (gustier wind, a
finer mesh, 24 fps, the depth-sensor model, unseen camera poses, framing checked).
This makes the demo's recording again as variants of a training-like recording
(the same ground truth and gusts: the same seed), each adding one difference, and
the demo's own recording with all of them. For each it evaluates the estimate's
objective along wind speed through the truth (bending and area weight held at
the truth) with the demo's trained network, with the candidates passed through
the sensor model (the estimate's default) and without, and reports where the PSD
is least. Prints a table and writes ``<workdir>/sim_to_real.json`` (and the PSD
lines as ``sim_to_real.png``).

  python -m experiments.demo --workdir=out/demo   # the network
  python -m benchmarks.sim_to_real --model=out/demo/model/gray_interlock
"""

import dataclasses
import os
import time

import matplotlib
import numpy as np
from absl import logging

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import cli, demo, embedding, files, search  # noqa: E402
from experiments.pipeline import datasets as gen  # noqa: E402
from experiments.pipeline import objective as objective_lib  # noqa: E402
from experiments.pipeline import recording as recording_lib  # noqa: E402
from experiments.studies import landscape  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Args:
  """The sim-to-real study.

  Attributes:
    model: the demo's network.
    workdir: recordings, JSON, PNG.
    material: the network's fabric.
    seed: the demo's --seed (recording and search).
    points: wind speeds across the range (+ truth).
    backend: simulator.
  """

  model: str = 'out/demo/model/gray_interlock'
  workdir: str = 'out/sim_to_real'
  material: str = 'gray_interlock'
  seed: int = 0
  points: int = 11
  backend: str = cli.choice('auto', ['auto', 'mjx', 'c'])


PRESETS = {'default': Args()}


def variants(train_cfg: gen.Config, rec_cfg: gen.Config) -> dict[str, gen.Config]:
  """Recording configs: training-like, one real-like difference each, all."""
  base = dataclasses.replace(
    rec_cfg,
    cloth_resolution=train_cfg.cloth_resolution,
    fps=train_cfg.fps,
    frames=train_cfg.frames,
    timestep=train_cfg.timestep,
    noise=False,
    poses='train',
    gust_intensity=train_cfg.gust_intensity,
    min_coverage=0.0,  # a re-drawn pose would change two things at once
  )
  one = {
    'gusts': dict(gust_intensity=rec_cfg.gust_intensity),
    'finer mesh': dict(cloth_resolution=rec_cfg.cloth_resolution),
    '24 fps': dict(fps=rec_cfg.fps, frames=rec_cfg.frames, timestep=rec_cfg.timestep),
    'sensor model': dict(noise=True),
    'unseen poses': dict(poses=rec_cfg.poses),
  }
  out = {'training-like': base}
  out.update({k: dataclasses.replace(base, **v) for k, v in one.items()})
  out['all (the demo recording)'] = rec_cfg
  return out


def wind_line(u_truth: np.ndarray, points: int) -> np.ndarray:
  """(n, 3) unit points along wind through the truth, sorted by wind
  (``experiments.studies.landscape``'s line for that parameter, without its grid)."""
  u, parts = landscape.points(landscape.Config(points_1d=points, grid=0), u_truth)
  return u[parts['line_1']]


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  t0 = time.time()
  model_dir, wd = args.model, args.workdir
  if not os.path.isdir(model_dir):
    raise ValueError(
      f'--model={model_dir}: no such run (python -m experiments.demo first)'
    )
  net = embedding.load_embedding(model_dir)
  material = args.material
  train_cfg, rec_cfg, _, est_cfg = demo.configs(material, 24, args.seed, args.backend)
  # the network's PSD, not the estimate's default (the shape)
  est_cfg = est_cfg.replace(distance=objective_lib.NETWORK_DISTANCE)
  size = net.image_size
  results, truth0 = {}, None
  evaluator = search.Evaluator()
  for name, cfg in variants(train_cfg, rec_cfg).items():
    root = os.path.join(wd, 'recordings', name.split(' ')[0].replace('-', '_'))
    gen.run(cfg, root)
    rec = recording_lib.load_recording(
      physsim.dataset.sequence_dir(root, material, '0000'),
      fps=est_cfg.simulation.fps,
      size=size,
      frames=est_cfg.simulation.frames,
    )
    truth0 = truth0 or rec.truth
    if rec.truth != truth0:
      raise ValueError(f'{root}: truth {rec.truth} differs from {truth0}')
    row = {}
    for noise in (True, False):
      problem = objective_lib.make_problem(
        est_cfg.replace(sensor_noise=noise), net, rec
      )
      u_truth = np.asarray(
        physsim.to_unit(physsim.params.make(**rec.truth), problem.space), np.float64
      ).ravel()
      line = wind_line(u_truth, args.points)
      psd = search.score(problem, line, evaluator=evaluator).psd
      wind = np.ravel(physsim.from_unit(line, problem.space)[1])
      k = int(np.nanargmin(psd))
      row['candidates with sensor model' if noise else 'clean candidates'] = {
        'wind_speed': wind.tolist(),
        'psd': psd.tolist(),
        'argmin_wind': float(wind[k]),
        'psd_at_truth': float(psd[np.argmin(np.abs(wind - rec.truth['wind_speed']))]),
        'psd_min': float(psd[k]),
      }
    results[name] = row
    print(
      f'{name}: ' + ', '.join(f'{k} {v["argmin_wind"]:.2f}' for k, v in row.items())
    )
  report = {
    'truth': truth0,
    'model': model_dir,
    'variants': results,
    'seconds': time.time() - t0,
  }
  files.write_json(os.path.join(wd, 'sim_to_real.json'), report)
  plot(results, truth0['wind_speed'], os.path.join(wd, 'sim_to_real.png'))
  print(table(report))


def table(report: dict) -> str:
  truth = report['truth']['wind_speed']
  lines = [
    f'PSD minimum along wind speed (truth {truth:.2f} m/s; PSD at the minimum / at the truth)',
    '| recording | clean candidates | candidates with sensor model |',
    '|---|---|---|',
  ]
  for name, row in report['variants'].items():
    cells = [
      f'{r["argmin_wind"]:.2f} m/s ({r["psd_min"]:.3g} / {r["psd_at_truth"]:.3g})'
      for r in (row['clean candidates'], row['candidates with sensor model'])
    ]
    lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
  return '\n'.join(lines)


def plot(results: dict, truth: float, path: str) -> None:
  fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
  for ax, key in zip(
    axes, ('clean candidates', 'candidates with sensor model'), strict=True
  ):
    for name, row in results.items():
      ax.semilogy(row[key]['wind_speed'], row[key]['psd'], marker='.', label=name)
    ax.axvline(truth, color='k', ls='--', lw=0.8)
    ax.set_title(key, fontsize=9)
    ax.set_xlabel('wind speed (m/s)')
  axes[0].set_ylabel('PSD to the recording')
  axes[1].legend(fontsize=7)
  fig.tight_layout()
  files.savefig(fig, path, dpi=120)
  plt.close(fig)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
