r"""Estimate a fabric's bending, area weight and the wind from one depth video.

  python -m experiments.estimate --recording=PATH --material=gray_interlock \
      --model=out/table1/physnet_depth/simulation/gray_interlock --workdir=out/estimate

Writes ``estimate.json``, ``trace.png`` and ``montage.png`` into ``--workdir``
and resumes from what it holds (``experiments.pipeline.search``).
"""

from __future__ import annotations

import dataclasses

from absl import logging

from experiments.pipeline import cli, embedding, report, search
from experiments.pipeline import objective as objective_lib
from experiments.pipeline import recording as recording_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """One estimate from the command line.

  Attributes:
    recording: the depth video: a folder of 16-bit PNGs in mm, .npy/.npz in
      metres, a video file, or a dataset sequence folder (meta.json, cam0/).
      Several, comma-separated: one fabric in several recordings (e.g. two
      fan settings), estimated jointly (one bending and area weight, one wind
      each).
    model: the material's trained network (a train or table1 run folder).
    workdir: where the search state, estimate.json and the pictures go.
    camera_json: the recording's camera as {"intrinsics": ..., "extrinsics":
      ...}; empty: unknown (training-like cameras are used).
    allow_other_material: search with a network trained on another fabric
      than material.
    search: the estimate's settings.
  """

  recording: tuple[str, ...] = ()
  model: str = cli.required()
  workdir: str = 'out/estimate'
  camera_json: str = ''
  allow_other_material: bool = False
  search: objective_lib.EstimateConfig = objective_lib.EstimateConfig()


PRESETS = {k: Args(search=v) for k, v in objective_lib.PRESETS.items()}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  config = args.search
  config.check()
  net = embedding.load_embedding(args.model)
  if (
    net.materials
    and config.material not in net.materials
    and not args.allow_other_material
  ):
    raise ValueError(
      f'{args.model} was trained on {list(net.materials)}, not {config.material}; '
      'pass --allow_other_material to search with it anyway'
    )
  if not args.recording:
    raise ValueError('missing --recording (see --help)')
  recs = [
    recording_lib.load_recording(
      path,
      fps=config.fps,
      size=net.image_size,
      frames=config.frames,
      camera_json=args.camera_json or None,
      rgb=net.modality == 'rgb',
    )  # fmt: skip
    for path in args.recording
  ]
  if len(recs) > 1:
    result = search.estimate_joint(config, recs, args.model, args.workdir)
    print(report.joint_table(result))
    return
  result = search.estimate(config, recs[0], args.model, args.workdir)
  print(report.report_table(result))
  print(f'estimate.json and pictures in {args.workdir}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
