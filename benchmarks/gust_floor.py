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

  python -m benchmarks.gust_floor --out=/tmp/gust_floor.json
  python -m benchmarks.gust_floor --winds=2,4,6 --seconds=5 --clips=2.5,5 --seed=1
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The gust floor.

  Attributes:
    material: the fabric.
    winds: mean wind speeds, m/s (comma-separated).
    area_weight: kg/m^2 (0: the middle of the fabric range).
    bending: bending scale (1: the fabric's measured).
    gusts: RMS relative gust intensity (>= 0).
    draws: gust histories per wind speed (>= 4).
    seconds: seconds recorded per history (>= 0.5).
    clips: clip lengths, s (<= --seconds; comma-separated).
    fps: frames per second summarised.
    warmup: seconds simulated before the first frame.
    cloth_resolution: vertices a side.
    step: relative area-weight step of the slope.
    readings: the anemometer's relative standard errors (comma-separated).
    backend: simulator (physsim.simulate).
    seed: gust histories.
    out: JSON path.
  """

  material: str = 'gray_interlock'
  winds: tuple[str, ...] = ('3', '5')
  area_weight: float = 0.0
  bending: float = 1.0
  gusts: float = 0.3
  draws: int = 24
  seconds: float = 10.0
  clips: tuple[str, ...] = ('2.5', '5', '10')
  fps: float = 20.0
  warmup: float = 1.0
  cloth_resolution: int = 33
  step: float = 0.05
  readings: tuple[str, ...] = ('0.02',)
  backend: str = 'auto'
  seed: int = 0
  out: str = 'out/benchmarks/gust_floor.json'


PRESETS = {
  'default': Args(),
  # checks the script on a CPU in about a minute
  'smoke': Args(
    winds=('3',), draws=4, seconds=1.0, clips=('0.5', '1'), cloth_resolution=8
  ),
}


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


def _positive_floats(name: str, values: tuple[str, ...]) -> list[float]:
  """A list flag's values as positive numbers; a ValueError naming the flag."""
  try:
    out = [float(v) for v in values]
  except ValueError:
    out = []
  if not out or not all(np.isfinite(v) and v > 0 for v in out):  # refuses NaN, inf
    raise ValueError(
      f'--{name}={",".join(values)}: need positive numbers, comma-separated'
    )
  return out


def main(args: Args) -> None:
  winds, clips, readings = (
    _positive_floats(n, getattr(args, n)) for n in ('winds', 'clips', 'readings')
  )
  for name, low in (('gusts', 0.0), ('draws', 4), ('seconds', 0.5)):
    if not getattr(args, name) >= low:
      raise ValueError(f'--{name}={getattr(args, name)}: need at least {low}')
  if max(clips) > args.seconds:
    raise ValueError(f'--clips up to {max(clips)} s but --seconds={args.seconds}')
  space = physsim.search_space(args.material)
  w = args.area_weight or float(space.center().area_weight)
  model = physsim.build(physsim.square(args.cloth_resolution), args.material)
  n = args.draws
  frames = round(args.seconds * args.fps)
  common = dict(fps=args.fps, warmup=args.warmup, backend=args.backend,
                material=args.material)  # fmt: skip
  print(f'{n * len(winds)} gusty worlds, {args.seconds:g} s each ...', flush=True)
  gusty = physsim.simulate(
    model,
    physsim.params.make(args.bending, np.repeat(winds, n), w),
    frames=frames,
    wind=physsim.Wind(gust_intensity=args.gusts),
    key=jax.random.key(args.seed),
    **common,
  )
  # steady wind: the slope, from area weights a step either side
  lo, hi = w / (1 + args.step), w * (1 + args.step)
  steady = physsim.simulate(
    model,
    physsim.params.make(
      args.bending, np.repeat(winds, 2), np.tile([lo, hi], len(winds))
    ),
    frames=round(args.fps),
    **common,
  )
  if not (np.all(gusty.valid) and np.all(steady.valid)):
    raise SystemExit('a simulation blew up (valid is False); nothing written')
  d_log_ratio = -np.log(hi / lo)  # the ratio goes as 1 / w
  rows = []
  for i, v in enumerate(winds):
    y = summaries(steady.positions[2 * i : 2 * i + 2], round(args.fps))
    slope = (y[1] - y[0]) / d_log_ratio
    ratio = float(physsim.load_ratio(v, w))
    for c in clips:
      samples = summaries(gusty.positions[i * n : (i + 1) * n], round(c * args.fps))
      s = ratio_sd(samples, slope)
      row = {
        'wind_speed': v, 'load_ratio': ratio, 'clip_s': c, 'ratio_sd': s,
        # its two factors: how far the summary moves with the ratio, and wanders
        'slope_m': slope.tolist(), 'gust_sd_m': samples.std(axis=0, ddof=1).tolist(),
      }  # fmt: skip
      for r in readings:
        row[f'area_weight_floor_{r:g}'] = {k: floor(s, r, k) for k in (1, 3)}
      rows.append(row)
  print(f'{args.material}, area weight {w:g} kg/m^2, gusts {args.gusts:g}, '
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
  settings = {k: v for k, v in dataclasses.asdict(args).items() if k != 'out'}
  files.write_json(args.out, {'rows': rows, 'flags': settings})
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
