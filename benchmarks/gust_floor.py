"""How well one clip can measure the load ratio while the fan gusts.

The shape distance reads the load ratio rho v^2/(w g) from where the sheet
hangs on average over the clip (``physsim.shape``). A gusty fan makes that
average wander from clip to clip at the same mean wind, a floor for any
estimator of the ratio from one clip of that length, however good its
simulator, and with an anemometer reading of the mean wind a floor on area
weight for an estimator told nothing else about it (a prior range, as the
estimate's, can only do better). This script measures it with the simulator
itself: ``--draws`` gust histories per wind speed, each ``--seconds`` long
after the warm-up; for each clip length in ``--clips`` the first that many
seconds of every history give one summary (the clip's mean of the sheet's
centroid, wind-wise y and vertical z, over all vertices: what the depth pixels
approximate), and their spread across histories is the gust noise Sigma
(2 x 2). Steady-wind worlds at area weight w / (1 + d) and w (1 + d) give the
summary's slope J with respect to the log load ratio. The ratio's standard
error from one clip is then 1 / sqrt(J^T Sigma^-1 J) (the Cramer-Rao bound of
a Gaussian summary).

With ``k`` recordings of one fabric at ``k`` fan settings, each with a reading
of relative error r, area weight's log error has standard deviation
sqrt((s^2 + (2 r)^2) / k), s the ratio's: the script prints the mean absolute
error that implies (sqrt(2 / pi) of it) for k = 1 and 3. Steady-wind slopes
stand in for gusty ones; the sheet is the estimator's (``--cloth_resolution``,
its time step); the spread is estimated from ``--draws`` histories (24: about
+-15% on each standard error). About 30 minutes on two CPU cores at the
defaults (MuJoCo C), minutes on a GPU:

  python benchmarks/gust_floor.py --out=/tmp/gust_floor.json
  python benchmarks/gust_floor.py --winds=2,4,6 --seconds=5 --clips=2.5,5 --seed=1
"""

from __future__ import annotations

import jax
import numpy as np
from absl import app, flags

import physsim
from experiments.pipeline import files

FLAGS = flags.FLAGS


def summaries(positions: np.ndarray, frames: int) -> np.ndarray:
  """(B, 2) mean (y, z) of the vertices' centroid over the first ``frames``
  frames of (B, T, V, 3) positions, metres."""
  centroid = positions[:, :frames].mean(axis=2)  # (B, frames, 3)
  return centroid.mean(axis=1)[:, 1:]


def ratio_sd(samples: np.ndarray, slope: np.ndarray) -> float:
  """The log load ratio's standard error from one summary: samples (N, 2) of
  the summary at one truth, slope (2,) d summary / d log ratio."""
  cov = np.cov(samples, rowvar=False)
  info = slope @ np.linalg.solve(cov, slope)
  return float(1.0 / np.sqrt(info))


def floor(s: float, reading: float, k: int) -> float:
  """Mean absolute relative error (%) of area weight from ``k`` recordings
  whose log ratios have standard error ``s`` each, winds read to ``reading``."""
  return float(100 * np.sqrt(2 / np.pi) * np.sqrt((s**2 + (2 * reading) ** 2) / k))


def _positive_floats(name: str) -> list[float]:
  """A list flag's values as positive floats; a usage error naming the flag."""
  try:
    values = [float(v) for v in FLAGS[name].value]
  except ValueError:
    values = []
  if not values or not all(v > 0 for v in values):  # also refuses NaN
    raise app.UsageError(
      f'--{name}={",".join(FLAGS[name].value)}: need positive numbers, comma-separated'
    )
  return values


def main(argv):
  del argv
  winds, clips, readings = (_positive_floats(n) for n in ('winds', 'clips', 'readings'))
  if max(clips) > FLAGS.seconds:
    raise app.UsageError(f'--clips up to {max(clips)} s but --seconds={FLAGS.seconds}')
  space = physsim.search_space(FLAGS.material)
  w = FLAGS.area_weight or float(space.center().area_weight)
  model = physsim.build(physsim.square(FLAGS.cloth_resolution), FLAGS.material)
  n = FLAGS.draws
  frames = round(FLAGS.seconds * FLAGS.fps)
  common = dict(fps=FLAGS.fps, warmup=FLAGS.warmup, backend=FLAGS.backend,
                material=FLAGS.material)  # fmt: skip
  print(f'{n * len(winds)} gusty worlds, {FLAGS.seconds:g} s each ...', flush=True)
  gusty = physsim.simulate(
    model,
    physsim.params.make(FLAGS.bending, np.repeat(winds, n), w),
    frames=frames,
    wind=physsim.Wind(gust_intensity=FLAGS.gusts),
    key=jax.random.key(FLAGS.seed),
    **common,
  )
  # steady wind: the slope, from area weights a step either side
  lo, hi = w / (1 + FLAGS.step), w * (1 + FLAGS.step)
  steady = physsim.simulate(
    model,
    physsim.params.make(
      FLAGS.bending, np.repeat(winds, 2), np.tile([lo, hi], len(winds))
    ),
    frames=round(FLAGS.fps),
    **common,
  )
  if not (np.all(gusty.valid) and np.all(steady.valid)):
    raise SystemExit('a simulation blew up (valid is False); nothing written')
  d_log_ratio = -np.log(hi / lo)  # the ratio goes as 1 / w
  rows = []
  for i, v in enumerate(winds):
    y = summaries(steady.positions[2 * i : 2 * i + 2], round(FLAGS.fps))
    slope = (y[1] - y[0]) / d_log_ratio
    ratio = float(physsim.load_ratio(v, w))
    for c in clips:
      samples = summaries(gusty.positions[i * n : (i + 1) * n], round(c * FLAGS.fps))
      s = ratio_sd(samples, slope)
      row = {
        'wind_speed': v, 'load_ratio': ratio, 'clip_s': c, 'ratio_sd': s,
        # its two factors: how far the summary moves with the ratio, and wanders
        'slope_m': slope.tolist(), 'gust_sd_m': samples.std(axis=0, ddof=1).tolist(),
      }  # fmt: skip
      for r in readings:
        row[f'area_weight_floor_{r:g}'] = {k: floor(s, r, k) for k in (1, 3)}
      rows.append(row)
  print(f'{FLAGS.material}, area weight {w:g} kg/m^2, gusts {FLAGS.gusts:g}, '
        f'{n} histories per wind; mean-error floors of area weight from k recordings, no prior')  # fmt: skip
  head = ''.join(f' | floor k=1, k=3 ({100 * r:g}% reading)' for r in readings)
  print('| wind m/s | load ratio | clip s | ratio sd' + head + ' |')
  print('|---:|---:|---:|---:|' + '---|' * len(readings))
  for row in rows:
    cells = ''.join(
      f' | {f[1]:.1f}%, {f[3]:.1f}%'
      for f in (row[f'area_weight_floor_{r:g}'] for r in readings)
    )
    print(f"| {row['wind_speed']:g} | {row['load_ratio']:.2f} | {row['clip_s']:g} | "
          f"{100 * row['ratio_sd']:.1f}%{cells} |")  # fmt: skip
  if FLAGS.out:
    flags_used = ('material', 'winds', 'area_weight', 'bending', 'gusts', 'draws', 'seconds',
                  'clips', 'fps', 'warmup', 'cloth_resolution', 'step', 'readings',
                  'backend', 'seed')  # fmt: skip
    files.write_json(
      FLAGS.out, {'rows': rows, 'flags': {k: FLAGS[k].value for k in flags_used}}
    )


def define_flags() -> None:
  """Defined only when run as a script, so tests can import the helpers."""
  flags.DEFINE_string('material', 'gray_interlock', 'the fabric')
  flags.DEFINE_list('winds', ['3', '5'], 'mean wind speeds, m/s')
  flags.DEFINE_float('area_weight', 0.0, 'kg/m^2 (0: the middle of the fabric range)')
  flags.DEFINE_float('bending', 1.0, "bending scale (1: the fabric's measured)")
  flags.DEFINE_float('gusts', 0.3, 'RMS relative gust intensity', lower_bound=0.0)
  flags.DEFINE_integer('draws', 24, 'gust histories per wind speed', lower_bound=4)
  flags.DEFINE_float('seconds', 10.0, 'seconds recorded per history', lower_bound=0.5)
  flags.DEFINE_list('clips', ['2.5', '5', '10'], 'clip lengths, s (<= --seconds)')
  flags.DEFINE_float('fps', 20.0, 'frames per second summarised')
  flags.DEFINE_float('warmup', 1.0, 'seconds simulated before the first frame')
  flags.DEFINE_integer('cloth_resolution', 33, 'vertices a side')
  flags.DEFINE_float('step', 0.05, 'relative area-weight step of the slope')
  flags.DEFINE_list('readings', ['0.02'], "the anemometer's relative standard errors")
  flags.DEFINE_string('backend', 'auto', 'simulator (physsim.simulate)')
  flags.DEFINE_integer('seed', 0, 'gust histories')
  flags.DEFINE_string('out', None, 'JSON path')


if __name__ == '__main__':
  define_flags()
  app.run(main)
