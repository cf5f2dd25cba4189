"""Simulate a light and a stiff fabric in a fan's gusty wind; save a filmstrip PNG.

Prints edge-strain statistics and the centre vertex's motion amplitude and
dominant frequency, and writes them as JSON beside the picture.

  python -m experiments.simulate_demo --workdir=out/demo
"""

from __future__ import annotations

import json
import os
import tempfile
import time

import jax
import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from absl import app, flags  # noqa: E402

import physsim  # noqa: E402
from experiments import files  # noqa: E402

FLAGS = flags.FLAGS
flags.DEFINE_string('workdir', 'out/demo', 'where the PNG and JSON go')
flags.DEFINE_list('fabrics', ['red_violet', 'black_denim'], 'light and stiff fabric')
flags.DEFINE_list('bending', ['0.3', '3.0'], 'bending scale per fabric')
flags.DEFINE_float('wind', 3.0, 'wind speed, m/s')
flags.DEFINE_float('gusts', 0.2, 'RMS gust intensity')
flags.DEFINE_integer('resolution', 15, 'cloth vertices per side')
flags.DEFINE_integer('frames', 60, 'frames at 20 Hz')
flags.DEFINE_enum(
  'backend', 'auto', ['auto', 'mjx', 'c'], "'auto': MJX on a GPU, else C"
)
flags.DEFINE_integer('seed', 0, 'gust seed')


def filmstrip(models, rollouts, labels, path, n=6):
  fig, axes = plt.subplots(
    len(models),
    n,
    figsize=(2.2 * n, 2.6 * len(models)),
    subplot_kw={'projection': '3d'},
  )
  for r, (model, xs, label) in enumerate(zip(models, rollouts, labels, strict=True)):
    for c, t in enumerate(np.linspace(0, len(xs) - 1, n).astype(int)):
      ax = axes[r, c]
      x = xs[t]
      ax.plot_trisurf(
        x[:, 0],
        x[:, 1],
        x[:, 2],
        triangles=model.mesh.faces,
        color='tab:blue' if r == 0 else 'tab:brown',
        edgecolor='none',
        alpha=0.9,
      )
      ax.set(
        xlim=(-0.6, 0.6),
        ylim=(-0.1, 1.1),
        zlim=(0.4, 1.6),
        xticks=[],
        yticks=[],
        zticks=[],
      )
      ax.view_init(elev=15, azim=-35)
      ax.set_title(
        f'{label}\nt={t / 20:.2f} s' if c == 0 else f't={t / 20:.2f} s', fontsize=8
      )
  fig.suptitle(f'{FLAGS.wind:g} m/s wind from -y, gusts {FLAGS.gusts:g}', fontsize=10)
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def main(argv):
  del argv
  os.makedirs(FLAGS.workdir, exist_ok=True)
  backend = physsim.resolve_backend(FLAGS.backend)
  models, rollouts, labels, stats = [], [], [], {}
  t0 = time.time()
  for name, scale in zip(FLAGS.fabrics, map(float, FLAGS.bending), strict=True):
    fab = physsim.fabric(name)
    model = physsim.build(physsim.square(FLAGS.resolution), name)
    p = physsim.params.make(scale, FLAGS.wind, fab.real_area_weight)
    out = physsim.simulate(
      model,
      p,
      frames=FLAGS.frames,
      wind=physsim.Wind(gust_intensity=FLAGS.gusts),
      key=jax.random.key(FLAGS.seed),
      backend=backend,
    ).check()
    s = physsim.motion.motion_stats(model.mesh, out.positions[0], 20.0)
    stats[name] = {'bending_scale': scale, 'area_weight': fab.real_area_weight, **s}
    models.append(model)
    rollouts.append(out.positions[0])
    labels.append(f'{name} x{scale:g}')
    print(
      f'{name:>12}: strain max {s["strain_max"]:.3f} p99 {s["strain_p99"]:.4f}, centre '
      f'amplitude {s["centre_amplitude_m"] * 100:.1f} cm at {s["centre_dominant_hz"]:.2f} Hz, '
      f'mean deflection {s["mean_deflection_m"]:.2f} m'
    )
  png = os.path.join(FLAGS.workdir, 'filmstrip.png')
  filmstrip(models, rollouts, labels, png)
  with tempfile.NamedTemporaryFile(
    'w', dir=FLAGS.workdir, delete=False, suffix='.json'
  ) as f:
    json.dump(
      {'backend': backend, 'wind': FLAGS.wind, 'gusts': FLAGS.gusts, 'fabrics': stats},
      f,
      indent=1,
    )
  os.replace(f.name, os.path.join(FLAGS.workdir, 'motion.json'))
  print(f'wrote {png} ({backend} backend, {time.time() - t0:.0f} s)')


if __name__ == '__main__':
  app.run(main)
