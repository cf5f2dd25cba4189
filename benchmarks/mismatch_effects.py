"""Which part of another physics moves the estimate's wind, and which way.

The paper-size check on recordings of ``physsim.mismatch.WORLD`` held its
intervals but left one confident miss: a white tablecloth in 4.08 m/s read as
5.14 m/s (BENCHMARKS.md [C19]). The shape distance reads the sheet's mean
position (how far it is blown back and lifted); this script simulates that
truth under the estimator's own physics at a sweep of winds, and under each
part of the other physics alone and all together (MuJoCo C, steady wind, so
each run is one deterministic simulation; or, with ``--gusts``, each the mean
over ``--seeds`` gust histories, the same ones for every variant), and reports
for each the wind at which the estimator's own sheet sits where this one does
(the nearest point of the sweep's (y, z) curve of mean positions,
interpolated): above the truth, that part makes the sheet look windier. The
gust spectrum (16 modes against 8) is a variant only with ``--gusts``.

  python -m benchmarks.mismatch_effects --out=$OUT/mismatch_effects.json
  python -m benchmarks.mismatch_effects --gusts=0.3 --seeds=4 \
      --out=$OUT/mismatch_effects_gusts.json
"""

from __future__ import annotations

import dataclasses
import time

import jax
import numpy as np

import physsim
from experiments.pipeline import cli, files


@dataclasses.dataclass(frozen=True)
class Args:
  """The truth and the sweep.

  Attributes:
    material: the fabric.
    bending_scale: the truth's bending scale.
    wind_speed: the truth's wind, m/s.
    area_weight: the truth's area weight, kg/m^2.
    resolution: cloth vertices per side (the estimator's 25).
    clip: seconds averaged, after the warm-up.
    warmup: seconds simulated first.
    winds: the own-physics sweep, as multiples of the truth's wind (1 is
      always in it).
    gusts: the gusts' relative strength (0: steady wind).
    seeds: gust histories averaged per variant and wind (with gusts).
    out: JSON path.
  """

  material: str = 'white_tablecloth'
  bending_scale: float = 0.524
  wind_speed: float = 4.083
  area_weight: float = 0.1451
  resolution: int = 25
  clip: float = 2.0
  warmup: float = 1.0
  winds: tuple[float, ...] = (0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4)
  gusts: float = 0.0
  seeds: int = 1
  out: str = 'out/benchmarks/mismatch_effects.json'


PRESETS = {
  'default': Args(),
  'smoke': Args(resolution=8, clip=0.2, warmup=0.2, winds=(0.9, 1.1)),
}

_FPS = 20.0


def _variants(gusts: float) -> dict[str, physsim.Mismatch]:
  """The other physics's parts alone, then together (its gust spectrum only
  where there are gusts)."""
  w = physsim.mismatch.WORLD
  parts = {
    'fan turned 10 deg': physsim.Mismatch(fan_yaw_deg=w.fan_yaw_deg),
    'drag along the cloth': physsim.Mismatch(air_drag=w.air_drag),
    'damped bending': physsim.Mismatch(bending_damping=w.bending_damping),
    'edges twice as soft': physsim.Mismatch(edge_solref_scale=w.edge_solref_scale),
  }
  if gusts:
    parts[f'{w.gust_modes} gust modes'] = physsim.Mismatch(gust_modes=w.gust_modes)
    return {**parts, 'all of them': w}
  return {
    **parts,
    'all of them': dataclasses.replace(w, gust_modes=physsim.mismatch.OWN.gust_modes),
  }


def mean_position(args: Args, physics: physsim.Mismatch, wind: float) -> np.ndarray:
  """(y, z): the sheet's mean vertex position over the clip (and over the
  gust histories), metres."""
  mesh = physsim.square(args.resolution)
  config = physsim.config_for_mesh(mesh, _FPS, **physics.sim_fields())
  model = physsim.build(mesh, args.material, config)
  n = args.seeds if args.gusts else 1
  out = physsim.simulate(
    model,
    physsim.params.make([args.bending_scale] * n, [wind] * n, [args.area_weight] * n),
    frames=max(1, round(args.clip * _FPS)), fps=_FPS, warmup=args.warmup,
    wind=physics.wind(args.gusts), key=jax.random.key(0), backend='c', workers=0,
  )  # fmt: skip
  if not np.all(out.valid):
    raise RuntimeError(f'{physics} at {wind} m/s blew up')
  return np.asarray(out.positions, np.float64).mean(axis=(0, 1, 2))[1:]


def equivalent_wind(sweep_winds, sweep_yz, yz) -> float:
  """The wind of the own-physics curve's point nearest ``yz`` (the curve
  interpolated linearly between the sweep's winds)."""
  fine = np.linspace(sweep_winds[0], sweep_winds[-1], 2001)
  curve = np.stack(
    [np.interp(fine, sweep_winds, sweep_yz[:, k]) for k in range(2)], axis=1
  )
  return float(fine[np.argmin(np.sum((curve - yz) ** 2, axis=1))])


def main(args: Args) -> None:
  if not (0 <= args.gusts <= 1 and args.seeds >= 1):
    raise ValueError(
      f'need 0 <= --gusts <= 1 and --seeds >= 1, got {args.gusts}, {args.seeds}'
    )
  if args.material not in physsim.FABRICS:
    raise ValueError(
      f'--material={args.material!r}: not one of {sorted(physsim.FABRICS)}'
    )
  t0 = time.time()
  winds = np.array(sorted({*args.winds, 1.0})) * args.wind_speed  # the truth's own
  own = np.stack([mean_position(args, physsim.mismatch.OWN, w) for w in winds])
  truth_yz = own[int(np.argmin(np.abs(winds - args.wind_speed)))]
  rows = [{'physics': 'own', 'y': truth_yz[0], 'z': truth_yz[1],
           'equivalent_wind': args.wind_speed}]  # fmt: skip
  for name, physics in _variants(args.gusts).items():
    yz = mean_position(args, physics, args.wind_speed)
    rows.append({'physics': name, 'y': float(yz[0]), 'z': float(yz[1]),
                 'equivalent_wind': equivalent_wind(winds, own, yz)})  # fmt: skip
  print(
    f'{args.material}, bending {args.bending_scale:g}, area weight '
    f'{args.area_weight:g} kg/m^2, wind {args.wind_speed:g} m/s ('
    + (f'gusts {args.gusts:g}, {args.seeds} histories, ' if args.gusts else 'steady, ')
    + f'{args.resolution}x{args.resolution}, MuJoCo C):\n'
  )
  print(
    '| physics | mean y (m) | mean z (m) | the own wind that looks alike | over the truth |'
  )
  print('|---|---:|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["physics"]} | {r["y"]:.4f} | {r["z"]:.4f} | {r["equivalent_wind"]:.2f} m/s | '
      f'{100 * (r["equivalent_wind"] / args.wind_speed - 1):+.1f}% |'
    )
  lo, hi = winds[0], winds[-1]
  print(f'\n(own sweep {lo:.2f}-{hi:.2f} m/s; {time.time() - t0:.0f} s)')
  files.write_json(
    args.out,
    {'args': dataclasses.asdict(args), 'sweep_winds': winds.tolist(),
     'sweep_yz': own.tolist(), 'rows': rows},
  )  # fmt: skip


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
