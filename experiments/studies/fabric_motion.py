"""Does the simulated cloth move like fabric? A sweep over wind, bending and settings.

Part 1 (the chosen settings): the centre's motion amplitude, dominant frequency
and flutter share against wind speed, for a light and a stiff fabric at three
bending scales. Part 2 (constraint and solver settings): edge stiffness, time
step and steady vs gusty wind, compared on the same motion statistics and on
edge strain, at the paper's fan speeds.

``experiments/fabric_motion.py`` is its command line (presets: full, smoke).

Writes ``motion_sweep.json``, ``motion_vs_wind.png`` and ``settings.md``; each
finished group is stored as it completes, so a rerun resumes.
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax
import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import cli, files  # noqa: E402
from physsim import motion  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Config:
  """The motion study.

  Attributes:
    fabrics: fabric names (physsim.FABRICS), each at its real area weight.
    winds: wind speeds of part 1, m/s.
    bendings: bending scales of part 1.
    gusts: RMS relative gust intensity.
    resolution: cloth vertices per side.
    frames: frames per simulation.
    fps: frame rate, Hz.
    warmup: simulated seconds before the first frame.
    variants: settings variants of part 2 (fabric_motion.VARIANTS).
    variant_winds: wind speeds of part 2, m/s.
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
    seed: gust seed.
  """

  fabrics: tuple[str, ...] = ('red_violet', 'black_denim')
  winds: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
  bendings: tuple[float, ...] = (0.1, 1.0, 10.0)
  gusts: float = 0.2
  resolution: int = 25
  frames: int = 60
  fps: float = 20.0
  warmup: float = 1.0
  variants: tuple[str, ...] = ('chosen', 'edges_10ms', 'edges_20ms', 'dt_1ms', 'steady')
  variant_winds: tuple[float, ...] = (2.5, 3.0)
  backend: str = cli.choice('auto', physsim.BACKENDS)
  seed: int = 0


PRESETS = {
  'full': Config(),
  'smoke': Config(
    winds=(2.0, 5.0),
    bendings=(1.0,),
    resolution=6,
    frames=8,
    warmup=0.2,
    variants=('chosen', 'edges_20ms'),
    variant_winds=(3.0,),
  ),
}

# name -> (SimConfig overrides, gust intensity or None for the config's)
VARIANTS = {
  'chosen': (
    {},
    None,
  ),  # edge solref 4 ms (= 2 dt, MuJoCo's stiffest), dt 2 ms, CG x50
  'edges_10ms': ({'edge_solref': 0.01}, None),
  'edges_20ms': ({'edge_solref': 0.02}, None),
  'dt_1ms': ({'timestep': 0.001, 'edge_solref': 0.002}, None),
  'steady': ({}, 0.0),
}


def _simulate_group(config: Config, variant: str, winds, bendings):
  """Simulates every fabric x wind x bending under one settings variant.

  One compiled model serves all fabrics (``simulate(material=...)``), so the
  whole group is one batch.
  """
  overrides, gusts = VARIANTS[variant]
  sim_config = dataclasses.replace(physsim.SimConfig(), **overrides)
  model = physsim.build(
    physsim.square(config.resolution), config.fabrics[0], sim_config
  )
  f, w, b = np.meshgrid(np.arange(len(config.fabrics)), winds, bendings, indexing='ij')
  f, w, b = f.ravel(), w.ravel(), b.ravel()
  names = [config.fabrics[i] for i in f]
  weight = np.array([physsim.fabric(n).real_area_weight for n in names])
  p = physsim.params.make(b, w, weight)
  backend = physsim.resolve_backend(config.backend)
  t0 = time.time()
  out = physsim.simulate(
    model,
    p,
    frames=config.frames,
    fps=config.fps,
    warmup=config.warmup,
    wind=physsim.Wind(gust_intensity=config.gusts if gusts is None else gusts),
    key=jax.random.key(config.seed),
    backend=backend,
    material=names,
  )
  seconds = time.time() - t0
  stats = motion.batch_stats(model.mesh, out.positions, out.valid, config.fps)
  rows = [
    {
      'fabric': names[i],
      'variant': variant,
      'wind_speed': float(w[i]),
      'bending_scale': float(b[i]),
      'area_weight': float(weight[i]),
      **st,
    }
    for i, st in enumerate(stats)
  ]
  return {'rows': rows, 'seconds': seconds, 'backend': backend, 'worlds': w.size}


def run(config: Config, workdir: str) -> dict:
  """Runs both parts, resuming from finished groups in ``workdir``."""
  os.makedirs(workdir, exist_ok=True)
  path = os.path.join(workdir, 'motion_sweep.json')
  done = files.resume(path, config).get('groups', {})
  groups = [('sweep', 'chosen', config.winds, config.bendings)]
  groups += [('settings', v, config.variant_winds, (1.0,)) for v in config.variants]
  for part, variant, winds, bendings in groups:
    key = f'{part}/{variant}'
    if key in done:
      continue
    n = len(config.fabrics) * len(winds) * len(bendings)
    print(f'{key}: simulating {n} worlds ...', flush=True)
    done[key] = _simulate_group(config, variant, winds, bendings)
    files.write_json(
      path, {'config': dataclasses.asdict(config), 'groups': done}
    )  # resume point
  plot_sweep(config, done, os.path.join(workdir, 'motion_vs_wind.png'))
  table = settings_table(config, done)
  files.write_text(os.path.join(workdir, 'settings.md'), table + '\n')
  print(sweep_table(config, done))
  print(table)
  return done


def _rows(done, part):
  return [r for k, g in done.items() if k.startswith(part + '/') for r in g['rows']]


def sweep_table(config: Config, done) -> str:
  lines = [
    '| fabric | bending | wind m/s | centre p-p cm | dominant Hz | flutter share '
    '| mean deflection m | strain p99 |',
    '|---|---|---|---|---|---|---|---|',
  ]
  for r in _rows(done, 'sweep'):
    if not r['valid']:
      lines.append(
        f'| {r["fabric"]} | {r["bending_scale"]:g} | {r["wind_speed"]:g} | '
        'blew up | | | | |'
      )
      continue
    lines.append(
      f'| {r["fabric"]} | {r["bending_scale"]:g} | {r["wind_speed"]:g} | '
      f'{100 * r["centre_amplitude_m"]:.1f} | {r["centre_dominant_hz"]:.2f} | '
      f'{r["flutter_fraction"]:.2f} | {r["mean_deflection_m"]:.2f} | '
      f'{r["strain_p99"]:.3f} |'
    )
  return '\n'.join(lines)


def settings_table(config: Config, done) -> str:
  lines = [
    '| settings | fabric | wind m/s | strain p99 | strain max | top sag cm '
    '| centre p-p cm | dominant Hz | flutter share | s per world |',
    '|---|---|---|---|---|---|---|---|---|---|',
  ]
  for key, g in done.items():
    if not key.startswith('settings/'):
      continue
    for r in g['rows']:
      head = f'| {r["variant"]} | {r["fabric"]} | {r["wind_speed"]:g} |'
      if not r['valid']:
        lines.append(head + ' blew up | | | | | | |')
        continue
      lines.append(
        head + f' {r["strain_p99"]:.3f} | {r["strain_max"]:.3f} | '
        f'{100 * r["sag_m"]:.1f} | {100 * r["centre_amplitude_m"]:.1f} | '
        f'{r["centre_dominant_hz"]:.2f} | {r["flutter_fraction"]:.2f} | '
        f'{g["seconds"] / g["worlds"]:.2f} |'
      )
  return '\n'.join(lines)


def plot_sweep(config: Config, done, path: str) -> None:
  rows = [r for r in _rows(done, 'sweep') if r['valid']]
  metrics = [
    ('centre_amplitude_m', 'centre peak-to-peak (m)'),
    ('centre_dominant_hz', 'dominant frequency (Hz)'),
    ('flutter_fraction', f'power share above {motion.FLUTTER_HZ:g} Hz'),
    ('mean_deflection_m', 'mean wind-wise deflection (m)'),
  ]
  fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.6))
  colours = plt.rcParams['axes.prop_cycle'].by_key()['color']
  styles = ['-', '--', ':', '-.']
  for ax, (m, label) in zip(axes, metrics, strict=True):
    for i, fab in enumerate(config.fabrics):
      for j, b in enumerate(config.bendings):
        sel = [r for r in rows if r['fabric'] == fab and r['bending_scale'] == b]
        ax.plot(
          [r['wind_speed'] for r in sel],
          [r[m] for r in sel],
          styles[j % len(styles)],
          marker='o',
          ms=3,
          color=colours[i % len(colours)],
          label=f'{fab} bending x{b:g}',
        )
    ax.set(xlabel='wind speed (m/s)', ylabel=label)
    ax.grid(alpha=0.3)
  axes[0].legend(fontsize=7)
  fig.suptitle(
    f'{config.resolution}x{config.resolution} cloth, gusts {config.gusts:g}, '
    f'{config.frames / config.fps:g} s after {config.warmup:g} s warm-up',
    fontsize=10,
  )
  fig.tight_layout()
  files.savefig(fig, path, dpi=100)
  plt.close(fig)
