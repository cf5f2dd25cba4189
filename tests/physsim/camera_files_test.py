"""Tests for physsim.camera_files: the camera files depth-camera tools write."""

import json
import os
import time

import numpy as np
import pytest

from physsim import camera, camera_files
from tests import blocking

_TOL = 1e-6
W, H, FX, FY, CX, CY = 320, 240, 300.0, 310.0, 170.3, 110.2
# A camera 2 m from the origin looking along +y in a z-up world (OpenCV axes).
_R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_C = np.array([0.3, -2.0, 1.1])


def _c2w():
  m = np.eye(4)
  m[:3, :3], m[:3, 3] = _R, _C
  return m


def _write(tmp_path, name, content):
  path = tmp_path / name
  path.write_text(content if isinstance(content, str) else json.dumps(content))
  return str(path)


def _check_k(intr):
  assert (intr.width, intr.height) == (W, H)
  np.testing.assert_allclose(
    intr.matrix(), [[FX, 0, CX], [0, FY, CY], [0, 0, 1]], rtol=_TOL, atol=_TOL
  )


def test_opencv_json_as_users_write_it(tmp_path):
  d = {
    'width': W, 'height': H, 'fx': FX, 'fy': FY, 'cx': CX, 'cy': CY,
    'cam_to_world': _c2w().tolist(), 'fps': 24, 'notes': 'lab A', 'frame_count': 90,
  }  # fmt: skip
  cam = camera_files.read_camera(_write(tmp_path, 'cam.json', d))
  _check_k(cam.intrinsics)
  assert cam.fps == 24 and cam.world == 'user' and cam.form == 'OpenCV JSON'
  np.testing.assert_allclose(cam.pose.rotation, _R, atol=_TOL)
  np.testing.assert_allclose(cam.pose.position, _C, atol=_TOL)
  # world_to_cam is the inverse; OpenGL axes flip y and z of the camera.
  inv = dict(d, world_to_cam=np.linalg.inv(_c2w()).tolist())
  del inv['cam_to_world']
  cam2 = camera_files.read_camera(_write(tmp_path, 'inv.json', inv))
  np.testing.assert_allclose(cam2.pose.rotation, _R, atol=1e-5)
  np.testing.assert_allclose(cam2.pose.position, _C, atol=1e-5)
  gl = _c2w()
  gl[:3, :3] = _R @ np.diag([1.0, -1.0, -1.0])
  cam3 = camera_files.read_camera(
    _write(tmp_path, 'gl.json', dict(d, cam_to_world=gl.tolist(), axes='opengl'))
  )
  np.testing.assert_allclose(cam3.pose.rotation, _R, atol=_TOL)


def test_tool_formats_give_the_same_camera(tmp_path):
  k = [[FX, 0, CX], [0, FY, CY], [0, 0, 1]]
  ros = f"""image_width: {W}
image_height: {H}
camera_name: depth
camera_matrix:
  rows: 3
  cols: 3
  data: [{FX}, 0, {CX}, 0, {FY}, {CY}, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.05, 0, 0, 0]
"""
  msg = f'width: {W}\nheight: {H}\nK: {np.ravel(k).tolist()}\nD: [0, 0, 0, 0, 0]\n'
  realsense = {'width': W, 'height': H, 'fx': FX, 'fy': FY, 'ppx': CX, 'ppy': CY,
               'model': 'Brown Conrady', 'coeffs': [0, 0, 0, 0, 0]}  # fmt: skip
  open3d = {
    'width': W,
    'height': H,
    'intrinsic_matrix': np.asarray(k).T.ravel().tolist(),
  }
  forms = {
    'ost.yaml': (ros, 'ROS CameraInfo YAML', True),
    'info.yaml': (msg, 'ROS CameraInfo', False),
    'rs.json': (realsense, 'RealSense intrinsics JSON', False),
    'o3d.json': (open3d, 'Open3D intrinsics JSON', False),
    'k.json': ({'width': W, 'height': H, 'K': k}, 'OpenCV JSON', False),
  }
  for name, (content, form, distorted) in forms.items():
    cam = camera_files.read_camera(_write(tmp_path, name, content))
    _check_k(cam.intrinsics)
    assert cam.form == form and cam.distorted == distorted and cam.pose is None, name


def test_project_form_keeps_its_simulator_pose(tmp_path):
  intr = camera.Intrinsics(64, 48, 50.0, 40.0)
  pose = camera.look_at([0.5, -2.0, 1.2], [0.0, 0.1, 1.0])
  d = {'intrinsics': intr.to_dict(), 'extrinsics': [camera.pose_to_dict(pose)]}
  cam = camera_files.read_camera(_write(tmp_path, 'meta.json', d))
  assert cam.intrinsics == intr and cam.world == 'simulator'
  np.testing.assert_allclose(cam.pose.rotation, pose.rotation, atol=_TOL)


def test_bad_camera_files_name_the_file_and_the_accepted_forms(tmp_path):
  base = {'width': W, 'height': H, 'fx': FX, 'fy': FY, 'cx': CX, 'cy': CY}
  zero = np.zeros((4, 4))
  zero[3, 3] = 1
  skew = _c2w()
  skew[:3, :3] *= 1.5
  cases = {
    'fov_only.json': ({'width': W, 'height': H, 'fov': 60}, 'no camera found'),
    'nofov.json': ({'intrinsics': {'width': W}}, r'missing \[.fov_x_deg'),
    'zero_rot.json': (dict(base, cam_to_world=zero.tolist()), 'not orthonormal'),
    'skew.json': (dict(base, cam_to_world=skew.tolist()), 'not orthonormal'),
    'nan.json': (dict(base, fx=float('nan')), 'fx'),
    'neg_f.json': (dict(base, fx=-3.0), 'positive focal length'),
    'shape.json': (dict(base, cam_to_world=[[1, 0, 0], [0, 1, 0]]), 'must hold 16'),
    'fps.json': (dict(base, fps=1e-9), 'fps'),
    'list.json': ([1, 2, 3], 'not a mapping'),
  }
  for name, (content, msg) in cases.items():
    path = _write(tmp_path, name, json.dumps(content).replace('NaN', 'NaN'))
    with pytest.raises(ValueError, match=msg) as e:
      camera_files.read_camera(path)
    assert name in str(e.value)
    line = str(e.value)
    assert '\n' not in line and len(line) <= 300, line
    if msg in ('no camera found', 'not a mapping'):
      assert 'accepted: OpenCV JSON' in line
  (tmp_path / 'broken.json').write_text('{"width": 3,')
  with pytest.raises(ValueError, match='broken.json: not readable JSON'):
    camera_files.read_camera(str(tmp_path / 'broken.json'))
  with pytest.raises(ValueError, match='no such camera file'):
    camera_files.read_camera(str(tmp_path / 'missing.json'))


def test_scaled_to_keeps_the_camera_and_refuses_other_aspect_ratios():
  cam = camera_files.parse_camera(
    {'width': W, 'height': H, 'fx': FX, 'fy': FY, 'cx': CX, 'cy': CY}
  )
  half = camera_files.scaled_to(cam, W // 2, H // 2).intrinsics
  # Pixel centres at integers: halving maps c to (c + 0.5) / 2 - 0.5.
  np.testing.assert_allclose([half.fx, half.fy], [FX / 2, FY / 2], rtol=_TOL)
  np.testing.assert_allclose(
    [half.cx, half.cy], [(CX + 0.5) / 2 - 0.5, (CY + 0.5) / 2 - 0.5], rtol=_TOL
  )
  with pytest.raises(ValueError, match='another aspect ratio'):
    camera_files.scaled_to(cam, 256, 256)


_BASE = {'width': W, 'height': H, 'fx': FX, 'fy': FY, 'cx': CX, 'cy': CY}


@pytest.mark.parametrize('count', [1, 2, 3, 6, 7, 9, 13, 15])
def test_distortion_counts_opencv_does_not_take_are_refused(tmp_path, count):
  path = _write(tmp_path, 'cam.json', dict(_BASE, distortion=[0.01] * count))
  with pytest.raises(ValueError, match=rf'{count} distortion coefficients') as e:
    camera_files.read_camera(path)
  assert str(e.value).startswith(path)


@pytest.mark.parametrize('count', [0, 4, 5, 8, 12, 14])
def test_distortion_counts_opencv_takes_are_read_and_undone(tmp_path, count):
  path = _write(tmp_path, 'cam.json', dict(_BASE, distortion=[1e-3] * count))
  cam = camera_files.read_camera(path)
  assert len(cam.distortion) == count
  out = camera_files.undistort(np.ones((1, H, W), np.float32), cam)
  assert out.shape == (1, H, W)


def test_absurd_distortion_is_blamed_on_the_camera_file(tmp_path):
  path = _write(tmp_path, 'cam.json', dict(_BASE, distortion=[1e6, 0, 0, 0, 0]))
  with pytest.raises(ValueError, match='distortion coefficient of 1e'):
    camera_files.read_camera(path)
  # Within the bound but still no lens: its undistortion leaves the frame.
  path = _write(tmp_path, 'cam2.json', dict(_BASE, distortion=[900, 0, 0, 0, 0]))
  cam = camera_files.read_camera(path)
  with pytest.raises(ValueError, match='inside the frame') as e:
    camera_files.undistort(np.ones((1, H, W), np.float32), cam)
  assert str(e.value).startswith(path)


@pytest.mark.parametrize(
  ('field', 'value'),
  [('fx', 1e300), ('fx', True), ('fy', 1e-3), ('fy', False), ('cx', 1e300),
   ('cy', -1e9), ('fx', 'NaN')],
)  # fmt: skip
def test_intrinsics_must_be_plausible_numbers_named_by_field(tmp_path, field, value):
  path = _write(tmp_path, 'cam.json', dict(_BASE, **{field: value}))
  with pytest.raises(ValueError, match=rf'"{field}"|{field} must') as e:
    camera_files.read_camera(path)
  assert str(e.value).startswith(path)
  # The same in a camera matrix, true/false included.
  k = [[FX, 0, CX], [0, FY, CY], [0, 0, 1]]
  k[0][0] = True
  path = _write(tmp_path, 'k.json', {'width': W, 'height': H, 'K': k})
  with pytest.raises(ValueError, match='true/false'):
    camera_files.read_camera(path)


def test_yaml_alias_bomb_is_refused_at_once_naming_the_file(tmp_path):
  lines = ['a: &a [0, 0, 0, 0, 0, 0, 0, 0, 0, 0]']
  for i in range(1, 12):
    prev = chr(ord('a') + i - 1)
    cur = chr(ord('a') + i)
    lines.append(f'{cur}: &{cur} [' + ', '.join([f'*{prev}'] * 10) + ']')
  lines += ['image_width: 320', 'image_height: 240', 'camera_matrix: *l']
  text = '\n'.join(lines) + '\n'
  assert len(text) < 700
  path = _write(tmp_path, 'bomb.yaml', text)
  t0 = time.perf_counter()
  with pytest.raises(ValueError, match='aliases') as e:
    camera_files.read_camera(path)
  assert time.perf_counter() - t0 < 1.0
  msg = str(e.value)
  assert msg.startswith(path) and '\n' not in msg and len(msg) <= 300


def test_a_fifo_named_as_camera_file_is_refused_without_opening(tmp_path):
  fifo = str(tmp_path / 'camera.json')
  os.mkfifo(fifo)
  t0 = time.perf_counter()
  with pytest.raises(ValueError, match='FIFO') as e:
    blocking.in_thread(lambda: camera_files.read_camera(fifo))
  assert str(e.value).startswith(fifo) and time.perf_counter() - t0 < 5
