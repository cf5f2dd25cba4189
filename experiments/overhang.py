"""A fabric's bending length from a ruler's reading of an overhang (issue 39).

  python -m experiments.overhang --overhang=0.06 --reach=0.045
  python -m experiments.overhang --overhang=0.06 --reach=0.045 --ruler_sd=0.002 \
      --material=gray_interlock --area_weight=0.21
  python -m experiments.overhang --overhang=0.06,0.06,0.06,0.06 \
      --reach=0.045,0.043,0.046,0.044      # both ends, face up and down (ASTM D1388)

Slide a strip of the fabric over a table's edge by ``--overhang`` metres
(measured along the strip), then read how far its free end reaches out from
the edge, horizontally (``--reach``). The heavy elastica
(``physsim.cantilever``) turns the pair into the bending length
c = (D / (w g))^(1/3), with the spread a ruler's ``--ruler_sd`` gives it; any
overhang of 0.05 to 5 bending lengths works, not only Peirce's 41.5 degree
slope. Several readings (the standard takes both ends of a strip, face up and
down: bending differs with direction) give their mean, whose uncertainty is the
larger of the ruler's and the readings' own scatter over sqrt(n). The printed
flags put it into an estimate's prior (``--bending_length``,
or a protocol file's ``"fabric"`` readings). With the fabric and its area
weight it also prints the rigidity D = w g c^3 and the bending scale (D over
the fabric's reference, what estimates report).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

import physsim
from experiments.pipeline import cli
from physsim import cantilever


@dataclasses.dataclass(frozen=True)
class Args:
  """An overhang's ruler readings.

  Attributes:
    overhang: length of strip past the table's edge, m (along the strip;
      required; comma-separated for several readings).
    reach: horizontal distance from the edge to the strip's free end, m
      (required; one per overhang).
    ruler_sd: standard uncertainty of each ruler reading, m.
    material: paper fabric name (physsim.FABRICS) for the bending scale; ''
      for none.
    area_weight: the fabric's area weight, kg/m^2 (a kitchen scale and a
      swatch of known size); 0: D and the bending scale are not printed.
    area_weight_sd: its standard uncertainty, kg/m^2.
  """

  overhang: tuple[float, ...] = ()
  reach: tuple[float, ...] = ()
  ruler_sd: float = 0.001
  material: str = ''
  area_weight: float = 0.0
  area_weight_sd: float = 0.0


PRESETS = {'default': Args()}


def reading(args: Args) -> dict:
  """The bending length (the readings' mean) and, with an area weight, the
  rigidity and bending scale, each with its standard uncertainty (SI units);
  ``readings``: each overhang's own bending length.

  Raises:
    ValueError: naming the flag of a reading out of range.
  """
  if not args.overhang or len(args.overhang) != len(args.reach):
    raise ValueError(
      f'--overhang={",".join(map(str, args.overhang))} --reach='
      f'{",".join(map(str, args.reach))}: need one reach per overhang, at least one'
    )
  for name in ('ruler_sd', 'area_weight', 'area_weight_sd'):
    v = getattr(args, name)
    if not (math.isfinite(v) and v >= 0):
      raise ValueError(f'--{name}={v}: need a finite value >= 0 (metres, kg/m^2)')
  if args.material and args.material not in physsim.FABRICS:
    raise ValueError(
      f'--material={args.material!r}: not one of {sorted(physsim.FABRICS)}'
    )
  each = [
    _one(o, r, args.ruler_sd) for o, r in zip(args.overhang, args.reach, strict=True)
  ]
  cs = np.array([c for c, _ in each])
  c = float(cs.mean())
  c_sd = math.sqrt(sum(sd**2 for _, sd in each)) / len(each)  # the ruler's
  if len(each) > 1:  # or the readings' own scatter, whichever is larger
    c_sd = max(c_sd, float(cs.std(ddof=1)) / math.sqrt(len(each)))
  out = {'bending_length': c, 'bending_length_sd': c_sd, 'readings': cs.tolist()}
  if args.area_weight > 0:
    d = cantilever.rigidity(c, args.area_weight)
    rel = math.hypot(3 * c_sd / c, args.area_weight_sd / args.area_weight)
    out.update(rigidity=d, rigidity_sd=d * rel)
    if args.material:
      d0 = physsim.search_space(args.material).rigidity  # as estimates read it
      out.update(bending_scale=d / d0, bending_scale_sd=d * rel / d0)
  return out


def _one(overhang: float, reach: float, ruler_sd: float) -> tuple[float, float]:
  """One reading's bending length and its sd, refusals naming the flags."""
  flags_ = f'--overhang={overhang} --reach={reach}'
  if not (math.isfinite(overhang) and 0 < overhang <= 1.0):
    raise ValueError(f'{flags_}: need 0 < overhang <= 1 m')
  if not (math.isfinite(reach) and 0 < reach < overhang):
    raise ValueError(
      f'{flags_}: the free end reaches out less than the overhang and more than 0'
    )
  try:
    return cantilever.bending_length_sd(overhang, reach, ruler_sd, ruler_sd)
  except ValueError as e:
    raise ValueError(f'{flags_}: {e}') from None


def main(args: Args) -> None:
  r = reading(args)
  c, sd = r['bending_length'], r['bending_length_sd']
  n = len(r['readings'])
  what = (
    f'{args.overhang[0]} m over the edge reaching {args.reach[0]} m out'
    if n == 1
    else f'the mean of {n} readings ({", ".join(f"{x:.4f}" for x in r["readings"])} m)'
  )
  print(f'bending length c = {c:.4f} m (sd {sd:.4f} m): {what} (the heavy elastica)')
  if 'rigidity' in r:
    line = f'rigidity D = w g c^3 = {r["rigidity"]:.3g} N m (sd {r["rigidity_sd"]:.2g})'
    if 'bending_scale' in r:
      line += (
        f'; bending scale {r["bending_scale"]:.3g} (sd {r["bending_scale_sd"]:.2g}) '
        f"of {args.material}'s reference"
      )
    print(line)
  print(
    f'estimate with: --bending_length={c:.4g} --bending_length_sd={sd:.2g} '
    f'(or a protocol file\'s "fabric": {{"bending_length": {c:.4g}, '
    f'"bending_length_sd": {sd:.2g}}})'
  )


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
