"""A fabric's bending length from a ruler's reading of an overhang (issue 39).

  python -m experiments.overhang --overhang=0.06 --reach=0.045
  python -m experiments.overhang --overhang=0.06 --reach=0.045 --ruler_sd=0.002 \
      --material=gray_interlock --area_weight=0.21

Slide a strip of the fabric over a table's edge by ``--overhang`` metres
(measured along the strip), then read how far its free end reaches out from
the edge, horizontally (``--reach``). The heavy elastica
(``physsim.cantilever``) turns the pair into the bending length
c = (D / (w g))^(1/3), with the spread a ruler's ``--ruler_sd`` gives it; any
overhang of 0.05 to 5 bending lengths works, not only Peirce's 41.5 degree
slope. The printed flags put it into an estimate's prior (``--bending_length``,
or a protocol file's ``"fabric"`` readings). With the fabric and its area
weight it also prints the rigidity D = w g c^3 and the bending scale (D over
the fabric's reference, what estimates report).
"""

from __future__ import annotations

import dataclasses
import math

import physsim
from experiments.pipeline import cli
from physsim import cantilever


@dataclasses.dataclass(frozen=True)
class Args:
  """An overhang's ruler readings.

  Attributes:
    overhang: length of strip past the table's edge, m (along the strip;
      required).
    reach: horizontal distance from the edge to the strip's free end, m
      (required).
    ruler_sd: standard uncertainty of each ruler reading, m.
    material: paper fabric name (physsim.FABRICS) for the bending scale; ''
      for none.
    area_weight: the fabric's area weight, kg/m^2 (a kitchen scale and a
      swatch of known size); 0: D and the bending scale are not printed.
    area_weight_sd: its standard uncertainty, kg/m^2.
  """

  overhang: float = 0.0
  reach: float = 0.0
  ruler_sd: float = 0.001
  material: str = ''
  area_weight: float = 0.0
  area_weight_sd: float = 0.0


PRESETS = {'default': Args()}


def reading(args: Args) -> dict:
  """The bending length and, with an area weight, the rigidity and bending
  scale, each with its standard uncertainty (SI units).

  Raises:
    ValueError: naming the flag of a reading out of range.
  """
  for name in ('overhang', 'reach', 'ruler_sd', 'area_weight', 'area_weight_sd'):
    v = getattr(args, name)
    if not (math.isfinite(v) and v >= 0):
      raise ValueError(f'--{name}={v}: need a finite value >= 0 (metres, kg/m^2)')
  if not 0 < args.overhang <= 1.0:
    raise ValueError(f'--overhang={args.overhang}: need 0 < overhang <= 1 m')
  if not 0 < args.reach < args.overhang:
    raise ValueError(
      f'--reach={args.reach}: the free end reaches out less than the overhang '
      f'({args.overhang} m) and more than 0'
    )
  if args.material and args.material not in physsim.FABRICS:
    raise ValueError(
      f'--material={args.material!r}: not one of {sorted(physsim.FABRICS)}'
    )
  try:
    c, c_sd = cantilever.bending_length_sd(
      args.overhang, args.reach, args.ruler_sd, args.ruler_sd
    )
  except ValueError as e:
    raise ValueError(f'--overhang={args.overhang} --reach={args.reach}: {e}') from None
  out = {'bending_length': c, 'bending_length_sd': c_sd}
  if args.area_weight > 0:
    d = cantilever.rigidity(c, args.area_weight)
    rel = math.hypot(3 * c_sd / c, args.area_weight_sd / args.area_weight)
    out.update(rigidity=d, rigidity_sd=d * rel)
    if args.material:
      d0 = physsim.reference_rigidity(args.material)
      out.update(bending_scale=d / d0, bending_scale_sd=d * rel / d0)
  return out


def main(args: Args) -> None:
  r = reading(args)
  c, sd = r['bending_length'], r['bending_length_sd']
  print(
    f'bending length c = {c:.4f} m (sd {sd:.4f} m): {args.overhang} m over the '
    f'edge reaching {args.reach} m out (the heavy elastica)'
  )
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
