"""One recording estimated alone against the same recording inside a lockstep.

A calibration study (``experiments.calibrate``) estimates its recordings in one
lockstep (``estimation.estimate_many``: one device program per step for all). This
script estimates some of them again, one at a time in one process, with the
settings and seed its estimate ran with (its ``estimate.json``), and prints per quantity the median and 90%
interval of each, and the time of each single estimate (the first includes the
compile; the later ones are the latency after compile).

  python -m benchmarks.single_vs_batched --workdir=/tmp/cal_paper \\
      --seqs=0000,0010 --out=$OUT/single_vs_batched.json

``--image_size`` must be the one the study read its recordings at
(``calibration.image_size``: 256 at the paper's size, 32 at the demo's).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time

from experiments.pipeline import cli, estimation, files, layout, search
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import recording as recording_lib
from experiments.pipeline.objective import EstimateConfig


@dataclasses.dataclass(frozen=True)
class Args:
  """The comparison.

  Attributes:
    workdir: a calibration study's workdir with finished estimates.
    image_size: pixels a side its recordings were read at.
    seqs: the recordings to estimate alone (their estimates' folder names).
    out: JSON path.
  """

  workdir: str = cli.required('')
  image_size: int = 256
  seqs: tuple[str, ...] = ('0000', '0010')
  out: str = 'out/benchmarks/single_vs_batched.json'


PRESETS = {'default': Args()}


def _summary(result: dict) -> dict:
  return {
    f: [result['estimate'][f]['median'], *result['estimate'][f]['interval_90']]
    for f in posterior_lib.FIELDS
  }


def main(args: Args) -> None:
  evaluator = search.Evaluator()
  rows = []
  for seq in args.seqs:
    batched = recording_lib.read_json(
      os.path.join(args.workdir, 'estimates', seq, layout.ESTIMATE_FILE)
    )
    est = EstimateConfig.from_flat(batched['config'])
    recording = recording_lib.load_recording(
      batched['recording'], fps=est.simulation.fps,
      size=(args.image_size, args.image_size), frames=est.simulation.frames,
    )  # fmt: skip
    t0 = time.perf_counter()
    alone = estimation.estimate(
      est, recording, '',
      os.path.join(args.workdir, 'alone', seq), progress=False, evaluator=evaluator,
    )  # fmt: skip
    rows.append({
      'seq': seq, 'material': batched['material'],
      'seconds': time.perf_counter() - t0,
      'objective_s': alone.get('seconds_in_objective'),
      'search_s': alone.get('seconds_in_search'),
      'alone': _summary(alone), 'batched': _summary(batched),
      'recordings_in_batch': batched.get('recordings_in_batch'),
    })  # fmt: skip
  files.write_json(args.out, rows)
  print('| recording | quantity | alone: median [90%] | in the batch | seconds alone |')
  print('|---|---|---|---|---|')
  for r in rows:
    for f in posterior_lib.FIELDS:
      a, b = r['alone'][f], r['batched'][f]
      print(f'| {r["seq"]} {r["material"]} | {f} | {a[0]:.3g} [{a[1]:.3g}, {a[2]:.3g}] '
            f'| {b[0]:.3g} [{b[1]:.3g}, {b[2]:.3g}] | {r["seconds"]:.1f} |')  # fmt: skip
  print(json.dumps({'out': args.out}))


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
