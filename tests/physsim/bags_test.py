"""Recordings as cameras write them (issue 40, item 3): ROS 2 and ROS 1 bags
written here with ``rosbags``' own writers, holding a depth topic (16-bit
mm), its CameraInfo, an accelerometer in its own frame (related to the
camera's by ``/tf_static``) and distractor topics; read by ``physsim.bags``
and taken in as any other recording."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip('rosbags')

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from experiments.pipeline import intake, objective  # noqa: E402
from physsim import bags  # noqa: E402
from tests.physsim.alignment_test import (  # noqa: E402
  _INTR,
  _pose,
  _scene_depth,
)

_CONFIG = objective.PRESETS['smoke'].replace(cloth_resolution=10)
_CAM_FRAME = 'camera_depth_optical_frame'
# The IMU's axes: turned 90 degrees about the camera's x and 20 about its z.
_A, _B = np.deg2rad(90.0), np.deg2rad(20.0)
_IMU_TO_CAM = np.array(
  [[np.cos(_B), -np.sin(_B), 0], [np.sin(_B), np.cos(_B), 0], [0, 0, 1]]
) @ np.array([[1, 0, 0], [0, np.cos(_A), -np.sin(_A)], [0, np.sin(_A), np.cos(_A)]])


def _quat(r):
  """(x, y, z, w) of a rotation matrix."""
  w = np.sqrt(max(1e-12, 1 + np.trace(r))) / 2
  return (
    (r[2, 1] - r[1, 2]) / (4 * w),
    (r[0, 2] - r[2, 0]) / (4 * w),
    (r[1, 0] - r[0, 1]) / (4 * w),
    w,
  )


class _Msgs:
  """Messages of one typestore (ROS 1 or ROS 2 field names)."""

  def __init__(self, store):
    self.ts = get_typestore(store)
    self.ros1 = store == Stores.ROS1_NOETIC

  def t(self, name):
    return self.ts.types[name]

  def header(self, t, frame):
    stamp = self.t('builtin_interfaces/msg/Time')(
      sec=int(t), nanosec=int(1e9 * (t % 1))
    )
    kw = dict(stamp=stamp, frame_id=frame)
    if self.ros1:
      kw['seq'] = 0
    return self.t('std_msgs/msg/Header')(**kw)

  def image(self, t, depth_mm, frame=_CAM_FRAME):
    h, w = depth_mm.shape
    return self.t('sensor_msgs/msg/Image')(
      header=self.header(t, frame), height=h, width=w, encoding='16UC1',
      is_bigendian=0, step=2 * w,
      data=np.frombuffer(depth_mm.astype('<u2').tobytes(), np.uint8),
    )  # fmt: skip

  def info(self, t):
    k = _INTR.matrix().ravel()
    roi = self.t('sensor_msgs/msg/RegionOfInterest')(
      x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    names = ('D', 'K', 'R', 'P') if self.ros1 else ('d', 'k', 'r', 'p')
    values = (np.zeros(5), k, np.eye(3).ravel(), np.zeros(12))
    return self.t('sensor_msgs/msg/CameraInfo')(
      header=self.header(t, _CAM_FRAME), height=_INTR.height, width=_INTR.width,
      distortion_model='plumb_bob', binning_x=0, binning_y=0, roi=roi,
      **dict(zip(names, values, strict=True)),
    )  # fmt: skip

  def imu(self, t, accel, frame):
    v3 = self.t('geometry_msgs/msg/Vector3')
    return self.t('sensor_msgs/msg/Imu')(
      header=self.header(t, frame),
      orientation=self.t('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0),
      orientation_covariance=np.zeros(9), angular_velocity=v3(x=0.0, y=0.0, z=0.0),
      angular_velocity_covariance=np.zeros(9),
      linear_acceleration=v3(x=accel[0], y=accel[1], z=accel[2]),
      linear_acceleration_covariance=np.zeros(9),
    )  # fmt: skip

  def tf_static(self, parent, child, r):
    x, y, z, w = _quat(r)
    tr = self.t('geometry_msgs/msg/TransformStamped')(
      header=self.header(0.0, parent), child_frame_id=child,
      transform=self.t('geometry_msgs/msg/Transform')(
        translation=self.t('geometry_msgs/msg/Vector3')(x=0.0, y=0.0, z=0.0),
        rotation=self.t('geometry_msgs/msg/Quaternion')(x=x, y=y, z=z, w=w),
      ),
    )  # fmt: skip
    return self.t('tf2_msgs/msg/TFMessage')(transforms=[tr])

  def serialize(self, msg):
    if self.ros1:
      return self.ts.serialize_ros1(msg, msg.__msgtype__)
    return self.ts.serialize_cdr(msg, msg.__msgtype__)


def write_bag(path, store, *, frames=24, fps=20.0, depth_topics=('/camera/depth/image_rect_raw',),
              imu=True, tf=True, extra_images=('/camera/color/image_raw',)):  # fmt: skip
  """A bag of the windy scene (floor out of view, cloth swung 35 degrees)."""
  m = _Msgs(store)
  pose = _pose()
  depth = _scene_depth(pose, _INTR, floor=False, wall=True, swing_deg=35.0)
  mm = np.round(1000 * depth).astype(np.uint16)
  up_cam = np.asarray(pose.rotation, np.float64).T @ [0, 0, 1.0]
  accel_imu = _IMU_TO_CAM.T @ (9.81 * up_cam)  # at rest an accelerometer reads up
  if store == Stores.ROS1_NOETIC:
    from rosbags.rosbag1 import Writer  # noqa: PLC0415

    writer = Writer(path)
  else:
    from rosbags.rosbag2 import Writer  # noqa: PLC0415

    writer = Writer(path, version=9)
  with writer:
    add = lambda topic, msgtype: writer.add_connection(topic, msgtype, typestore=m.ts)
    conns = {t: add(t, 'sensor_msgs/msg/Image') for t in depth_topics + extra_images}
    info = add('/camera/depth/camera_info', 'sensor_msgs/msg/CameraInfo')
    imu_c = add('/camera/accel/sample', 'sensor_msgs/msg/Imu') if imu else None
    if tf:
      tf_c = add('/tf_static', 'tf2_msgs/msg/TFMessage')
      writer.write(
        tf_c, 1, m.serialize(m.tf_static(_CAM_FRAME, 'imu_link', _IMU_TO_CAM))
      )
    for k in range(frames):
      t = 100.0 + k / fps
      ns = int(t * 1e9)
      for topic, c in conns.items():
        frame = mm if 'depth' in topic else np.zeros_like(mm)
        writer.write(c, ns, m.serialize(m.image(t, frame)))
      if k == 0:
        writer.write(info, ns, m.serialize(m.info(t)))
      if imu_c is not None:
        for j in range(4):
          writer.write(
            imu_c, ns + j, m.serialize(m.imu(t + j * 1e-3, accel_imu, 'imu_link'))
          )
  return str(path), pose, depth


def _rotation_error_deg(a, b) -> float:
  r = np.asarray(a.rotation, np.float64).T @ np.asarray(b.rotation, np.float64)
  return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))


def test_a_ros2_bag_gives_frames_camera_and_gravity(tmp_path):
  path, pose, depth = write_bag(tmp_path / 'rec', Stores.ROS2_HUMBLE)
  assert bags.is_bag(path)
  rec = bags.read_bag(path)
  assert rec.topics == {
    'depth': '/camera/depth/image_rect_raw', 'info': '/camera/depth/camera_info',
    'imu': '/camera/accel/sample',
  }  # fmt: skip
  assert rec.depth.shape == (24, 120, 160) and rec.fps == pytest.approx(20.0)
  np.testing.assert_allclose(rec.depth[0], np.round(1000 * depth) / 1000, atol=1e-6)
  assert rec.camera.intrinsics.fx == pytest.approx(_INTR.fx)
  down = np.asarray(pose.rotation, np.float64).T @ [0, 0, -1.0]
  np.testing.assert_allclose(rec.gravity, down, atol=1e-6)
  # The intake takes up from the IMU, not the swung cloth's plane.
  ik = intake.take_in(
    path, intake.IntakeConfig(min_overlap=0.3), '', _CONFIG.simulation
  )
  assert ik.up_from == 'gravity' and ik.camera_form.startswith('ROS CameraInfo')
  assert _rotation_error_deg(ik.pose, pose) < 2.0


def test_a_ros1_bag_reads_the_same(tmp_path):
  path, _, depth = write_bag(tmp_path / 'rec.bag', Stores.ROS1_NOETIC, tf=False)
  rec = bags.read_bag(path)
  np.testing.assert_allclose(rec.depth[3], np.round(1000 * depth) / 1000, atol=1e-6)
  assert rec.camera.intrinsics.width == 160 and rec.fps == pytest.approx(20.0)
  # No /tf_static relates the IMU's frame to the camera's: left out, said so.
  assert rec.gravity is None and 'imu_link' in rec.notes[0]
  with pytest.raises(ValueError, match=r'rec.bag: .*accel/sample.*--world_up'):
    bags.read_bag(path, imu_topic='/camera/accel/sample')


def test_ambiguous_topics_are_listed_and_bad_bags_named(tmp_path):
  path, _, _ = write_bag(
    tmp_path / 'two', Stores.ROS2_HUMBLE, frames=3, imu=False,
    depth_topics=('/left/depth/image', '/right/depth/image'),
  )  # fmt: skip
  with pytest.raises(
    ValueError, match=r'two: 3 image topics .*/left/depth/image, /right/depth/image.*'
    r'--depth_topic',
  ):  # fmt: skip
    bags.read_bag(path)
  assert bags.read_bag(path, depth_topic='/right/depth/image').depth.shape[0] == 3
  with pytest.raises(ValueError, match="no image topic '/nope'"):
    bags.read_bag(path, depth_topic='/nope')
  junk = tmp_path / 'junk.bag'
  junk.write_bytes(b'#ROSBAG V2.0\n' + bytes(range(256)))
  with pytest.raises(ValueError, match='junk.bag: not a readable ROS bag'):
    bags.read_bag(str(junk))
  with pytest.raises(ValueError, match='junk.bag: not a readable ROS bag'):
    intake.take_in(str(junk), intake.IntakeConfig(), '', _CONFIG.simulation)


def test_a_ros2_bag_folder_without_metadata_is_named_as_such(tmp_path):
  path, _, _ = write_bag(tmp_path / 'rec', Stores.ROS2_HUMBLE, frames=2, imu=False)
  (tmp_path / 'rec' / 'metadata.yaml').unlink()
  assert not bags.is_bag(path)
  with pytest.raises(
    ValueError, match=r'rec: a ROS 2 bag folder .*without its metadata'
  ):
    intake.take_in(path, intake.IntakeConfig(), '', _CONFIG.simulation)


def test_a_bag_whose_files_are_fifos_is_refused_by_name(tmp_path):
  import os  # noqa: PLC0415
  import threading  # noqa: PLC0415

  path, _, _ = write_bag(tmp_path / 'rec', Stores.ROS2_HUMBLE, frames=2, imu=False)
  (db3,) = [f for f in os.listdir(path) if f.endswith(('.db3', '.mcap'))]
  os.remove(os.path.join(path, db3))
  os.mkfifo(os.path.join(path, db3))
  fifo_bag = str(tmp_path / 'x.bag')
  os.mkfifo(fifo_bag)
  for bag, name in ((path, db3), (fifo_bag, 'x.bag')):
    out = {}

    def target(bag=bag, out=out):
      try:
        bags.read_bag(bag)
      except ValueError as e:
        out['error'] = str(e)

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(10.0)
    assert not t.is_alive(), f'{bag}: blocked'
    assert name in out['error'] and 'FIFO' in out['error']


def test_a_yaml_alias_in_metadata_is_refused_before_rosbags_expands_it(tmp_path):
  import time  # noqa: PLC0415

  path, _, _ = write_bag(tmp_path / 'rec', Stores.ROS2_HUMBLE, frames=2, imu=False)
  meta = tmp_path / 'rec' / 'metadata.yaml'
  bomb = ['a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]']
  bomb += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 10) + ']' for i in range(1, 9)]
  meta.write_text('\n'.join(bomb) + '\n' + meta.read_text())
  t0 = time.perf_counter()
  with pytest.raises(ValueError, match=r'metadata.yaml: YAML aliases') as e:
    bags.read_bag(path)
  assert time.perf_counter() - t0 < 1.0 and len(str(e.value)) <= 300
