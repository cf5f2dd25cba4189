"""Camera files as depth-camera tools write them, read into one checked form.

Accepted forms (``read_camera``), told apart by their keys:

* **OpenCV JSON**: ``{"width", "height", "fx", "fy", "cx", "cy"}`` (or a 3x3
  ``"K"`` / ``"camera_matrix"``), optionally ``"cam_to_world"`` or
  ``"world_to_cam"`` (4x4, the user's world frame), ``"axes"`` (``"opencv"``,
  the default: x right, y down, z forward; or ``"opengl"``: x right, y up,
  looking along -z), ``"distortion"`` (OpenCV's k1 k2 p1 p2 [k3 ...]) and
  ``"fps"`` (the recording's frame rate). Other keys (notes, frame counts) are
  ignored.
* any form may add ``"gravity"``: 3 numbers, the direction gravity pulls
  (down) in the camera's axes (``"axes"``; OpenCV's by default), e.g. a depth
  camera's IMU at rest (an accelerometer at rest reads its opposite: give
  minus the reading); its size does not matter.
* **ROS CameraInfo YAML**: ``camera_calibration``'s file (``image_width``,
  ``image_height``, ``camera_matrix: {data}``, ``distortion_coefficients``)
  or a CameraInfo message (``width``, ``height``, ``K``/``k``, ``D``/``d``).
* **RealSense intrinsics JSON**: ``width``, ``height``, ``fx``, ``fy``,
  ``ppx``, ``ppy`` and optionally ``coeffs``.
* **Open3D PinholeCameraIntrinsic JSON**: ``width``, ``height`` and
  ``intrinsic_matrix`` (9 numbers, column-major).
* **this project's**: ``{"intrinsics": {...fields of view...}, "extrinsics":
  {"rotation", "position"}}`` as in a dataset's ``meta.json``; its pose is in
  the simulator's world frame.

Pixel centres sit at integer coordinates in all of them (OpenCV's and ROS's
convention). Poses are returned in OpenCV axes as camera-to-world rotation and
camera centre (``physsim.Pose``), checked finite and orthonormal.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, NamedTuple

import cv2
import numpy as np

from physsim import input_files
from physsim.camera import Intrinsics, Pose

FORMS = (
  'OpenCV JSON {"width", "height", "fx", "fy", "cx", "cy" (or "K"), optional '
  '"cam_to_world" or "world_to_cam" 4x4, "axes": "opencv"|"opengl", "distortion", '
  '"fps"}',
  'ROS CameraInfo YAML (image_width, image_height, camera_matrix, '
  'distortion_coefficients; or width, height, K, D)',
  'RealSense intrinsics JSON {"width", "height", "fx", "fy", "ppx", "ppy", "coeffs"}',
  'Open3D intrinsics JSON {"width", "height", "intrinsic_matrix"}',
  'this project\'s {"intrinsics": {"fov_x_deg", "fov_y_deg", ...}, "extrinsics": '
  '{"rotation", "position"}}',
)
# OpenGL camera axes (x right, y up, looking along -z) in OpenCV's.
_GL_TO_CV = np.diag([1.0, -1.0, -1.0])
ORTHONORMAL_TOL = 1e-3
# What --world_up may name.
WORLD_AXES = ('x', 'y', 'z', '+x', '+y', '+z', '-x', '-y', '-z')
# The largest camera file read (a camera's takes a few kB).
MAX_FILE_BYTES = 1 << 20
# The largest image side a camera file may give, pixels.
MAX_SIDE = 8192
# How many distortion coefficients OpenCV's models take (k1 k2 p1 p2 [k3 [k4 k5
# k6 [s1 s2 s3 s4 [tx ty]]]]).
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
# The largest distortion coefficient a lens has (rational models reach tens);
# beyond it the file holds another unit or a typo.
MAX_DISTORTION = 1000.0
# Focal lengths as a share of the image side: 0.1 is a 157 degree view, 100 a
# 0.6 degree one; outside, the file gives another unit or a typo.
FOCAL_RANGE = (0.1, 100.0)
# The principal point may lie this many image sides outside the image.
PRINCIPAL_MARGIN = 1.0
# The least share of the undistorted image that must map inside the frame.
MIN_UNDISTORTED_INSIDE = 0.5


def one_line(e: BaseException) -> str:
  return ' '.join(str(e).split())


class CameraFile(NamedTuple):
  """A camera as a file describes it.

  Attributes:
    intrinsics: the pinhole camera at the file's image size.
    distortion: OpenCV distortion coefficients (k1, k2, p1, p2, ...), () if none.
    pose: the camera's pose (OpenCV axes) or None: in the simulator's world
      when ``world == 'simulator'``, else in the user's.
    world: ``'simulator'`` (this project's form) or ``'user'``.
    fps: the recording's frame rate when the file gives it, else None.
    form: which accepted form the file was read as.
    path: the file.
    gravity: (3,) unit direction of gravity (down) in the camera frame
      (OpenCV axes), or None.
  """

  intrinsics: Intrinsics
  distortion: tuple[float, ...]
  pose: Pose | None
  world: str
  fps: float | None
  form: str
  path: str
  gravity: np.ndarray | None = None

  def world_up(self, axis: str) -> np.ndarray:
    """(3,) the user world's ``axis`` ('x', '-z', ...) in the camera frame
    (OpenCV axes), from the file's camera-to-world pose.

    Raises:
      ValueError: naming --world_up and the file: no pose in the user's world,
        or not an axis.
    """
    if axis not in WORLD_AXES:
      raise ValueError(f'--world_up={axis}: must be one of {", ".join(WORLD_AXES)}')
    if self.pose is None or self.world != 'user':
      raise ValueError(
        f'--world_up={axis}: {self.path} has no "cam_to_world" (or "world_to_cam") '
        "in your world to turn it into the camera's frame; give --up (camera "
        'frame) or "gravity" in the camera file instead'
      )
    e = np.zeros(3)
    e['xyz'.index(axis[-1])] = -1.0 if axis.startswith('-') else 1.0
    return np.asarray(self.pose.rotation, np.float64).T @ e

  @property
  def distorted(self) -> bool:
    return any(abs(c) > 0 for c in self.distortion)


# The accepted forms in one short line, for a file that holds none of them.
FORMS_LINE = (
  'accepted: OpenCV JSON (width, height, fx, fy, cx, cy), ROS CameraInfo YAML, '
  "RealSense/Open3D intrinsics JSON, the project's (intrinsics, extrinsics)"
)


def _error(path: str, why: str, forms: bool = False) -> ValueError:
  """One line naming the file (``forms``: and the accepted forms)."""
  why = input_files.short(ValueError(why), 160)
  return ValueError(f'{path}: {why}' + (f'; {FORMS_LINE}' if forms else ''))


def _load(path: str) -> dict:
  if not os.path.lexists(path):
    raise ValueError(f'{path}: no such camera file')
  text = input_files.read_text(path, 'camera file', MAX_FILE_BYTES)
  if path.lower().endswith(('.yaml', '.yml')):
    data = input_files.load_yaml(text, path)
  else:
    try:
      data = json.loads(text)
    except ValueError as e:
      raise ValueError(f'{path}: not readable JSON ({e})') from None
    except RecursionError:
      raise ValueError(f'{path}: not readable JSON (nested too deeply)') from None
  if not isinstance(data, dict):
    raise _error(path, f'holds a {type(data).__name__}, not a mapping', forms=True)
  return data


def _has_bool(value, depth: int = 0) -> bool:
  """True where a (nested) list holds a JSON true/false among its numbers."""
  if isinstance(value, bool | np.bool_):
    return True
  if isinstance(value, list | tuple) and depth < 4:
    return any(_has_bool(v, depth + 1) for v in value)
  return False


def _numbers(path: str, key: str, value, shape) -> np.ndarray:
  if isinstance(value, dict) and 'data' in value:  # ROS / OpenCV YAML matrices
    value = value['data']
  if _has_bool(value):
    raise _error(path, f'"{key}" holds true/false, not numbers')
  try:
    a = np.asarray(value, np.float64)
  except (TypeError, ValueError, OverflowError, RecursionError):
    raise _error(path, f'"{key}" is not numbers: {input_files.shown(value)}') from None
  if shape is not None:
    if a.size != math.prod(shape):
      raise _error(path, f'"{key}" must hold {math.prod(shape)} numbers, has {a.size}')
    a = a.reshape(shape)
  if not np.all(np.isfinite(a)):
    raise _error(path, f'"{key}" holds non-finite values')
  return a


def check_rotation(r: np.ndarray, where: str) -> None:
  """A ValueError naming ``where`` unless ``r`` is a proper rotation."""
  r = np.asarray(r, np.float64)
  if r.shape != (3, 3) or not np.all(np.isfinite(r)):
    raise ValueError(f'{where}: rotation must be a finite 3x3 matrix')
  err = float(np.abs(r.T @ r - np.eye(3)).max())
  if err > ORTHONORMAL_TOL or np.linalg.det(r) <= 0:
    raise ValueError(
      f'{where}: rotation is not orthonormal with det +1 (|R^T R - I| = {err:.3g}, '
      f'det {np.linalg.det(r):.3g})'
    )


def _pose(path: str, d: dict) -> Pose | None:
  keys = [k for k in ('cam_to_world', 'world_to_cam') if k in d]
  if not keys:
    return None
  if len(keys) == 2:
    raise _error(path, 'give "cam_to_world" or "world_to_cam", not both')
  m = _numbers(path, keys[0], d[keys[0]], (4, 4))
  if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-6):
    raise _error(path, f'"{keys[0]}" last row must be [0, 0, 0, 1], got {m[3]}')
  if keys[0] == 'world_to_cam':
    check_rotation(m[:3, :3], f'{path}: "world_to_cam"')
    m = np.linalg.inv(m)
  axes = str(d.get('axes', 'opencv')).lower()
  if axes not in ('opencv', 'opengl'):
    raise _error(path, f'"axes" must be "opencv" or "opengl", got {axes!r}')
  r = m[:3, :3] @ _GL_TO_CV if axes == 'opengl' else m[:3, :3]
  check_rotation(r, f'{path}: "{keys[0]}"')
  return Pose(r.astype(np.float32), m[:3, 3].astype(np.float32))


def _gravity(path: str, d: dict) -> np.ndarray | None:
  if d.get('gravity') is None:
    return None
  g = _numbers(path, 'gravity', d['gravity'], (3,))
  norm = float(np.linalg.norm(g))
  if not norm > 0:
    raise _error(path, f'"gravity" must be a direction, got {g.tolist()}')
  axes = str(d.get('axes', 'opencv')).lower()
  if axes not in ('opencv', 'opengl'):
    raise _error(path, f'"axes" must be "opencv" or "opengl", got {axes!r}')
  g = g / norm
  return _GL_TO_CV @ g if axes == 'opengl' else g


def _fps(path: str, d: dict) -> float | None:
  if 'fps' not in d or d['fps'] is None:
    return None
  try:
    fps = float(d['fps'])
  except (TypeError, ValueError):
    fps = math.nan
  if not (math.isfinite(fps) and 1.0 <= fps <= 1000.0):
    raise _error(path, f'"fps" must be in [1, 1000] Hz, got {d["fps"]!r}')
  return fps


def _size(path: str, d: dict, w_key: str, h_key: str) -> tuple[int, int]:
  try:
    w, h = int(d[w_key]), int(d[h_key])
  except (KeyError, TypeError, ValueError, OverflowError):
    raise _error(path, f'needs integer "{w_key}" and "{h_key}"') from None
  if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
    raise _error(path, f'image size must be 1 to {MAX_SIDE} px a side, got {w} x {h}')
  return w, h


def _pinhole(path, w, h, k: np.ndarray) -> Intrinsics:
  if abs(k[0, 1]) > 1e-6 * abs(k[0, 0]) or not np.allclose(k[2], [0, 0, 1]):
    raise _error(
      path,
      f'camera matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {k.tolist()}',
    )
  lo, hi = FOCAL_RANGE
  for name, v, side in (('fx', k[0, 0], w), ('fy', k[1, 1], h)):
    if not (math.isfinite(v) and lo * side <= v <= hi * side):
      raise _error(
        path,
        f'"{name}"={v:.6g} must be a positive focal length in pixels, '
        f'{lo * side:g} to {hi * side:g} for a {side} px side',
      )
  m = PRINCIPAL_MARGIN
  for name, v, side in (('cx', k[0, 2], w), ('cy', k[1, 2], h)):
    if not (math.isfinite(v) and -m * side <= v <= (1 + m) * side):
      raise _error(
        path,
        f'"{name}"={v:.6g} px is far outside the {side} px image (expected '
        f'{-m * side:g} to {(1 + m) * side:g} px)',
      )
  try:
    return Intrinsics.from_pinhole(w, h, k[0, 0], k[1, 1], k[0, 2], k[1, 2])
  except ValueError as e:
    raise _error(path, str(e)) from None


def _distortion(path: str, dist) -> tuple[float, ...]:
  """OpenCV's distortion coefficients, checked for a count OpenCV takes and
  a lens's magnitudes."""
  a = _numbers(path, 'distortion', dist or [], None).ravel()
  if a.size not in DISTORTION_LENGTHS:
    raise _error(
      path,
      f'{a.size} distortion coefficients; OpenCV takes '
      f'{", ".join(map(str, DISTORTION_LENGTHS))} (k1 k2 p1 p2 [k3 ...])',
    )
  worst = float(np.abs(a).max()) if a.size else 0.0
  if worst > MAX_DISTORTION:
    raise _error(
      path,
      f'a distortion coefficient of {worst:.3g}; no lens has one above '
      f'{MAX_DISTORTION:g} (another unit or a typo?)',
    )
  return tuple(float(c) for c in a)


def parse_camera(d: dict[str, Any], path: str = 'camera') -> CameraFile:
  """A camera mapping (the content of a camera file) in any accepted form."""
  if 'intrinsics' in d:
    try:
      intr = Intrinsics.from_dict(d['intrinsics'])
    except (ValueError, TypeError, AttributeError, KeyError, OverflowError) as e:
      raise _error(path, f'bad "intrinsics" ({e!r})') from None
    if not (1 <= intr.width <= MAX_SIDE and 1 <= intr.height <= MAX_SIDE):
      raise _error(
        path, f'image size must be 1 to {MAX_SIDE} px a side, got {intr.width} x '
        f'{intr.height}',
      )  # fmt: skip
    pose = None
    ext = d.get('extrinsics')
    if ext is not None:
      if isinstance(ext, list):
        if not ext:
          raise _error(path, 'empty "extrinsics" list')
        ext = ext[0]
      try:
        r = _numbers(path, 'rotation', ext['rotation'], (3, 3))
        p = _numbers(path, 'position', ext['position'], (3,))
      except (KeyError, TypeError):
        raise _error(path, '"extrinsics" needs "rotation" and "position"') from None
      check_rotation(r, f'{path}: "extrinsics"')
      pose = Pose(r.astype(np.float32), p.astype(np.float32))
    return CameraFile(
      intr, (), pose, 'simulator', _fps(path, d), 'project', path, _gravity(path, d)
    )
  if 'image_width' in d or 'camera_matrix' in d and 'width' not in d:
    w, h = _size(path, d, 'image_width', 'image_height')
    k = _numbers(path, 'camera_matrix', d.get('camera_matrix'), (3, 3))
    dist = d.get('distortion_coefficients', ())
    form = 'ROS CameraInfo YAML'
  elif any(key in d for key in ('K', 'k')) and 'fx' not in d:
    w, h = _size(path, d, 'width', 'height')
    k = _numbers(path, 'K', d.get('K', d.get('k')), (3, 3))
    dist = d.get('D', d.get('d', d.get('distortion', ())))
    form = 'ROS CameraInfo' if any(x in d for x in ('D', 'd')) else 'OpenCV JSON'
  elif 'intrinsic_matrix' in d:
    w, h = _size(path, d, 'width', 'height')
    k = _numbers(path, 'intrinsic_matrix', d['intrinsic_matrix'], (3, 3)).T
    dist, form = (), 'Open3D intrinsics JSON'
  elif 'ppx' in d:
    w, h = _size(path, d, 'width', 'height')
    vals = [_numbers(path, key, d.get(key), ()) for key in ('fx', 'fy', 'ppx', 'ppy')]
    k = np.array([[vals[0], 0, vals[2]], [0, vals[1], vals[3]], [0, 0, 1]])
    dist, form = d.get('coeffs', ()), 'RealSense intrinsics JSON'
  elif 'fx' in d or 'camera_matrix' in d:
    w, h = _size(path, d, 'width', 'height')
    if 'camera_matrix' in d:
      k = _numbers(path, 'camera_matrix', d['camera_matrix'], (3, 3))
    else:
      keys = ('fx', 'fy', 'cx', 'cy')
      for key in keys:
        if isinstance(d.get(key), bool):
          raise _error(path, f'"{key}" must be a number, got {d[key]!r}')
      try:
        vals = [float(d[key]) for key in keys]
      except (KeyError, TypeError, ValueError, OverflowError):
        raise _error(path, 'needs numbers "fx", "fy", "cx" and "cy"') from None
      k = np.array([[vals[0], 0, vals[2]], [0, vals[1], vals[3]], [0, 0, 1]])
    dist = d.get('distortion', d.get('dist_coeffs', ()))
    form = 'OpenCV JSON'
  else:
    keys = input_files.shown(list(d), 80)
    raise _error(path, f'no camera found among its keys {keys}', forms=True)
  intr = _pinhole(path, w, h, k)
  distortion = _distortion(path, dist)
  return CameraFile(
    intr, distortion, _pose(path, d), 'user', _fps(path, d), form, path,
    _gravity(path, d),
  )  # fmt: skip


def read_camera(path: str) -> CameraFile:
  """Reads a camera file in any accepted form (module docstring).

  Raises:
    ValueError: naming the file: missing, unreadable, or in no accepted form
      (the message lists them), or a camera that cannot be (non-positive
      focal length, non-orthonormal rotation, non-finite values).
  """
  data = _load(path)
  try:
    return parse_camera(data, path)
  except (TypeError, KeyError, IndexError, AttributeError, OverflowError) as e:
    # A value of an unexpected type deep in an otherwise accepted form.
    raise _error(path, f'cannot be read ({type(e).__name__}: {e})') from None
  except RecursionError:
    raise _error(path, 'a value is nested too deeply') from None


def scaled_to(camera: CameraFile, width: int, height: int) -> CameraFile:
  """The camera for frames of ``width`` x ``height``: the file's own size, or
  the same image resampled (aspect ratio within 1%)."""
  intr = camera.intrinsics
  if (intr.width, intr.height) == (width, height):
    return camera
  if abs(intr.width / intr.height - width / height) > 0.01 * width / height:
    raise ValueError(
      f'{camera.path}: the camera is {intr.width} x {intr.height} but the frames are '
      f'{width} x {height} (another aspect ratio)'
    )
  return camera._replace(intrinsics=intr.resized(width, height))


def undistort(depth: np.ndarray, cam: CameraFile) -> np.ndarray:
  """(T, H, W) depth frames remapped to the file's camera without its lens
  distortion (nearest pixel: every value a real measurement).

  Raises:
    ValueError: naming the camera file: a distortion that maps most of the
      image outside the frame (no lens does).
  """
  intr = cam.intrinsics
  k = intr.matrix()
  maps = cv2.initUndistortRectifyMap(
    k, np.asarray(cam.distortion), None, k, (intr.width, intr.height), cv2.CV_32FC1
  )
  inside = float(
    np.mean(
      (maps[0] >= -0.5) & (maps[0] <= intr.width - 0.5)
      & (maps[1] >= -0.5) & (maps[1] <= intr.height - 0.5)
    )
  )  # fmt: skip
  if not inside >= MIN_UNDISTORTED_INSIDE:
    raise ValueError(
      f'{cam.path}: its {len(cam.distortion)} distortion coefficients map only '
      f'{inside:.0%} of the image inside the frame; check them (k1 k2 p1 p2 [k3 ...])'
    )
  return np.stack([cv2.remap(f, *maps, cv2.INTER_NEAREST) for f in depth])
