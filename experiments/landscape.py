r"""The estimate's objective landscape around a known truth, and what physics tells apart.

  python -m experiments.landscape --recording=out/demo/recording/gray_interlock/0000 \
      --model=out/demo/model/gray_interlock --workdir=out/landscape --preset=smoke

What it evaluates and writes: ``experiments.studies.landscape``.
"""

from __future__ import annotations

import dataclasses
import json

from absl import logging

from experiments.pipeline import cli
from experiments.studies import landscape as landscape_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """A landscape study from the command line.

  Attributes:
    recording: a dataset sequence folder with ground truth (meta.json).
    model: a trained PhySNet run (none with --distance=shape).
    image_size: pixels a side of the frames without a network.
    workdir: PNGs, JSON and the resumable state go here.
    study: what is evaluated.
  """

  recording: str = cli.required()
  model: str = ''
  image_size: int = 256
  workdir: str = 'out/landscape'
  study: landscape_lib.Config = landscape_lib.Config()


PRESETS = {k: Args(study=v) for k, v in landscape_lib.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  result = landscape_lib.run(
    args.study, args.recording, args.model, args.workdir, args.image_size
  )
  print(json.dumps({k: result[k] for k in ('truth', 'truth_ratio', 'psd_truth')}))
  print(json.dumps({'grid_argmin': result['grid']['argmin']}))
  print('psd_vs_ratio', json.dumps(result['grid']['psd_vs_ratio']))
  for s in landscape_lib.STATS:
    print(s, json.dumps(result['identifiability'][s]))


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
