r"""A fabric's bending length from an overhang: a ruler's reading or a depth recording (issue 39).

  python -m experiments.overhang --overhang=0.06 --reach=0.045
  python -m experiments.overhang --overhang=0.05 --depth=strip_frames/ \
      --camera_json=camera.json --figure=overhang.png   # a depth camera instead
  python -m experiments.overhang --overhang=0.06 --reach=0.045 --ruler_sd=0.002 \
      --material=gray_interlock --area_weight=0.21
  python -m experiments.overhang --overhang=0.06,0.06,0.06,0.06 \
      --reach=0.045,0.043,0.046,0.044      # both ends, face up and down (ASTM D1388)

Slide a strip of the fabric over a table's edge by ``--overhang`` metres
(measured along the strip from the point of it above the table's front face),
then read how far its free end reaches out from that face, horizontally
(``--reach``). On a rounded edge the strip bends from where the rounding
starts, about its radius behind the face: give the radius
(``--edge_radius``, with ``--edge_radius_sd``) and the elastica starts there,
its overhang and reach that much longer. The heavy elastica
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

With ``--depth`` (one recording per overhang: a folder of 16-bit PNG frames in
mm, an .npy/.npz or a video, as estimates read them) and ``--camera_json`` (its
intrinsics, an OpenCV-style JSON file) the reach is not read by hand: the
strip's whole hanging curve is found in the frames and the elastica fitted
to it (``physsim.overhang_depth``; film the table's edge from in front,
0.35-0.55 m away and 20-40 degrees above the table's top, the strip and the
front of the table's top board in view, a few still frames). ``--ruler_sd``
is then the uncertainty of the overhang read off the strip's marks.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

import physsim
from experiments.pipeline import cli, files
from physsim import cantilever, overhang_depth


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
    depth: depth recordings of the overhangs instead of reaches (one per
      overhang).
    camera: the depth camera's file (intrinsics; required with ``depth``);
      ``--camera_json`` as in ``experiments.estimate`` (``--camera`` is its
      older name).
    depth_scale: metres per unit of 16-bit PNG frames.
    figure: a PNG of what was read from the recordings ('' for none).
    edge_radius: the rounding of the table's edge, m, where measured (0: a
      sharp edge); negative (the default): not measured, a depth reading
      fits it from the frames and a ruler's takes the edge as sharp.
    edge_radius_sd: its standard uncertainty, m (a ruler's reading).
  """

  overhang: tuple[float, ...] = ()
  reach: tuple[float, ...] = ()
  ruler_sd: float = 0.001
  material: str = ''
  area_weight: float = 0.0
  area_weight_sd: float = 0.0
  depth: tuple[str, ...] = ()
  camera: str = cli.renamed('', 'camera_json', aliases=('camera',))
  depth_scale: float = 0.001
  figure: str = ''
  edge_radius: float = -1.0
  edge_radius_sd: float = 0.0


PRESETS = {'default': Args()}


def reading(args: Args) -> dict:
  """The bending length (the readings' mean) and, with an area weight, the
  rigidity and bending scale, each with its standard uncertainty (SI units);
  ``readings``: each overhang's own bending length.

  Raises:
    ValueError: naming the flag of a reading out of range.
  """
  readings = args.depth or args.reach
  what = '--depth' if args.depth else '--reach'
  if args.depth and args.reach:
    raise ValueError('--depth and --reach: give one or the other')
  if not args.overhang or len(args.overhang) != len(readings):
    raise ValueError(
      f'--overhang={",".join(map(str, args.overhang))} {what}='
      f'{",".join(map(str, readings))}: need one {what[2:]} per overhang, at least one'
    )
  for name in ('ruler_sd', 'area_weight', 'area_weight_sd', 'edge_radius_sd'):
    v = getattr(args, name)
    if not (math.isfinite(v) and v >= 0):
      raise ValueError(f'--{name}={v}: need a finite value >= 0 (metres, kg/m^2)')
  if args.material and args.material not in physsim.FABRICS:
    raise ValueError(
      f'--material={args.material!r}: not one of {sorted(physsim.FABRICS)}'
    )
  if args.depth:
    found = [
      _from_depth(o, path, args)
      for o, path in zip(args.overhang, args.depth, strict=True)
    ]
    each = [(r.bending_length, r.bending_length_sd) for r in found]
  else:
    found = []
    each = [
      _one(o, r, args.ruler_sd, max(args.edge_radius, 0.0), args.edge_radius_sd)
      for o, r in zip(args.overhang, args.reach, strict=True)
    ]
  cs = np.array([c for c, _ in each])
  c = float(cs.mean())
  c_sd = math.sqrt(sum(sd**2 for _, sd in each)) / len(each)  # the ruler's
  if len(each) > 1:  # or the readings' own scatter, whichever is larger
    c_sd = max(c_sd, float(cs.std(ddof=1)) / math.sqrt(len(each)))
  out = {'bending_length': c, 'bending_length_sd': c_sd, 'readings': cs.tolist()}
  if found:
    # a depth camera's readings err as its t law; their mean keeps it (its
    # tails are a little lighter: the interval errs wide)
    out['bending_length_dof'] = overhang_depth.DOF
    out['depth_readings'] = found
  if args.area_weight > 0:
    d = cantilever.rigidity(c, args.area_weight)
    rel = math.hypot(3 * c_sd / c, args.area_weight_sd / args.area_weight)
    out.update(rigidity=d, rigidity_sd=d * rel)
    if args.material:
      d0 = physsim.search_space(args.material).rigidity  # as estimates read it
      out.update(bending_scale=d / d0, bending_scale_sd=d * rel / d0)
  return out


def _from_depth(overhang: float, path: str, args: Args) -> overhang_depth.Reading:
  """One depth recording's reading, refusals naming the file or flag."""
  if not args.camera:
    raise ValueError(f"--depth={path}: needs --camera_json (the depth camera's file)")
  known = args.edge_radius if args.edge_radius >= 0 else None
  return overhang_depth.read_recording(
    path, args.camera, overhang, args.ruler_sd, args.depth_scale,
    known_radius=known,
  )  # fmt: skip


def _one(overhang: float, reach: float, ruler_sd: float, radius: float = 0.0,
         radius_sd: float = 0.0) -> tuple[float, float]:  # fmt: skip
  """One reading's bending length and its sd, refusals naming the flags. Both
  are measured from the front face; on an edge rounded by ``radius`` the
  strip bends from that far behind it (``physsim.tabletop``), so the
  elastica's overhang and reach are each ``radius`` longer; its sd
  (``radius_sd``) adds by a secant over +-1 sd, as the ruler's do."""
  flags_ = f'--overhang={overhang} --reach={reach}'
  if not (math.isfinite(overhang) and 0 < overhang <= 1.0):
    raise ValueError(f'{flags_}: need 0 < overhang <= 1 m')
  if not (math.isfinite(reach) and 0 < reach < overhang):
    raise ValueError(
      f'{flags_}: the free end reaches out less than the overhang and more than 0'
    )
  if not (math.isfinite(radius) and 0 <= radius < overhang):
    raise ValueError(f'--edge_radius={radius}: need 0 <= radius < the overhang (m)')
  try:
    c, sd = cantilever.bending_length_sd(
      overhang + radius, reach + radius, ruler_sd, ruler_sd
    )
    if radius_sd > 0:
      up, down = (
        cantilever.bending_length(overhang + r, reach + r)
        for r in (radius + radius_sd, max(radius - radius_sd, 0.0))
      )
      sd = math.hypot(sd, (up - down) / 2)
  except ValueError as e:
    raise ValueError(f'{flags_}: {e}') from None
  return c, sd


def main(args: Args) -> None:
  r = reading(args)
  c, sd = r['bending_length'], r['bending_length_sd']
  n = len(r['readings'])
  if args.depth:
    for path, d in zip(args.depth, r['depth_readings'], strict=True):
      print(
        f'{path}: {d.points} strip pixels, the elastica of {d.overhang:.4f} m over '
        f'{d.ratio:.2f} bending lengths fits them to {1000 * d.residual_m:.2f} mm '
        f'(RMS): reach {d.reach:.4f} m, drop {d.drop:.4f} m (from the front face); '
        f'the edge rounded {1000 * d.edge_radius:.1f} mm (sd {1000 * d.edge_radius_sd:.1f})'
      )
      if hint := overhang_depth.advice(d):
        print(f'{path}: {hint}')
    if args.figure:
      plot(args.depth, r['depth_readings'], args.figure)
  first = f'{args.reach[0]} m out' if args.reach else f'as {args.depth[0]} shows it'
  what = (
    f'{args.overhang[0]} m over the edge reaching {first}'
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
  dof = r.get('bending_length_dof', 0.0)
  flag = f' --bending_length_dof={dof:g}' if dof else ''
  key = f', "bending_length_dof": {dof:g}' if dof else ''
  print(
    f'estimate with: --bending_length={c:.4g} --bending_length_sd={sd:.2g}{flag} '
    f'(or a protocol file\'s "fabric": {{"bending_length": {c:.4g}, '
    f'"bending_length_sd": {sd:.2g}{key}}})'
  )


def plot(paths, readings, path: str) -> None:
  """Each recording's strip pixels and the fitted elastica, side view."""
  import matplotlib

  matplotlib.use('Agg')
  import matplotlib.pyplot as plt

  fig, axes = plt.subplots(
    1, len(readings), figsize=(4.5 * len(readings), 4), squeeze=False
  )
  for ax, name, d in zip(axes[0], paths, readings, strict=True):
    p = d.profile[:: max(1, len(d.profile) // 3000)]
    ax.plot(100 * p[:, 0], -100 * p[:, 1], '.', ms=1.5, alpha=0.4, label='strip pixels')
    line = cantilever.shape(d.ratio) * d.overhang
    ax.plot(100 * line[:, 0], -100 * line[:, 1], 'r-',
            label=f'elastica, c = {100 * d.bending_length:.2f} cm')  # fmt: skip
    ax.axhline(0, color='0.6', lw=0.8)
    ax.axvline(0, color='0.6', lw=0.8)
    ax.set_aspect('equal')
    ax.set_xlabel('out from the edge (cm)')
    ax.set_ylabel('height above the table (cm)')
    ax.set_title(os.path.basename(os.path.normpath(name)), fontsize=9)
    ax.legend(fontsize=7, loc='lower left')
  fig.tight_layout()
  files.savefig(fig, path, dpi=110)
  plt.close(fig)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
