"""Does the sheet move the same on the estimate's mesh as on a finer one?

The real-like recordings are simulated on a finer mesh (33x33) than the
estimate's candidates (25x25). Where the two meshes move differently under the
same wind, the estimate is biased before any network is involved. This
simulates the same fabrics, winds and gust histories (a few seeds; a seed's
frozen turbulence is the same on every mesh) at several mesh resolutions and
compares the motion statistics of ``physsim.motion`` between meshes against how
much they change between gust seeds alone. For each world it also reports the
*equivalent wind*: the wind at which the estimate's mesh has the same mean
wind-wise deflection (linear interpolation along its wind sweep up to where the
curve first goes flat; beyond that, or outside the sweep, it is not defined).
Prints a table and writes ``mesh_convergence.json`` and
``mesh_convergence.png``; each finished resolution is saved as it completes, so
a rerun resumes.

  python -m benchmarks.mesh_convergence --workdir=out/mesh
  python -m benchmarks.mesh_convergence --preset=smoke --workdir=/tmp/m
"""

import dataclasses
import os
import time

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import physsim  # noqa: E402
from experiments.pipeline import cli, files  # noqa: E402
from physsim import motion  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Config:
  """The mesh study.

  Attributes:
    fabrics: fabric names (physsim.FABRICS), each at its real area weight.
    winds: wind speeds, m/s.
    resolutions: cloth vertices per side of the meshes compared.
    estimate_resolution: the estimate's cloth (EstimateConfig.cloth_resolution).
    cloth_size: the square's side, metres (EstimateConfig.cloth_size); each
      mesh simulates at the step it needs (physsim.stable_timestep).
    bending: bending scale.
    gusts: RMS relative gust intensity.
    frames: frames per simulation.
    fps: frame rate, Hz.
    warmup: simulated seconds before the first frame.
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
    seeds: gust histories; each the same on every mesh.
    scaled_edges: the edges' time constant shrinks with the spacing
      (physsim.scaled_edge_solref: the same stretch stiffness on every
      mesh; the default); off: the fixed one of every mesh before.
  """

  fabrics: tuple[str, ...] = ('white_tablecloth', 'red_violet', 'black_denim')
  winds: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
  resolutions: tuple[int, ...] = (17, 25, 33)
  estimate_resolution: int = 25
  cloth_size: float = 1.0
  bending: float = 1.0
  gusts: float = 0.2
  frames: int = 60
  fps: float = 20.0
  warmup: float = 1.0
  backend: str = cli.choice('auto', physsim.BACKENDS)
  seeds: tuple[int, ...] = (0, 1, 2)
  scaled_edges: bool = True


@dataclasses.dataclass(frozen=True)
class Args:
  """The benchmark from the command line.

  Attributes:
    workdir: results and figures go here (resumed from what it holds).
    study: what is simulated.
  """

  workdir: str = 'out/mesh'
  study: Config = Config()


PRESETS = {
  'default': Config(),
  'smoke': Config(
    fabrics=('red_violet',),
    winds=(2.0, 4.0),
    resolutions=(6, 8),
    estimate_resolution=6,
    frames=8,
    warmup=0.2,
    seeds=(0, 1),
  ),
  # issue 39: the protocol's 20 cm swatch in a gentle fan (docs/protocol.md)
  'swatch': Config(
    fabrics=('gray_interlock',),
    winds=(1.0, 2.0, 3.0),
    resolutions=(9, 17, 25, 33),
    cloth_size=0.2,
    frames=30,
    warmup=1.0,
  ),
}
STATS = ('mean_deflection_m', 'centre_dominant_hz', 'flutter_fraction', 'strain_p99')
# A deflection curve rising by less than this per m/s carries no wind information.
_FLAT_M_PER_MS = 0.01


def simulate_resolution(config: Config, resolution: int) -> dict:
  """Every fabric x wind x gust seed on one mesh as one batch; motion statistics
  per world. A seed's gust modes do not depend on the mesh (``physsim.forces``),
  so world (fabric, wind, seed) sees the same gusts on every mesh."""
  mesh = physsim.square(resolution, config.cloth_size)
  model = physsim.build(
    mesh,
    config.fabrics[0],
    physsim.config_for_mesh(mesh, config.fps, scaled_edges=config.scaled_edges),
  )
  f, w, s = np.meshgrid(
    np.arange(len(config.fabrics)), config.winds, config.seeds, indexing='ij'
  )
  f, w, s = f.ravel(), w.ravel(), s.ravel()
  names = [config.fabrics[i] for i in f]
  weight = np.array([physsim.fabric(n).real_area_weight for n in names])
  p = physsim.params.make(np.full(w.size, config.bending), w, weight)
  t0 = time.time()
  out = physsim.simulate(
    model,
    p,
    frames=config.frames,
    fps=config.fps,
    warmup=config.warmup,
    wind=physsim.Wind(gust_intensity=config.gusts),
    key=jax.vmap(jax.random.key)(jnp.asarray(s)),  # one key per world: its seed
    backend=physsim.resolve_backend(config.backend),
    material=names,
  )
  stats = motion.batch_stats(mesh, out.positions, out.valid, config.fps)
  rows = [
    {
      'fabric': names[i],
      'wind_speed': float(w[i]),
      'seed': int(s[i]),
      'valid': st['valid'],
      **{k: st[k] for k in STATS if k in st},
    }
    for i, st in enumerate(stats)
  ]
  return {'rows': rows, 'seconds': time.time() - t0}


def equivalent_wind(winds, deflection, target: float, size: float = 1.0) -> float:
  """The wind at which a deflection-vs-wind curve reaches ``target``.

  Linear interpolation along the curve from the lowest wind, up to its first
  flat segment: beyond it the sheet is blown flat and deflects alike over a
  range of winds, so deflection no longer names a wind (NaN), as it is for a
  ``target`` outside the curve's range. A ``size`` m cloth deflects ``size``
  times as far, so its flat slope is too.
  """
  winds = np.asarray(winds, np.float64)
  d = np.asarray(deflection, np.float64)
  for k in range(len(winds) - 1):
    lo, hi = d[k], d[k + 1]
    if (hi - lo) / (winds[k + 1] - winds[k]) < _FLAT_M_PER_MS * size:
      return float('nan')
    if lo <= target <= hi:
      return float(winds[k] + (target - lo) / (hi - lo) * (winds[k + 1] - winds[k]))
  return float('nan')


def compare(config: Config, done: dict) -> list[dict]:
  """One row per fabric, wind and resolution, with the equivalent wind on the
  estimate's mesh of that world's mean deflection."""
  base = {
    (r['fabric'], r['wind_speed'], r['seed']): r
    for r in done[str(config.estimate_resolution)]['rows']
  }
  out = []
  for res in config.resolutions:
    for r in done[str(res)]['rows']:
      row = {'resolution': res, **r}
      curve = [base.get((r['fabric'], w, r['seed'])) for w in config.winds]
      if r['valid'] and all(c and c['valid'] for c in curve):
        row['equivalent_wind'] = equivalent_wind(
          config.winds,
          [c['mean_deflection_m'] for c in curve],
          r['mean_deflection_m'],
          config.cloth_size,
        )
      out.append(row)
  return out


def aggregate(rows: list[dict]) -> list[dict]:
  """Per fabric, wind and mesh: each statistic's mean and standard deviation
  over the gust seeds, and the mean equivalent wind where it is defined."""
  groups: dict = {}
  for r in rows:
    if r['valid']:
      groups.setdefault((r['fabric'], r['wind_speed'], r['resolution']), []).append(r)
  out = []
  for (fabric, wind, res), rs in sorted(groups.items()):
    row = {'fabric': fabric, 'wind_speed': wind, 'resolution': res, 'seeds': len(rs)}
    for k in STATS:
      v = np.array([r[k] for r in rs])
      row[k] = {'mean': float(v.mean()), 'std': float(v.std())}
    eq = np.array([r.get('equivalent_wind', np.nan) for r in rs])
    row['equivalent_wind'] = (
      float(eq[np.isfinite(eq)].mean()) if np.isfinite(eq).any() else None
    )
    out.append(row)
  return out


def spread(rows: list[dict]) -> dict:
  """How much each statistic changes between meshes (same fabric, wind and
  gusts) against between gust seeds (same fabric, wind and mesh): the mean
  range of each over its groups. A mesh effect is one clearly above chance."""
  out = {}
  for k in STATS:
    by_mesh, by_seed = {}, {}
    for r in rows:
      if r['valid']:
        by_mesh.setdefault((r['fabric'], r['wind_speed'], r['seed']), []).append(r[k])
        by_seed.setdefault((r['fabric'], r['wind_speed'], r['resolution']), []).append(
          r[k]
        )
    out[k] = {
      'between_meshes': float(np.mean([np.ptp(v) for v in by_mesh.values()])),
      'between_seeds': float(np.mean([np.ptp(v) for v in by_seed.values()])),
    }
  return out


def table(config: Config, rows: list[dict]) -> str:
  lines = [
    '| fabric | wind m/s | mesh | mean deflection m | dominant Hz | flutter share '
    f'| strain p99 | wind on the {config.estimate_resolution}x'
    f'{config.estimate_resolution} mesh for that deflection |',
    '|---|---|---|---|---|---|---|---|',
  ]
  for r in aggregate(rows):
    cells = [
      f'{r[k]["mean"]:.{p}f} +- {r[k]["std"]:.{p}f}'
      for k, p in zip(STATS, (3, 2, 2, 3), strict=True)
    ]
    eq = r['equivalent_wind']
    lines.append(
      f'| {r["fabric"]} | {r["wind_speed"]:g} | {r["resolution"]} | '
      + ' | '.join(cells)
      + f' | {"n/d" if eq is None else f"{eq:.2f}"} |'
    )
  lines += [
    '',
    f'Means +- standard deviations over {len(config.seeds)} gust seeds. Mean range '
    'of each statistic between meshes (same fabric, wind, gusts) and between gust '
    'seeds (same fabric, wind, mesh):',
    '',
    '| statistic | between meshes | between gust seeds |',
    '|---|---|---|',
  ]
  for k, v in spread(rows).items():
    lines.append(f'| {k} | {v["between_meshes"]:.3f} | {v["between_seeds"]:.3f} |')
  return '\n'.join(lines)


def plot(config: Config, rows: list[dict], path: str) -> None:
  agg = aggregate(rows)
  fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
  for ax, stat in zip(axes, STATS[:3], strict=True):
    for i, fab in enumerate(config.fabrics):
      for j, res in enumerate(config.resolutions):
        sel = [r for r in agg if r['fabric'] == fab and r['resolution'] == res]
        ax.errorbar(
          [r['wind_speed'] + 0.06 * (j - 1) for r in sel],
          [r[stat]['mean'] for r in sel],
          yerr=[r[stat]['std'] for r in sel],
          fmt=['-', '--', ':', '-.'][j % 4],
          marker='o',
          ms=3,
          capsize=2,
          color=f'C{i}',
          label=f'{fab} {res}x{res}',
        )
    ax.set(xlabel='wind speed (m/s)', ylabel=stat)
    ax.grid(alpha=0.3)
  axes[0].legend(fontsize=6)
  fig.suptitle(
    f'the same fabrics and gusts on {len(config.resolutions)} meshes '
    f'(mean +- sd over {len(config.seeds)} gust seeds)'
  )
  fig.tight_layout()
  files.savefig(fig, path, dpi=100)
  plt.close(fig)


def run(config: Config, workdir: str) -> list[dict]:
  os.makedirs(workdir, exist_ok=True)
  path = os.path.join(workdir, 'mesh_convergence.json')
  done = files.resume(path, config).get('resolutions', {})
  for res in sorted(set(config.resolutions) | {config.estimate_resolution}):
    if str(res) in done:
      continue
    n = len(config.fabrics) * len(config.winds) * len(config.seeds)
    print(f'{res}x{res} mesh: simulating {n} worlds ...', flush=True)
    done[str(res)] = simulate_resolution(config, res)
    files.write_json(path, {'config': dataclasses.asdict(config), 'resolutions': done})
  rows = compare(config, done)
  files.write_json(
    path,
    {
      'config': dataclasses.asdict(config),
      'resolutions': done,
      'rows': rows,
      'spread': spread(rows),
    },
  )
  plot(config, rows, os.path.join(workdir, 'mesh_convergence.png'))
  print(table(config, rows))
  return rows


if __name__ == '__main__':
  cli.run(
    Args, {k: Args(study=v) for k, v in PRESETS.items()},
    lambda args: run(args.study, args.workdir),
  )  # fmt: skip
