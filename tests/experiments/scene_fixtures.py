"""A recording as a user's depth camera would give it, made without the
project's ray-caster: a simulated cloth in a room (a floor and a wall behind
it) rendered by MuJoCo's own OpenGL renderer, everything expressed in a user
world frame that is rotated (y up) and shifted away from the simulator's, and
the camera's image cropped off-centre, so its principal point is not the image
centre. The camera is written as the OpenCV JSON users write:
``{"width", "height", "fx", "fy", "cx", "cy", "cam_to_world", "fps"}``.

``SceneRecording`` also carries the truth the intake must recover: the pins in
the camera frame and, per frame, the cloth's true pixels (MuJoCo's
segmentation render).
"""

from __future__ import annotations

import json
import os
from typing import NamedTuple

import cv2
import mujoco
import numpy as np

import physsim
from physsim import dataset
from tests import mujoco_gl

WIDTH, HEIGHT = 160, 120
# The render is larger and centred; the crop's offset moves the principal point.
_FULL = (200, 150)
_CROP = (28, 8)  # (x0, y0) of the crop in the full render
_FOVY = 50.0
# The user's world: y up, rotated 40 degrees about it and shifted (metres).
_ANGLE = np.deg2rad(40.0)
_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # z up -> y up
_ABOUT_Y = np.array(
  [
    [np.cos(_ANGLE), 0.0, np.sin(_ANGLE)],
    [0.0, 1.0, 0.0],
    [-np.sin(_ANGLE), 0.0, np.cos(_ANGLE)],
  ]
)
_USER_FROM_SIM = _ABOUT_Y @ _Y_UP  # user = R sim + shift
_USER_SHIFT = np.array([1.3, 0.4, -2.0])
EYE, TARGET = (0.55, -2.1, 1.25), (0.0, 0.2, 1.05)


class SceneRecording(NamedTuple):
  frames: str  # folder of 16-bit mm PNGs
  camera_json: str
  pins_camera: np.ndarray  # (2, 3) left, right
  cloth_masks: np.ndarray  # (T, H, W) bool
  pose_sim: physsim.Pose


def _to_user(points):
  return np.asarray(points, np.float64) @ _USER_FROM_SIM.T + _USER_SHIFT


def _fmt(a):
  return ' '.join(f'{x:.9g}' for x in np.ravel(a))


def _mjcf(verts_user, faces, cam_pos, cam_xyaxes) -> str:
  both = np.concatenate([faces, faces[:, ::-1]])
  # Floor (top at z = 0) and wall (front at y = 1.2) in the simulator's world.
  floor_c, wall_c = _to_user([0.0, 0.6, -0.05]), _to_user([0.0, 1.25, 1.5])
  rot = _USER_FROM_SIM  # box axes: simulator x, y, z in user coordinates
  quat = np.zeros(4)
  mujoco.mju_mat2Quat(quat, rot.ravel())
  return f"""
<mujoco>
  <visual><map znear="0.01" zfar="30"/></visual>
  <asset>
    <mesh name="cloth" vertex="{_fmt(verts_user)}" face="{_fmt(both)}" inertia="shell"/>
  </asset>
  <worldbody>
    <geom name="cloth" type="mesh" mesh="cloth" contype="0" conaffinity="0"/>
    <geom name="floor" type="box" size="3 3 0.05" pos="{_fmt(floor_c)}" quat="{_fmt(quat)}"
      contype="0" conaffinity="0"/>
    <geom name="wall" type="box" size="3 0.05 2" pos="{_fmt(wall_c)}" quat="{_fmt(quat)}"
      contype="0" conaffinity="0"/>
    <camera name="cam" pos="{_fmt(cam_pos)}" xyaxes="{_fmt(cam_xyaxes)}" fovy="{_FOVY}"/>
  </worldbody>
</mujoco>"""


def write_scene_recording(root: str, positions: np.ndarray, faces, fps: float):
  """Renders (T, V, 3) simulator-world cloth positions in the room; writes the
  frames and the camera file under ``root``."""
  pose = physsim.look_at(EYE, TARGET)
  r_sim = np.asarray(pose.rotation, np.float64)
  r_user = _USER_FROM_SIM @ r_sim  # camera axes (OpenCV) in user coordinates
  c_user = _to_user(np.asarray(pose.position))
  xyaxes = np.concatenate([r_user[:, 0], -r_user[:, 1]])  # MuJoCo: y up
  depth, masks = [], []
  x0, y0 = _CROP
  for verts in positions:
    model = mujoco.MjModel.from_xml_string(
      _mjcf(_to_user(verts), faces, c_user, xyaxes)
    )
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    renderer = mujoco_gl.offscreen_renderer(model, _FULL[1], _FULL[0])
    try:
      renderer.enable_depth_rendering()
      renderer.update_scene(data, camera='cam')
      d = np.asarray(renderer.render(), np.float64)
      renderer.disable_depth_rendering()
      renderer.enable_segmentation_rendering()
      renderer.update_scene(data, camera='cam')
      seg = np.asarray(renderer.render())[..., 0]
    finally:
      renderer.close()
    cloth_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, 'cloth')
    d = np.where(d < 25.0, d, 0.0)[y0 : y0 + HEIGHT, x0 : x0 + WIDTH]
    depth.append(d)
    masks.append((seg == cloth_id)[y0 : y0 + HEIGHT, x0 : x0 + WIDTH])
  folder = os.path.join(root, 'depth')
  os.makedirs(folder)
  for t, frame in enumerate(dataset.depth_to_mm(np.stack(depth))):
    assert cv2.imwrite(os.path.join(folder, f'frame_{t + 1}.png'), frame)
  # The full render's camera: square pixels, centred; the crop shifts it.
  f = 0.5 * _FULL[1] / np.tan(np.deg2rad(_FOVY) / 2)
  cx, cy = 0.5 * (_FULL[0] - 1) - x0, 0.5 * (_FULL[1] - 1) - y0
  cam_to_world = np.eye(4)
  cam_to_world[:3, :3], cam_to_world[:3, 3] = r_user, c_user
  cam = {
    'width': WIDTH, 'height': HEIGHT, 'fx': f, 'fy': f, 'cx': cx, 'cy': cy,
    'cam_to_world': cam_to_world.tolist(), 'fps': fps,
    'notes': 'rendered by MuJoCo (OpenGL) in a y-up user world', 'frame_count': len(depth),
  }  # fmt: skip
  camera_json = os.path.join(root, 'camera.json')
  with open(camera_json, 'w') as fh:
    json.dump(cam, fh)
  mesh_pins = physsim.square(int(round(np.sqrt(positions.shape[1])))).pinned
  pins_world = positions[0][mesh_pins]
  pins_world = pins_world[np.argsort(pins_world[:, 0])]
  pins_cam = (pins_world - np.asarray(pose.position)) @ r_sim
  return SceneRecording(folder, camera_json, pins_cam, np.stack(masks), pose)
