r"""Estimate a fabric's bending, area weight and the wind from one depth video.

  # the default: where the sheet hangs (--distance=shape), no network
  python -m experiments.estimate --recording=PATH --material=gray_interlock \
      --workdir=out/estimate

  # through a trained PhySNet: the PSD between embeddings
  python -m experiments.estimate --recording=PATH --material=gray_interlock \
      --distance=energy --model=out/table1/physnet_depth/simulation/gray_interlock \
      --workdir=out/estimate_psd

  # a camera's own recording: its camera file, only the intake (no network)
  python -m experiments.estimate --recording=rec/depth --camera_json=rec/camera.json \
      --intake_only --workdir=out/intake

A recording with a camera file (or any recording that is not a dataset
sequence) is first taken in (``experiments.pipeline.intake``): clipped,
background removed, the cloth found and the camera placed in the simulator's
world; its summary is printed and ``intake.json``, ``overlay.png`` and the
cleaned frames are written before the search. Writes ``estimate.json``,
``trace.png`` and ``montage.png`` into ``--workdir`` and resumes from what it
holds (``experiments.pipeline.search``).

``--help`` lists the flags most estimates need; ``--helpfull`` lists all of them.
"""

from __future__ import annotations

import dataclasses
import os
import sys

from absl import logging

import physsim
from experiments.pipeline import (
  advice,
  cli,
  files,
  intake,
  layout,
  report,
  setup,
  summaries,
  takes,
  user_recordings,
)
from experiments.pipeline import objective as objective_lib
from physsim import overhang_depth


@dataclasses.dataclass(frozen=True)
class Args:
  """One estimate from the command line.

  Attributes:
    recording: the depth video: a folder of 16-bit PNGs in mm, .npy/.npz in
      metres, a ROS 1/2 or RealSense bag (its depth, CameraInfo and IMU
      topics: --depth_topic, --info_topic, --imu_topic), a video file, or a
      dataset sequence folder (meta.json, cam0/).
      Several, comma-separated: one fabric in several recordings (e.g. two
      fan settings), estimated jointly (one bending and area weight, one wind
      each).
    model: the material's trained network (a train or table1 run folder)
      for a distance that embeds (--distance=energy, centroid, energy+shape);
      several, comma-separated: an ensemble of runs of one architecture (each
      video embedded by every member; PSD the geometric mean of theirs). Not
      needed with intake_only, nor with the default --distance=shape (which
      reads the sheet's place from the depth frames themselves; a model given
      with it only sets the frames' size, and a note says so).
    image_size: without a network (--distance=shape, no model), the size
      (pixels a side) the frames are compared at; a network fixes its own.
    workdir: where the search state, estimate.json and the pictures go.
    camera_json: the recording's camera file: OpenCV JSON {"width",
      "height", "fx", "fy", "cx", "cy", "cam_to_world"}, ROS CameraInfo YAML,
      RealSense or Open3D intrinsics JSON, or this project's {"intrinsics",
      "extrinsics"} (physsim.camera_files); empty: unknown (training-like
      cameras are used).
    allow_other_material: search with a network trained on another fabric
      than material.
    intake_only: take the recording in (camera, clip, background, alignment),
      write intake.json, overlay.png and the cleaned frames, and stop.
    wind_speeds: with several recordings: an anemometer's reading at each
      (m/s), in the recordings' order; each recording's search and the joint
      posterior take it as that recording's wind prior (--wind_speed is one
      recording's).
    wind_speed_sds: their standard uncertainties (m/s), one per reading.
    alignment_sd: where the intake placed the camera (a camera file in the
      user's world) and --camera_sd_m and --camera_sd_deg are both 0, the
      posterior carries the intake's estimate of its own error
      (intake_alignment.alignment_error: large in tilt when up came from the
      cloth's plane) as camera_sd_m and camera_sd_deg; --noalignment_sd: trust
      the placement exactly.
    allow_guessed_up: estimate from a recording whose up is a guess from the
      cloth's own plane (no floor in view, no --world_up, --up or "gravity"):
      a cloth the wind swings in the first frames tilts that guess by the
      swing, and the camera with it (issue 40: 2 m too high, the wind read
      at a third). Refused unless this is set; the posterior then carries a
      20-degree tilt (1 sd).
    protocol: a protocol file (JSON or YAML; experiments.pipeline.takes)
      listing the recordings, each with its own camera file, cloth size,
      anemometer reading and up axis, instead of --recording.
    cloth_sizes: with several recordings: each one's cloth side (m), in the
      recordings' order (a sheet and a swatch of one fabric); empty: all
      --cloth_size.
    intake: how the recording is read, cleaned and aligned.
    search: the estimate's settings.
  """

  recording: tuple[str, ...] = ()
  model: str = ''
  image_size: int = 256
  workdir: str = 'out/estimate'
  camera_json: str = ''
  allow_other_material: bool = False
  intake_only: bool = False
  wind_speeds: tuple[float, ...] = ()
  wind_speed_sds: tuple[float, ...] = ()
  alignment_sd: bool = True
  allow_guessed_up: bool = False
  protocol: str = ''
  cloth_sizes: tuple[float, ...] = ()
  intake: intake.IntakeConfig = intake.IntakeConfig()
  search: objective_lib.EstimateConfig = objective_lib.EstimateConfig()


PRESETS = {k: Args(search=v) for k, v in objective_lib.PRESETS.items()}
# What --help lists: the recording, its camera, the fabric, the readings a
# person has; the search's own settings under --helpfull.
KEY_FLAGS = (
  'recording', 'camera_json', 'protocol', 'workdir', 'preset', 'material',
  'distance', 'model', 'intake_only', 'fps', 'depth_scale', 'world_up',
  'cloth_size', 'wind_speed', 'wind_speed_sd', 'area_weight', 'area_weight_sd',
  'bending_length', 'bending_length_sd',
)  # fmt: skip

# What a joint estimate's recordings share (joint.json's entries).
JOINT_SHARED = ('bending_scale', 'area_weight')


def joint_winds(args: Args) -> list[tuple[float, float]] | None:
  """The per-recording wind readings of a joint estimate, or None.

  Raises:
    ValueError: readings without one per recording, or without uncertainties.
  """
  if not args.wind_speeds and not args.wind_speed_sds:
    return None
  n = len(args.recording)
  if n < 2:
    raise ValueError('--wind_speeds is for several recordings; use --wind_speed')
  if len(args.wind_speeds) != n or len(args.wind_speed_sds) != n:
    raise ValueError(
      f'--wind_speeds={",".join(map(str, args.wind_speeds))} and --wind_speed_sds='
      f'{",".join(map(str, args.wind_speed_sds))}: need one reading and one '
      f'uncertainty for each of the {n} recordings'
    )
  if any(v < 0 for v in args.wind_speeds) or any(sd <= 0 for sd in args.wind_speed_sds):
    raise ValueError(
      f'--wind_speeds={",".join(map(str, args.wind_speeds))} and --wind_speed_sds='
      f'{",".join(map(str, args.wind_speed_sds))}: readings must be >= 0 m/s and '
      'their uncertainties > 0'
    )
  return list(zip(args.wind_speeds, args.wind_speed_sds, strict=True))


def recording_takes(args: Args) -> list[takes.Take]:
  """The recordings and each one's own set-up, from --protocol or from
  --recording (with --camera_json, --cloth_sizes, --wind_speeds).

  Raises:
    ValueError: both or neither given, or a bad entry (named), before any
      recording is read.
  """
  if args.protocol:
    if args.recording or args.cloth_sizes or args.wind_speeds or args.camera_json:
      raise ValueError(
        f'--protocol={args.protocol} lists the recordings and their set-ups; give '
        'it without --recording, --camera_json, --cloth_sizes and --wind_speeds'
      )
    return takes.read(args.protocol)
  if not args.recording:
    raise ValueError('missing --recording or --protocol (see --help)')
  if args.cloth_sizes and len(args.recording) < 2:
    raise ValueError('--cloth_sizes is for several recordings; use --cloth_size')
  return takes.from_flags(
    args.recording, args.camera_json, args.cloth_sizes, joint_winds(args)
  )


def with_fabric_readings(args: Args) -> Args:
  """``args`` with the fabric's readings of its protocol file (``"fabric"``:
  area weight, bending length) as the estimate's.

  Raises:
    ValueError: a reading given both in the file and as a flag, naming both.
  """
  if not args.protocol:
    return args
  readings = takes.fabric_readings(args.protocol)
  strip = takes.fabric_overhang(args.protocol)
  if strip is not None:  # the bending length, read once here
    r = overhang_depth.read_recording(
      strip.path, strip.camera_json, strip.length, strip.length_sd, strip.depth_scale
    )
    print(
      f'{strip.path}: bending length {r.bending_length:.4f} m (sd '
      f'{r.bending_length_sd:.4f}) from {r.points} strip pixels over the edge'
    )
    if hint := overhang_depth.advice(r):
      print(f'{strip.path}: {hint}')
    readings.update(bending_length=r.bending_length,
                    bending_length_sd=r.bending_length_sd,
                    bending_length_dof=r.bending_length_dof)  # fmt: skip
  both = sorted(k for k in readings if getattr(args.search.measured, k) != 0.0)
  if both:
    raise ValueError(
      f"--protocol={args.protocol} gives the fabric's {', '.join(both)}: give "
      'them in the file or as flags (--' + ', --'.join(both) + '), not both'
    )
  return dataclasses.replace(args, search=args.search.replace(**readings))


def network(args: Args) -> setup.Network:
  """The estimate's network (``--model``) with its record, or none for
  ``--distance=shape`` (``setup.network``: the library's own checks).

  Raises:
    ValueError: no model for a distance that embeds, a bad ``image_size``, or
      a network of another fabric (unless ``allow_other_material``).
  """
  return setup.network(
    args.model, args.search.scoring.distance, args.image_size,
    args.search.simulation.material,
    allow_other_material=args.allow_other_material,
  )  # fmt: skip


def model_note(args: Args) -> str:
  """A line for a ``--model`` the estimate does not compare through (the
  default distance, the shape, reads the frames themselves), else ''."""
  if not (args.model and args.search.scoring.distance == 'shape'):
    return ''
  return (
    f"note: --model={args.model} only sets the frames' size: --distance=shape (the "
    'default, which reads more: BENCHMARKS.md) needs no network; --distance=energy '
    'compares the frames through it'
  )


def main(args: Args) -> None:
  """Checks every setting, then holds the workdir (one process at a time;
  ``files.locked``) for the intake and the search."""
  logging.set_verbosity(logging.WARNING)  # orbax and jax log every step at INFO
  cli.check_numbers(args)
  args = with_fabric_readings(args)
  args.search.check()
  args.intake.check()
  recorded = recording_takes(args)  # checked before anything is read
  for take in recorded:  # each recording's own settings checked
    user_recordings.take_settings(args.intake, args.search, take)
  if not args.intake_only:  # the simulator's modules load while the intake runs
    physsim.rollout.prefetch(args.search.hardware.backend)
  with files.locked(args.workdir):
    _main(args, recorded)


def _main(args: Args, recorded: list[takes.Take]) -> None:
  n = len(recorded)
  config = args.search
  print(
    f'{config.simulation.material}: {n} recording{"s" * (n > 1)} into {args.workdir}; reading '
    'and aligning, then the first simulations compile (a minute or two on a CPU)',
    flush=True,
  )  # a line within seconds: the first step's output comes much later
  # Before any intake writes: no workdir may hold another recording's run.
  user_recordings.check_workdirs(recorded, args.workdir, args.intake_only)
  if args.intake_only:
    for i, take in enumerate(recorded):
      user_recordings.take_in(
        take, args.intake, config, user_recordings.intake_dir(args.workdir, i, n)
      )
    print(f'intake.json, overlay.png and the cleaned frames in {args.workdir}')
    return
  loaded = network(args)
  if note := model_note(args):
    print(note, flush=True)
  prepared = user_recordings.prepare(
    recorded, args.intake, config, loaded, args.workdir,
    carry_alignment=args.alignment_sd, allow_guessed_up=args.allow_guessed_up,
  )  # fmt: skip
  scoring = prepared.configs[0].scoring
  aligned = any(user_recordings.needs_intake(t) for t in recorded)
  warning = advice.shape_camera_warning(scoring, aligned)
  for line in (warning, advice.synthetic_warning(scoring), *prepared.lines):
    if line:
      print(line)
  drawings = []  # the pictures, drawn once the answer is printed
  # The network restored here is the one the search uses (not restored twice).
  nets = {args.model: loaded.embedding} if args.model else None
  result = user_recordings.estimate(
    recorded, prepared, config, args.model, args.workdir, pictures=drawings,
    allow_other_material=args.allow_other_material, nets=nets,
  )  # fmt: skip
  if n > 1:
    print(report.joint_table(result), flush=True)
    ratios = [summaries.point_of(r['load_ratio']) for r in result['recordings']]
  else:
    print(report.report_table(result), flush=True)
    ratios = [summaries.point_of(result['load_ratio'])]
  record = prepared.record
  for line in (record or {}).get('warnings', []):
    if 'up is a guess' in line:
      print(f'note: {line}')
  for note in (
    advice.fan_setting_note(ratios, config.simulation.material),
    # experiments.plan reads the posterior: one recording's, or the joint's
    advice.next_recording_note(
      result['estimate'] if n == 1 else {k: result[k] for k in JOINT_SHARED},
      prepared.configs[0].measured,
      args.workdir,
    ),  # fmt: skip
  ):
    if note:
      print(note)
  where = os.path.abspath(args.workdir)
  sys.stdout.flush()  # the answer before the pictures are drawn
  for draw in drawings:
    draw()
  if n == 1:
    pictures = (
      ('posterior.png', 'trace.png', 'montage.png')
      if prepared.configs[0].posterior
      else ('trace.png', 'montage.png')
    )
    print(
      f'{where}/estimate.json; pictures: ' + ', '.join(f'{where}/{p}' for p in pictures)
    )
  else:
    print(
      f"{where}/{layout.JOINT_FILE}; each recording's estimate.json and pictures: "
      f'{where}/recording_<k>/'
    )
  print(
    f'the fabric for your simulator (MuJoCo MJCF, ArcSim material, posterior draws): '
    f'python -m experiments.export --workdir={args.workdir}'
  )


if __name__ == '__main__':
  cli.run(Args, PRESETS, main, key_flags=KEY_FLAGS)
