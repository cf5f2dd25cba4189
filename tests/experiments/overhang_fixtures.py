"""A depth recording of a strip over a table's edge as a depth camera's tools
write it: 16-bit PNG frames in mm (rendered by the project's ray-caster from
``physsim.tabletop``'s scene) and the camera's OpenCV-style JSON."""

from __future__ import annotations

import json
import os

import cv2
import numpy as np

import physsim
from physsim import render, tabletop

INTR = physsim.Intrinsics(320, 240, 58.0, 45.0)


def write_overhang_recording(root: str, bending_length: float = 0.02,
                             overhang: float = 0.04) -> tuple[str, str]:  # fmt: skip
  """(the frames' folder, the camera file) under ``root``."""
  table = tabletop.Table()
  pose = tabletop.camera(table, 0.4, 28.0, 10.0)
  v, f = tabletop.scene(
    tabletop.Strip(overhang, bending_length), table,
    floor_to_y=float(np.asarray(pose.position)[1]) - 0.05,
  )  # fmt: skip
  depth = np.asarray(render.depth_image(v, f, INTR, pose))
  frames = os.path.join(root, 'strip')
  os.makedirs(frames)
  for k in range(3):
    mm = np.round(depth * 1000).astype(np.uint16)
    cv2.imwrite(os.path.join(frames, f'{k:04d}.png'), mm)
  cam = os.path.join(root, 'strip_camera.json')
  with open(cam, 'w') as fh:
    json.dump({'width': INTR.width, 'height': INTR.height, 'fx': INTR.fx,
               'fy': INTR.fy, 'cx': INTR.cx, 'cy': INTR.cy}, fh)  # fmt: skip
  return frames, cam
