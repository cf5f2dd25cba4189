"""A protocol set to time and check a joint estimate of the fabric: a sheet
recording and an overhang recording of the same truth, in a protocol file.

Given a dataset sequence of the 1 m sheet (``experiments.generate_dataset``,
e.g. ``--preset=eval --physics=mismatched``), writes beside it, under
``--out``: a depth recording of the same fabric's strip over a table's edge
(``physsim.tabletop.write_recording``: the heavy elastica of the truth's
bending length, slid about three bending lengths over, read off 5 mm marks)
and ``protocol.json`` naming both, the sheet with a simulated anemometer
reading of its wind (``--reading_sd``). Then time the estimate a user runs:

  python -m experiments.generate_dataset --preset=eval --materials=gray_interlock \\
      --sequences=1 --physics=mismatched --out=/tmp/ev
  python -m benchmarks.protocol_set --sequence=/tmp/ev/gray_interlock/0000 --out=/tmp/pset
  python -m experiments.estimate --protocol=/tmp/pset/protocol.json --distance=shape \\
      --material=gray_interlock --workdir=/tmp/pe
"""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np

import physsim
from experiments.pipeline import cli, files
from physsim import overhang_depth, tabletop


@dataclasses.dataclass(frozen=True)
class Args:
  """The sheet recording and where the set goes.

  Attributes:
    sequence: a dataset sequence folder of the sheet (its meta.json holds
      the truth).
    material: its fabric.
    reading_sd: the anemometer's relative standard error.
    seed: of the reading.
    out: the set's folder (created).
  """

  sequence: str = cli.required()
  material: str = 'gray_interlock'
  reading_sd: float = 0.02
  seed: int = 0
  out: str = 'out/benchmarks/protocol_set'


PRESETS = {'default': Args()}


def main(args: Args) -> None:
  meta_path = os.path.join(args.sequence, 'meta.json')
  try:
    with open(meta_path) as f:
      meta = json.load(f)
    b, w, v = (float(meta[k]) for k in ('bending_scale', 'area_weight', 'wind_speed'))
  except (OSError, ValueError, KeyError) as e:
    raise ValueError(f'--sequence={args.sequence}: no dataset truth there ({e})') from e
  if not (0 <= args.reading_sd < 1):
    raise ValueError(f'--reading_sd={args.reading_sd}: need 0 <= sd < 1')
  space = physsim.search_space(args.material)
  c = float(physsim.params.bending_length(b, w, space.rigidity))
  # README's overhang in bending lengths, read off the strip's 5 mm marks
  length = max(0.015, round(overhang_depth.PROTOCOL_RATIO * c * 200) / 200)
  os.makedirs(args.out, exist_ok=True)
  tabletop.write_recording(args.out, tabletop.Strip(length, c))
  reading = v * (
    1 + args.reading_sd * np.random.default_rng(args.seed).standard_normal()
  )
  files.write_json(os.path.join(args.out, 'protocol.json'), {
    'recordings': [{'recording': os.path.abspath(args.sequence), 'wind_speed': reading,
                    'wind_speed_sd': args.reading_sd * v}],
    'fabric': {'overhang': {'recording': 'strip', 'camera_json': 'strip_camera.json',
                            'length': length}},
  })  # fmt: skip
  print(
    f'truth: bending {b:.3f}, area weight {w:.4f} kg/m^2, wind {v:.3f} m/s, c '
    f'{c:.4f} m; the strip {length} m over the edge; '
    f'{os.path.join(args.out, "protocol.json")}'
  )


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
