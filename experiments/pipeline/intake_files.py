"""What the intake writes into a workdir, and the recording it hands on.

``write`` saves ``intake.json`` (``to_json``), ``overlay.png`` (``overlay``:
the recording's cloth with the simulated cloth's outline and the pins, for the
user to check the alignment) and the cleaned frames (``intake/NNNN.png``,
16-bit mm, own resolution), all of them or none; ``check_workdir`` refuses,
before anything is written, a workdir that holds another recording's intake
or estimate. ``to_recording`` resamples the cleaned frames to the
comparison's rate and the network's image size.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import cv2
import numpy as np

import physsim
from experiments.pipeline import cloth_view, files, simulation
from experiments.pipeline import recording as recording_lib
from experiments.pipeline.intake_record import Intake
from physsim import dataset, video

INTAKE_FILE = 'intake.json'
OVERLAY_FILE = 'overlay.png'
FRAMES_DIR = 'intake'


def to_json(intake: Intake) -> dict:
  """``intake.json``'s content."""
  pose = physsim.pose_to_dict(intake.pose) if intake.pose is not None else None
  pins = intake.pins_camera.tolist() if intake.pins_camera is not None else None
  return {
    'source': os.path.abspath(intake.source),
    'fps': intake.fps,
    'frames': int(len(intake.depth)),
    'source_frames': intake.source_frames.tolist(),
    'resolution': [int(intake.depth.shape[2]), int(intake.depth.shape[1])],
    'pins_camera': pins,
    'up_from': intake.up_from,
    'camera_form': intake.camera_form,
    'camera_file': os.path.abspath(intake.camera_file) if intake.camera_file else '',
    'intrinsics': intake.intrinsics.to_dict() if intake.intrinsics else None,
    'pose_in_simulator': pose,
    'valid_fraction': intake.valid_fraction.tolist(),
    'cloth_fraction': intake.cloth_fraction.tolist(),
    'overlap_iou': intake.overlap,
    'swing_deg': intake.swing_deg,
    'overlap_frame': intake.overlap_frame,
    'background_planes': [{'normal': n, 'offset': o} for n, o in intake.planes],
    'warnings': list(intake.warnings),
    'alignment_sd': {'m': intake.alignment_sd[0], 'deg': intake.alignment_sd[1]},
    'up_is_guess': intake.up_is_guess,
  }


def overlay(intake: Intake, mesh) -> np.ndarray:
  """BGR picture: the depth of the frame that best matched the simulated
  cloth (``overlap_frame``; grey, removed background dark blue) with the
  simulated cloth's outline (red) and the pins (green), over a legend that
  says so (``with_legend``)."""
  first = intake.depth[min(intake.overlap_frame, len(intake.depth) - 1)]
  valid = first > 0
  img = np.zeros(first.shape + (3,), np.uint8)
  if valid.any():
    lo, hi = np.quantile(first[valid], [0.02, 0.98])
    grey = np.clip(255 * (1 - (first - lo) / max(hi - lo, 1e-6)), 40, 255).astype(
      np.uint8
    )
    img[valid] = grey[valid, None]
  img[~valid] = (60, 20, 0)
  scale = max(1, 480 // max(first.shape))
  img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
  sim = intake.silhouette
  if sim is None and intake.pose is not None and intake.intrinsics is not None:
    sim = cloth_view.silhouettes(
      mesh, cloth_view.outer_pins(mesh), intake.intrinsics, intake.pose, (0.0,)
    )[0]
  if sim is not None:
    sim = sim.astype(np.uint8)
    sim = cv2.resize(sim, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    contours, _ = cv2.findContours(sim, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, (0, 0, 255), 1)
  if intake.pins_camera is not None and intake.intrinsics is not None:
    k = intake.intrinsics.matrix()
    for p in intake.pins_camera:
      u, v, z = k @ p
      if z > 0:
        centre = (int(round((u / z + 0.5) * scale)), int(round((v / z + 0.5) * scale)))
        cv2.circle(img, centre, max(3, scale), (0, 255, 0), 2)
  return with_legend(img)


# What the overlay's colours mean (BGR), drawn under the picture.
LEGEND = (
  ((0, 0, 255), 'simulated cloth outline'),
  ((0, 255, 0), 'pins found'),
  ((200, 200, 200), 'depth (near: light)'),
  ((60, 20, 0), 'background removed'),
)


def with_legend(img: np.ndarray) -> np.ndarray:
  """``img`` (BGR) over a band that names each colour of ``LEGEND``."""
  row = 18
  band = np.full((row * len(LEGEND) + 6, img.shape[1], 3), 255, np.uint8)
  for k, (colour, text) in enumerate(LEGEND):
    y = 4 + k * row
    band[y + 2 : y + row - 4, 4:18] = colour
    cv2.putText(band, text, (24, y + row - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                (0, 0, 0), 1, cv2.LINE_AA)  # fmt: skip
  return np.concatenate([img, band], axis=0)


def check_workdir(workdir: str, path: str, camera_json: str, run_file: str) -> None:
  """Refuses, before anything is written, an intake of ``path`` into a
  workdir that holds another recording's intake (``intake.json`` of another
  source), or a search (``run_file``) of another recording or camera file.

  Raises:
    ValueError: naming the workdir's file and what differs.
  """
  old_path = os.path.join(workdir, INTAKE_FILE)
  run = os.path.join(workdir, run_file)
  if not os.path.exists(old_path):
    if os.path.exists(run):
      raise ValueError(
        f'{run}: the workdir holds an estimate of a recording that was not taken '
        f'in here, not of {path}; use another --workdir'
      )
    return
  old = recording_lib.read_json(old_path)
  source = old.get('source') if isinstance(old, dict) else None
  if source != os.path.abspath(path):
    raise ValueError(
      f'{old_path}: the workdir holds the intake of {source}, not of {path}; use '
      'another --workdir'
    )
  camera = os.path.abspath(camera_json) if camera_json else ''
  if os.path.exists(run) and old.get('camera_file', camera) != camera:
    raise ValueError(
      f'{old_path}: the workdir holds an estimate with a different camera file '
      f'({old.get("camera_file") or "none"}, not {camera or "none"}); use another '
      '--workdir'
    )


def write(
  intake: Intake, workdir: str, sim: simulation.Simulation, *, frames: bool = True
) -> None:
  """Saves ``intake.json``, ``overlay.png`` and (``frames``) the cleaned
  frames as 16-bit mm PNGs in ``intake/`` (``sim``: the estimate's
  ``Simulation``, for the simulated cloth): all of them, or none. Each is
  written under a temporary folder first and renamed into place only when
  every one is complete, ``intake.json`` last: a full disk leaves no
  ``overlay.png`` without its ``intake.json``.

  Raises:
    ValueError: "disk full" naming the file that did not fit.
  """
  os.makedirs(workdir, exist_ok=True)
  img = overlay(intake, simulation.mesh(sim))
  tmp = tempfile.mkdtemp(prefix='.intake-', dir=workdir)
  try:
    dataset.imwrite(os.path.join(tmp, OVERLAY_FILE), img)
    if frames:
      staged = os.path.join(tmp, FRAMES_DIR)
      os.makedirs(staged)
      mm = dataset.depth_to_mm(intake.depth)
      for t, f in enumerate(mm):
        dataset.imwrite(os.path.join(staged, f'{t:04d}.png'), f)
      with open(os.path.join(staged, 'fps.txt'), 'w') as f:
        f.write(f'{intake.fps:g}\n')
      os.chmod(staged, dataset.user_mode(0o777))
    files.write_json(os.path.join(tmp, INTAKE_FILE), to_json(intake))
    for name in (OVERLAY_FILE, INTAKE_FILE):
      os.chmod(os.path.join(tmp, name), dataset.user_mode(0o666))
    # Into place: the frames, the overlay, then intake.json (the run's mark).
    if frames:
      final = os.path.join(workdir, FRAMES_DIR)
      if os.path.isdir(final):
        shutil.rmtree(final)
      os.replace(staged, final)
    os.replace(os.path.join(tmp, OVERLAY_FILE), os.path.join(workdir, OVERLAY_FILE))
    os.replace(os.path.join(tmp, INTAKE_FILE), os.path.join(workdir, INTAKE_FILE))
  except OSError as e:
    if dataset.is_disk_full(e):
      raise dataset.disk_full(getattr(e, 'filename', None) or workdir, e) from None
    raise
  finally:
    shutil.rmtree(tmp, ignore_errors=True)


def to_recording(intake: Intake, fps: float, size: tuple[int, int], frames: int):
  """The ``recording.Recording`` the search compares: the cleaned frames at
  ``fps`` (nearest in time) and ``size`` (nearest), the camera resized."""
  pos = video.resample_indices(len(intake.depth), intake.fps, fps)[:frames]
  depth = video.resample_frames(intake.depth, pos, 'nearest')
  depth = video.resize_frames(depth, tuple(size), 'nearest')
  intr = intake.intrinsics.resized(size[1], size[0]) if intake.intrinsics else None
  return recording_lib.Recording(
    np.ascontiguousarray(depth, np.float32), fps, intr, intake.pose, intake.source,
    intake.truth,
  )  # fmt: skip
