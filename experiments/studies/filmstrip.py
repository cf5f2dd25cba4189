"""A light and a stiff fabric in a fan's gusty wind, as a filmstrip PNG.

Prints edge-strain statistics and the centre vertex's motion amplitude and
dominant frequency, and writes them as JSON beside the picture.
``experiments/simulate_demo.py`` is its command line.
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


@dataclasses.dataclass(frozen=True)
class Config:
  """The filmstrip.

  Attributes:
    fabrics: fabric names (physsim.FABRICS), each at its real area weight.
    bending: bending scale of each fabric.
    wind: wind speed, m/s.
    gusts: RMS relative gust intensity.
    resolution: cloth vertices per side.
    frames: frames at 20 Hz.
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
    seed: gust seed.
  """

  fabrics: tuple[str, ...] = ('red_violet', 'black_denim')
  bending: tuple[float, ...] = (0.3, 3.0)
  wind: float = 3.0
  gusts: float = 0.2
  resolution: int = 15
  frames: int = 60
  backend: str = cli.choice('auto', physsim.BACKENDS)
  seed: int = 0


def plot(config: Config, meshes, rollouts, labels, path: str, n: int = 6) -> None:
  """Rows: fabrics; columns: ``n`` frames of each rollout (T, V, 3)."""
  fig, axes = plt.subplots(
    len(meshes), n, figsize=(2.2 * n, 2.6 * len(meshes)),
    subplot_kw={'projection': '3d'}, squeeze=False,
  )  # fmt: skip
  for r, (mesh, xs, label) in enumerate(zip(meshes, rollouts, labels, strict=True)):
    for c, t in enumerate(np.linspace(0, len(xs) - 1, n).astype(int)):
      ax = axes[r, c]
      x = xs[t]
      ax.plot_trisurf(
        x[:, 0], x[:, 1], x[:, 2], triangles=mesh.faces,
        color=f'C{r}', edgecolor='none', alpha=0.9,
      )  # fmt: skip
      ax.set(xlim=(-0.6, 0.6), ylim=(-0.1, 1.1), zlim=(0.4, 1.6),
             xticks=[], yticks=[], zticks=[])  # fmt: skip
      ax.view_init(elev=15, azim=-35)
      title = f't = {t / 20:.2f} s'
      ax.set_title(f'{label}\n{title}' if c == 0 else title, fontsize=8)
  fig.suptitle(f'{config.wind:g} m/s wind from -y, gusts {config.gusts:g}', fontsize=10)
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def run(config: Config, workdir: str) -> dict:
  """Simulates each fabric, writes ``filmstrip.png`` and ``motion.json``.

  Raises:
    ValueError: fabrics and bending of different lengths, an unknown fabric,
      or a simulation that blew up.
  """
  if len(config.fabrics) != len(config.bending):
    raise ValueError(
      f'{len(config.fabrics)} fabrics but {len(config.bending)} bending scales'
    )
  os.makedirs(workdir, exist_ok=True)
  backend = physsim.resolve_backend(config.backend)
  meshes, rollouts, labels, stats = [], [], [], {}
  t0 = time.time()
  for name, scale in zip(config.fabrics, config.bending, strict=True):
    fab = physsim.fabric(name)
    model = physsim.build(physsim.square(config.resolution), name)
    p = physsim.params.make(scale, config.wind, fab.real_area_weight)
    out = physsim.simulate(
      model, p, frames=config.frames, wind=physsim.Wind(gust_intensity=config.gusts),
      key=jax.random.key(config.seed), backend=backend,
    ).check()  # fmt: skip
    s = physsim.motion.motion_stats(model.mesh, out.positions[0], 20.0)
    stats[name] = {'bending_scale': scale, 'area_weight': fab.real_area_weight, **s}
    meshes.append(model.mesh)
    rollouts.append(out.positions[0])
    labels.append(f'{name} x{scale:g}')
    print(
      f'{name:>12}: strain max {s["strain_max"]:.3f} p99 {s["strain_p99"]:.4f}, centre '
      f'amplitude {s["centre_amplitude_m"] * 100:.1f} cm at '
      f'{s["centre_dominant_hz"]:.2f} Hz, mean deflection {s["mean_deflection_m"]:.2f} m'
    )
  png = os.path.join(workdir, 'filmstrip.png')
  plot(config, meshes, rollouts, labels, png)
  result = {'backend': backend, 'config': dataclasses.asdict(config), 'fabrics': stats}
  files.write_json(os.path.join(workdir, 'motion.json'), result)
  print(f'wrote {png} ({backend} backend, {time.time() - t0:.0f} s)')
  return result
