"""Check an exported fabric on a recording it was not estimated from.

  python -m experiments.validate --fabric=out/estimate/fabric_25x25 \\
      --recording=capture/fan2 --camera_json=capture/camera.json --world_up=z \\
      --cloth_size=1 --wind_speed=2.4

Simulates the export's fabric (``experiments.export``) in the recording's
set-up (its camera, its sheet, the anemometer's wind) with several gust seeds,
and prints how far the prediction's mean shape lies from the recording's,
against the recording's own noise floor (the same fabric, other gust seeds)
and against the library's default fabric; writes ``validate.json`` and
``validate.png`` (the recording beside the prediction) into ``--out``
(``experiments.pipeline.validation``).
"""

from __future__ import annotations

import dataclasses
import os

from experiments.pipeline import cli, files, intake, validation


@dataclasses.dataclass(frozen=True)
class Args:
  """An export, and a recording it was not estimated from.

  Attributes:
    fabric: an export's folder (``fabric.json`` and ``fabric.xml``).
    recording: the recording (frames, .npy/.npz or a bag), not one the
      estimate used.
    camera_json: its camera file (needed: the prediction is seen through it).
    cloth_size: its sheet's side, m (0: the export's); must be the export's.
    wind_speed: the anemometer's reading at the sheet, m/s.
    out: where validate.json and validate.png go ('': beside the export,
      ``<fabric>/validate_<recording>``).
    settings: how the prediction is simulated and compared.
    intake: how the recording is read and aligned (as the estimate's).
  """

  fabric: str = cli.required()
  recording: str = cli.required()
  camera_json: str = ''
  cloth_size: float = 0.0
  wind_speed: float = 0.0
  out: str = ''
  settings: validation.Settings = validation.Settings()
  intake: intake.IntakeConfig = cli.nested(
    intake.IntakeConfig(), skip=('allow_no_camera',)
  )


def main(args: Args) -> dict:
  cli.check_numbers(args)
  args.settings.check()
  args.intake.check()
  exported = validation.read_export(args.fabric)
  validation.check_set_up(
    exported, args.recording, args.camera_json, args.cloth_size or exported.size,
    args.wind_speed,
  )  # fmt: skip
  taken, rec = validation.take_in(
    exported, args.recording, args.camera_json, args.intake, args.settings
  )
  result = validation.predict(exported, rec, args.wind_speed, args.settings)
  for line in validation.report(exported, args.recording, result, taken.alignment_sd):
    print(line)
  name = os.path.basename(os.path.normpath(args.recording)) or 'recording'
  out = args.out or os.path.join(args.fabric, f'validate_{name}')
  record = {
    'fabric': os.path.abspath(args.fabric), 'recording': os.path.abspath(args.recording),
    'camera_json': os.path.abspath(args.camera_json) if args.camera_json else '',
    **result.record(), 'verdict': validation.verdict(result),
    'alignment_sd': {'m': taken.alignment_sd[0], 'deg': taken.alignment_sd[1]},
    'settings': dataclasses.asdict(args.settings),
  }  # fmt: skip
  files.write_json(os.path.join(out, validation.RESULT_FILE), record)
  validation.figure(
    exported, args.recording, result, os.path.join(out, validation.FIGURE_FILE)
  )
  print(f'wrote {out}/{validation.RESULT_FILE}, {out}/{validation.FIGURE_FILE}')
  return record


if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
