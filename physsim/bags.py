"""Depth recordings as cameras write them: ROS 1 and ROS 2 bags, and
RealSense ``.bag`` files (ROS 1 bags), read with ``rosbags`` (pure Python).

``read_bag`` takes from a bag:

* the **depth** images (``sensor_msgs/Image``, ``16UC1``/``mono16`` in
  millimetres, or a RealSense file's own depth units, or ``32FC1`` in
  metres): ``depth_topic``, else the one image topic whose name holds
  "depth", else the only image topic; several candidates are refused with
  their list;
* its **camera** (``sensor_msgs/CameraInfo``): ``info_topic``, else the
  CameraInfo beside the depth topic (same namespace), else the only one;
* **gravity** from an accelerometer (``sensor_msgs/Imu``): ``imu_topic``,
  else the only IMU topic (or the one whose name holds "accel"); the mean
  reading over the first second (at rest, an accelerometer reads up), turned
  into the depth camera's frame by ``/tf_static`` when the two frames differ.
  An IMU whose frame cannot be related to the camera's is left out, with a
  note (or refused where ``imu_topic`` was named).

Frame rate from the depth messages' timestamps. Sizes are checked from the
first message's header fields (width, height) and the topic's message count
before the frames are gathered.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from physsim import camera_files, input_files, video_files

IMAGE = ('sensor_msgs/msg/Image', 'sensor_msgs/Image')
INFO = ('sensor_msgs/msg/CameraInfo', 'sensor_msgs/CameraInfo')
IMU = ('sensor_msgs/msg/Imu', 'sensor_msgs/Imu')
TF = ('tf2_msgs/msg/TFMessage', 'tf2_msgs/TFMessage')
# The files a ROS 2 bag folder stores its messages in.
STORAGE_EXTENSIONS = ('.db3', '.mcap')
# The largest metadata.yaml read (ros2 writes a few kB).
MAX_METADATA = 1 << 20
# Seconds of IMU readings averaged for gravity (the camera at rest).
IMU_SECONDS = 1.0
_ENCODINGS = {'16UC1': np.uint16, 'mono16': np.uint16, '32FC1': np.float32}


class BagRecording(NamedTuple):
  """What a bag holds for the intake.

  Attributes:
    depth: (T, H, W) float32 metres, 0 invalid.
    fps: frame rate from the timestamps.
    camera: its ``camera_files.CameraFile`` (CameraInfo), or None.
    gravity: (3,) unit direction of gravity (down) in the depth camera's
      frame (OpenCV axes), or None.
    topics: {'depth': ..., 'info': ..., 'imu': ...} the topics used ('' none).
    notes: what the user should know (an IMU left out).
  """

  depth: np.ndarray
  fps: float | None
  camera: camera_files.CameraFile | None
  gravity: np.ndarray | None
  topics: dict
  notes: tuple[str, ...] = ()


def is_bag(path: str) -> bool:
  """A ROS 1 / RealSense ``.bag`` file, or a ROS 2 bag folder
  (``metadata.yaml``)."""
  if os.path.isfile(path):
    return path.lower().endswith('.bag')
  return os.path.isfile(os.path.join(path, 'metadata.yaml'))


def check_bag_folder(path: str) -> None:
  """Refuses a folder that holds a ROS 2 bag's storage (``.db3``, ``.mcap``)
  without its ``metadata.yaml``: read as a frame folder it would be
  refused for the wrong reason.

  Raises:
    ValueError: naming the folder and the storage file.
  """
  if not os.path.isdir(path) or os.path.lexists(os.path.join(path, 'metadata.yaml')):
    return
  stored = sorted(f for f in os.listdir(path) if f.lower().endswith(STORAGE_EXTENSIONS))
  if stored:
    raise ValueError(
      f'{path}: a ROS 2 bag folder ({stored[0]}) without its metadata.yaml; copy '
      'the whole folder `ros2 bag record` wrote, or run `ros2 bag reindex` on it'
    )


def _check_files(path: str) -> None:
  """Refuses a bag whose files are not regular files (a FIFO would block
  the reader forever), or whose metadata.yaml is too large or holds a YAML
  alias, naming the file."""
  if not os.path.isdir(path):
    input_files.check_regular(path, 'bag')
    return
  for name in sorted(os.listdir(path)):
    if name.lower().endswith((*STORAGE_EXTENSIONS, '.yaml')):
      input_files.check_regular(os.path.join(path, name), 'bag file')
  # rosbags expands YAML aliases: a few hundred bytes of them would take
  # minutes and gigabytes. No metadata.yaml ros2 writes holds one.
  meta = os.path.join(path, 'metadata.yaml')
  input_files.load_yaml(input_files.read_text(meta, 'bag file', MAX_METADATA), meta)


def _pick(path, conns, kind: str, given: str, prefer, flag: str):
  """The connection of ``kind`` to read: ``given``, else by ``prefer``."""
  topics = sorted({c.topic for c in conns})
  if given:
    chosen = [c for c in conns if c.topic == given]
    if not chosen:
      raise ValueError(
        f'{path}: no {kind} topic {given!r} (--{flag}); its {kind} topics: '
        f'{", ".join(topics) or "none"}'
      )
    return chosen[0]
  if len(topics) == 1:
    return conns[0]
  if not topics:
    return None
  preferred = sorted({c.topic for c in conns if prefer(c.topic)})
  if len(preferred) == 1:
    return next(c for c in conns if c.topic == preferred[0])
  raise ValueError(
    f'{path}: {len(topics)} {kind} topics ({", ".join(topics)}); name one with --{flag}'
  )


def _namespace(topic: str) -> str:
  return topic.rsplit('/', 1)[0]


def _quat_matrix(q) -> np.ndarray:
  x, y, z, w = (float(q.x), float(q.y), float(q.z), float(q.w))
  n = np.sqrt(x * x + y * y + z * z + w * w)
  if not n > 0:
    raise ValueError('zero quaternion')
  x, y, z, w = x / n, y / n, z / n, w / n
  return np.array(
    [
      [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
  )


def _rotation_between(edges: dict, source: str, target: str) -> np.ndarray | None:
  """R with v_target = R v_source, through the static transforms ``edges``
  ({(parent, child): R child-to-parent}), or None when unrelated."""
  graph: dict = {}
  for (parent, child), r in edges.items():
    graph.setdefault(child, []).append((parent, r))  # v_parent = r v_child
    graph.setdefault(parent, []).append((child, r.T))
  seen, todo = {source: np.eye(3)}, [source]
  while todo:
    frame = todo.pop()
    for nxt, r in graph.get(frame, []):
      if nxt not in seen:
        seen[nxt] = r @ seen[frame]
        todo.append(nxt)
  return seen.get(target)


def _frame_id(msg) -> str:
  header = getattr(msg, 'header', None)
  return str(getattr(header, 'frame_id', '') or '').lstrip('/')


def _stamp(msg, fallback_ns: int) -> float:
  header = getattr(msg, 'header', None)
  stamp = getattr(header, 'stamp', None)
  if stamp is None:
    return fallback_ns * 1e-9
  sec = getattr(stamp, 'sec', getattr(stamp, 'secs', 0))
  nsec = getattr(stamp, 'nanosec', getattr(stamp, 'nsecs', 0))
  t = float(sec) + 1e-9 * float(nsec)
  return t if t > 0 else fallback_ns * 1e-9


def _image(path: str, topic: str, msg, scale: float) -> np.ndarray:
  enc = str(msg.encoding)
  if enc not in _ENCODINGS:
    raise ValueError(
      f'{path}: {topic} holds {enc!r} images; depth must be 16UC1/mono16 (mm) or '
      '32FC1 (metres)'
    )
  dtype = np.dtype(_ENCODINGS[enc]).newbyteorder('>' if msg.is_bigendian else '<')
  h, w, step = int(msg.height), int(msg.width), int(msg.step)
  data = np.asarray(msg.data, np.uint8)
  if step < w * dtype.itemsize or data.size < h * step:
    raise ValueError(
      f'{path}: {topic}: an image of {w} x {h} px with step {step} holds only '
      f'{data.size} bytes'
    )
  rows = data[: h * step].reshape(h, step)[:, : w * dtype.itemsize]
  img = rows.copy().view(dtype).reshape(h, w).astype(np.float32)
  if dtype.kind == 'f':
    return np.where(np.isfinite(img) & (img > 0), img, 0.0).astype(np.float32)
  return img * np.float32(scale)


def _camera(path: str, topic: str, msg) -> camera_files.CameraFile:
  k = getattr(msg, 'k', getattr(msg, 'K', None))
  d = getattr(msg, 'd', getattr(msg, 'D', ()))
  cam = {
    'width': int(msg.width), 'height': int(msg.height),
    'K': np.asarray(k, np.float64).tolist(), 'D': np.asarray(d, np.float64).tolist(),
  }  # fmt: skip
  return camera_files.parse_camera(cam, f'{path}:{topic}')


def read_bag(
  path: str,
  *,
  depth_topic: str = '',
  info_topic: str = '',
  imu_topic: str = '',
  start: int = 0,
) -> BagRecording:
  """Reads a bag's depth frames, camera and gravity (module docstring).

  Raises:
    ValueError: naming the bag (and topic or flag): unreadable, no or several
      candidate topics, an unsupported encoding, frames too large.
  """
  try:
    from rosbags.highlevel import AnyReader  # noqa: PLC0415 - only bags need it
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415
  except ImportError:
    raise ValueError(f'{path}: reading bags needs `pip install rosbags`') from None
  _check_files(path)
  try:
    reader = AnyReader(
      [Path(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE)
    )
    reader.open()
  except Exception as e:  # noqa: BLE001 - rosbags raises its own many kinds
    raise ValueError(
      f'{path}: not a readable ROS bag ({type(e).__name__}: '
      f'{input_files.short(e, 160)})'
    ) from None
  try:
    return _read(reader, path, depth_topic, info_topic, imu_topic, start)
  except (ValueError, OSError):
    raise
  except Exception as e:  # noqa: BLE001 - a corrupt message deep in the bag
    raise ValueError(
      f'{path}: a message cannot be read ({type(e).__name__}: '
      f'{input_files.short(e, 160)})'
    ) from None
  finally:
    reader.close()


def _read(reader, path, depth_topic, info_topic, imu_topic, start) -> BagRecording:
  conns = list(reader.connections)
  of = lambda types: [c for c in conns if c.msgtype in types]
  depth_c = _pick(
    path, of(IMAGE), 'image', depth_topic, lambda t: 'depth' in t.lower(), 'depth_topic'
  )
  if depth_c is None:
    raise ValueError(
      f'{path}: no image topic; its topics: {", ".join(sorted({c.topic for c in conns}))}'
    )
  ns = _namespace(depth_c.topic)
  info_c = _pick(
    path, of(INFO), 'CameraInfo', info_topic,
    lambda t: _namespace(t) == ns or _namespace(_namespace(t)) == _namespace(ns),
    'info_topic',
  )  # fmt: skip
  imu_c = _pick(
    path, of(IMU), 'IMU', imu_topic, lambda t: 'accel' in t.lower(), 'imu_topic'
  )
  # RealSense files keep their depth unit as an option topic.
  scale = 0.001
  units = [c for c in conns if c.topic.lower().endswith('depth units/value')]
  if units:
    for c, _, raw in reader.messages(connections=units[:1]):
      scale = float(reader.deserialize(raw, c.msgtype).data)
      break
    if not (np.isfinite(scale) and 1e-6 <= scale <= 1.0):
      raise ValueError(f'{path}: {units[0].topic}: depth unit {scale} m is not one')

  frames, stamps, first = [], [], None
  for i, (c, t_ns, raw) in enumerate(reader.messages(connections=[depth_c])):
    if i < start:
      continue
    msg = reader.deserialize(raw, c.msgtype)
    if first is None:
      first = (int(msg.width), int(msg.height))
      header = video_files.Header(max(depth_c.msgcount - start, 1), first[1], first[0])
      if (
        max(first) > video_files.MAX_SIDE
        or header.decoded_bytes > video_files.MAX_BYTES
      ):
        raise ValueError(
          f'{path}: {depth_c.topic}: {header.frames} frames of {first[0]} x '
          f'{first[1]} px ({header.decoded_bytes / 2**30:.1f} GiB decoded): too large'
        )
    elif (int(msg.width), int(msg.height)) != first:
      raise ValueError(
        f'{path}: {depth_c.topic}: message {i} is {msg.width} x {msg.height} px, '
        f'the first {first[0]} x {first[1]}'
      )
    frames.append(_image(path, depth_c.topic, msg, scale))
    stamps.append(_stamp(msg, t_ns))
  if not frames:
    raise ValueError(f'{path}: {depth_c.topic}: no depth frames (after start {start})')
  depth = np.stack(frames)
  fps = None
  if len(stamps) > 1:
    dt = np.diff(np.asarray(stamps))
    if (dt > 0).all():
      fps = float(1.0 / np.median(dt))

  camera, cam_frame = None, ''
  if info_c is not None:
    for c, _, raw in reader.messages(connections=[info_c]):
      msg = reader.deserialize(raw, c.msgtype)
      camera, cam_frame = _camera(path, info_c.topic, msg), _frame_id(msg)
      break
  gravity, notes = None, []
  if imu_c is not None:
    gravity, note = _gravity(reader, path, imu_c, conns, cam_frame, bool(imu_topic))
    notes += [note] if note else []
  topics = {
    'depth': depth_c.topic,
    'info': info_c.topic if info_c is not None else '',
    'imu': imu_c.topic if imu_c is not None and gravity is not None else '',
  }
  return BagRecording(depth, fps, camera, gravity, topics, tuple(notes))


def _gravity(reader, path, imu_c, conns, cam_frame: str, named: bool):
  """(gravity in the camera frame or None, a note or None)."""
  readings, t0, imu_frame = [], None, ''
  for c, t_ns, raw in reader.messages(connections=[imu_c]):
    msg = reader.deserialize(raw, c.msgtype)
    t = _stamp(msg, t_ns)
    t0 = t if t0 is None else t0
    if t - t0 > IMU_SECONDS:
      break
    a = msg.linear_acceleration
    readings.append([float(a.x), float(a.y), float(a.z)])
    imu_frame = imu_frame or _frame_id(msg)
  mean = np.mean(readings, axis=0) if readings else np.zeros(3)
  norm = float(np.linalg.norm(mean))
  if not (np.isfinite(norm) and 5.0 < norm < 15.0):
    why = f'{imu_c.topic}: mean acceleration {norm:.2f} m/s^2 is not gravity at rest'
    if named:
      raise ValueError(f'{path}: {why}')
    return None, f'{why}; the IMU is left out'
  up = mean / norm  # an accelerometer at rest reads up
  if imu_frame and cam_frame and imu_frame != cam_frame:
    edges = {}
    for c in conns:
      if c.msgtype in TF and c.topic.endswith('tf_static'):
        for _, _, raw in reader.messages(connections=[c]):
          for tr in reader.deserialize(raw, c.msgtype).transforms:
            parent = str(tr.header.frame_id).lstrip('/')
            edges[(parent, str(tr.child_frame_id).lstrip('/'))] = _quat_matrix(
              tr.transform.rotation
            )
    r = _rotation_between(edges, imu_frame, cam_frame)
    if r is None:
      why = (
        f"{imu_c.topic}: its frame {imu_frame!r} is not related to the camera's "
        f'{cam_frame!r} by /tf_static'
      )
      if named:
        raise ValueError(f'{path}: {why}; give --world_up or "gravity" instead')
      return None, f'{why}; the IMU is left out'
    up = r @ up
  elif not (imu_frame and cam_frame):
    why = f"{imu_c.topic}: no frame ids relate the IMU's axes to the camera's"
    if named:  # the user named it: its axes taken as the camera's
      return -up, f"{why}; its axes are taken as the depth camera's"
    return (
      None,
      f"{why}; the IMU is left out (--imu_topic takes its axes as the camera's)",
    )
  return -up, None
