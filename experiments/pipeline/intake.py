"""A user's recording in: its camera, its clip, its background, its cloth.

``take_in`` turns a depth recording as a camera wrote it into what the search
compares against simulations, in the recording's own terms (resolution, frame
rate), and checks it before any simulation runs:

1. **camera**: any form ``physsim.camera_files`` reads (OpenCV JSON, ROS
   CameraInfo YAML, RealSense/Open3D intrinsics, this project's); lens
   distortion is undone with OpenCV; the file's ``fps`` is the recording's
   frame rate unless ``--fps`` says otherwise;
2. **clip**: frames from ``start`` covering the compared duration (``frames``
   at the comparison rate), their unit from ``depth_scale``;
3. **background** (``physsim.scene``): ``depth_range``, a mask image or
   folder, floor and wall planes, and all but the largest region removed;
   the kept cloth share of each frame reported;
4. **alignment** (``physsim.alignment``): the pins given by the user or
   fitted, up from a floor (else the cloth plane), and from them the camera's
   pose in the simulator's world. A camera file in this project's own form
   (a simulated recording) already has that pose and is not refitted;
5. **checks**: the pins as far apart as the simulated cloth's (within 20%),
   the cloth in view from the pose, and the simulated cloth's silhouette
   overlapping the recording's (IoU >= ``min_overlap``); else it refuses,
   after writing the overlay that shows why.

A dataset sequence folder (``meta.json`` beside ``cam0/``) is this project's
own simulation: it has no background and its camera is in the simulator's
world, so it passes through unchanged.

``take_in`` runs these steps in order; each lives where its concept does:
``intake_record`` (``IntakeConfig``, the ``Intake`` taken in, its summary),
``intake_frames`` (steps 1-3: the frames, the camera, the clip, the
background), ``intake_alignment`` (steps 4-5: the pose and its checks),
``cloth_view`` (the simulated cloth as the camera sees it) and
``intake_files`` (``write`` saves ``intake.json``, ``overlay.png`` and the
cleaned frames, ``intake/NNNN.png``, 16-bit mm, own resolution;
``to_recording`` resamples the cleaned frames to the comparison's rate and the
network's image size).
"""

from __future__ import annotations

from experiments.pipeline import intake_alignment, intake_frames, simulation
from experiments.pipeline.intake_record import Intake, IntakeConfig


def take_in(
  path: str,
  config: IntakeConfig,
  camera_json: str,
  sim: simulation.Simulation,
  *,
  workdir: str | None = None,
) -> Intake:
  """Reads, cleans, aligns and checks a recording (module docstring).

  Args:
    path: the recording (a frame folder, .npy/.npz, or a dataset sequence).
    config: the intake settings.
    camera_json: its camera file ('' for none).
    sim: the estimate's ``Simulation`` (comparison rate and length, cloth).
    workdir: where a refused alignment writes its overlay, or None.

  Raises:
    ValueError: naming the file or setting, for anything that would make the
      estimate meaningless.
  """
  config.check()
  if intake_frames.is_sequence(path) and not camera_json:
    return intake_frames.passthrough(path, sim)
  bag = intake_frames.read_bag(path, config)
  cam = intake_frames.read_camera(path, camera_json, bag, config)
  vid, truth = intake_frames.read_video(path, config, cam, bag)
  index, depth, cam = intake_frames.compared_clip(path, vid, cam, sim)
  intr = cam.intrinsics if cam is not None else None
  valid = (depth > 0).reshape(len(depth), -1).mean(axis=1)
  bg = intake_frames.without_background(path, depth, intr, index, config)
  planes = [(p.normal.tolist(), p.offset) for p in bg.planes]
  taken = Intake(
    bg.depth, vid.fps, index + config.start, intr, None, None, '', valid,
    bg.fraction, None, planes, path, truth, cam.form if cam else '',
    camera_file=camera_json, warnings=bag.notes if bag is not None else (),
  )  # fmt: skip
  if cam is None:
    return taken
  return intake_alignment.align(taken, cam, config, sim, bg.planes, workdir)
