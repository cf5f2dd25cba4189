"""A strip of fabric overhanging a table's edge, as a depth camera sees it.

The scene of the cantilever recording (issue 39's overhang): a table (its top
and the front face of its top board) on a floor, and a strip lying on the
table with ``overhang`` of it past the edge, hanging as the heavy elastica of
its bending length (``physsim.cantilever.shape``). World frame: z up, the
table's top at ``Table.height``, its front edge along x at y = 0, the table
behind it (y < 0). ``scene`` gives triangles for ``physsim.render`` and
``camera`` a pose in front of the edge: what ``benchmarks.overhang_depth`` and
the tests render and ``physsim.overhang_depth`` reads.

A strip can differ from the ideal one the way a real one does: its
cross-section curls (``curl``), it has a thickness (the camera sees its upper
face), and it may leave the edge at an angle (``yaw_deg``).
"""

from __future__ import annotations

import dataclasses
import math
import os

import cv2
import numpy as np

from physsim import camera as camera_lib
from physsim import cantilever, dataset, render, sensor

# write_recording's default camera: a depth camera's 58 x 45 degrees at 320 x 240
RECORDING_CAMERA = camera_lib.Intrinsics(320, 240)


@dataclasses.dataclass(frozen=True)
class Table:
  """A table top and the floor under it.

  Attributes:
    height: the top above the floor, m.
    thickness: the top board's, m: the front face's height below the edge.
    width: along the edge (x), m.
    depth: back from the edge (y < 0), m.
  """

  height: float = 0.75
  thickness: float = 0.03
  width: float = 0.8
  depth: float = 0.6


@dataclasses.dataclass(frozen=True)
class Strip:
  """A strip lying on the table with part of it over the edge.

  Attributes:
    overhang: its length past the edge along the strip (L), m.
    bending_length: c = (D / (w g))^(1/3), m.
    width: across the strip, m.
    on_table: its length lying on the table, m.
    thickness: m; the camera sees the upper face, half of it off the centre line.
    curl: how far the cross-section's edges rise above its middle, m
      (negative: they fall).
    yaw_deg: the strip's direction from the edge's normal, degrees.
    x: where along the edge its middle crosses it, m.
  """

  overhang: float
  bending_length: float
  width: float = 0.03
  on_table: float = 0.1
  thickness: float = 0.0
  curl: float = 0.0
  yaw_deg: float = 0.0
  x: float = 0.0

  def __post_init__(self):
    for name in ('overhang', 'bending_length', 'width', 'on_table'):
      v = getattr(self, name)
      if not (math.isfinite(v) and v > 0):
        raise ValueError(f'Strip.{name} must be a finite length > 0 m, got {v!r}')
    if not (math.isfinite(self.yaw_deg) and abs(self.yaw_deg) < 45.0):
      raise ValueError(f'Strip.yaw_deg must be within +-45 degrees: {self.yaw_deg!r}')
    spread = askew_spread(self.width, self.yaw_deg)
    if not self.overhang > spread:
      raise ValueError(
        f'Strip: askew by {self.yaw_deg} degrees, a fibre at its side would not '
        f'reach the edge (overhang {self.overhang} m, width {self.width} m)'
      )
    ratio = (self.overhang + spread) / self.bending_length
    if not ratio <= cantilever.MAX_RATIO:
      raise ValueError(
        f'Strip: an overhang of {self.overhang} m (its longest fibre '
        f'{self.overhang + spread:.4g} m) is {ratio:.3g} bending lengths; '
        f'the elastica is solved to {cantilever.MAX_RATIO:g}'
      )


def _rect(corner, a, b, na: int, nb: int) -> tuple[np.ndarray, np.ndarray]:
  """(vertices, faces) of the parallelogram corner + [0, 1] a + [0, 1] b on
  an na x nb grid of quads (large faces split so that none crosses far)."""
  s, t = np.meshgrid(
    np.linspace(0, 1, na + 1), np.linspace(0, 1, nb + 1), indexing='ij'
  )
  v = np.asarray(corner) + s[..., None] * np.asarray(a) + t[..., None] * np.asarray(b)
  return v.reshape(-1, 3), _grid_faces(na + 1, nb + 1)


def _grid_faces(rows: int, cols: int) -> np.ndarray:
  """Two triangles per quad of a rows x cols vertex grid (row-major)."""
  i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing='ij')
  a = (i * cols + j).ravel()
  b, c, d = a + 1, a + cols, a + cols + 1
  return np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])


def table_mesh(table: Table, floor_to_y: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
  """(vertices, faces) of the table's top, its front face and the floor (the
  floor from behind the table to ``floor_to_y``: keep it in front of the
  camera)."""
  h, w = table.height, table.width
  parts = [
    _rect((-w / 2, -table.depth, h), (w, 0, 0), (0, table.depth, 0), 8, 6),
    _rect((-w / 2, 0, h - table.thickness), (w, 0, 0), (0, 0, table.thickness), 8, 1),
    _rect((-3, -5, 0), (6, 0, 0), (0, 5 + floor_to_y, 0), 12, 12),
  ]
  return _join(parts)


def _join(parts) -> tuple[np.ndarray, np.ndarray]:
  verts, faces, n = [], [], 0
  for v, f in parts:
    verts.append(v)
    faces.append(f + n)
    n += len(v)
  return np.concatenate(verts), np.concatenate(faces)


def askew_spread(width: float, yaw_deg: float) -> float:
  """How much longer an askew strip's longest fibre hangs than its middle
  (and its shortest shorter), m: half the width times tan(yaw)."""
  return width / 2 * abs(math.tan(math.radians(yaw_deg)))


def fibre_overhangs(strip: Strip, cols: int = 9) -> tuple[np.ndarray, np.ndarray]:
  """(across offsets t, overhangs) of ``cols`` fibres along the strip: a strip
  laid askew (``yaw_deg``) crosses the edge obliquely, so with its end cut
  square each fibre leaves the edge at its own point and hangs by its own
  length, ``overhang`` at the middle (where the ruler reads it) and
  ``overhang - t tan(yaw)`` at ``t`` across."""
  t = np.linspace(-strip.width / 2, strip.width / 2, cols)
  return t, strip.overhang - t * math.tan(math.radians(strip.yaw_deg))


def strip_mesh(strip: Strip, table: Table, rows: int = 80,
               cols: int = 9) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
  """(vertices, faces) of the strip's upper face: ``rows`` points along its
  hanging part, a few on the table, ``cols`` across. Each fibre (a column)
  bends at the edge, where the table stops holding it, and hangs as the
  heavy elastica of its own overhang (``fibre_overhangs``; one length for
  all when the strip is square to the edge), its centre line half the
  thickness above the top."""
  t, lengths = fibre_overhangs(strip, cols)
  line = cantilever.shape(lengths / strip.bending_length) * lengths[:, None, None]
  pick = np.unique(np.round(np.linspace(0, line.shape[1] - 1, rows)).astype(int))
  along, drop = line[:, pick, 0].T, line[:, pick, 1].T  # (rows, cols)
  # the tangent's angle below the horizontal, and the upper face's normal
  theta = np.arctan2(np.gradient(drop, axis=0), np.gradient(along, axis=0))
  n_along, n_up = np.sin(theta), np.cos(theta)
  yaw = math.radians(strip.yaw_deg)
  start = t * math.tan(yaw)  # (cols,) where each fibre meets the edge, along it
  back = np.linspace(-strip.on_table, 0.0, 6)[:-1, None] + np.zeros_like(start)
  along = np.concatenate([back, along]) + start
  drop = np.concatenate([np.zeros_like(back), drop])
  n_along = np.concatenate([np.zeros_like(back), n_along])
  n_up = np.concatenate([np.ones_like(back), n_up])
  d = np.array([math.sin(yaw), math.cos(yaw), 0.0])  # along the strip, outwards
  e = np.array([math.cos(yaw), -math.sin(yaw), 0.0])  # across
  up = np.array([0.0, 0.0, 1.0])
  lift = strip.thickness / 2 + strip.curl * (2 * t / strip.width) ** 2  # (cols,)
  root = np.array([strip.x, 0.0, table.height + strip.thickness / 2])
  centre = root + along[..., None] * d - drop[..., None] * up  # (rows, cols, 3)
  normal = n_along[..., None] * d + n_up[..., None] * up
  v = centre + t[None, :, None] * e + lift[None, :, None] * normal
  return v.reshape(-1, 3), _grid_faces(len(along), cols)


def scene(strip: Strip, table: Table = Table(),
          floor_to_y: float = 0.4) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
  """(vertices float32, faces int32) of the table, floor and strip."""
  v, f = _join([table_mesh(table, floor_to_y), strip_mesh(strip, table)])
  return v.astype(np.float32), f.astype(np.int32)


def camera(table: Table, distance: float, elevation_deg: float, azimuth_deg: float = 0.0,
           roll_deg: float = 0.0, x: float = 0.0,
           below_edge: float = 0.03) -> camera_lib.Pose:  # fmt: skip
  """A camera ``distance`` m from a point ``below_edge`` under the edge at
  ``x``, looking at it from ``elevation_deg`` above the horizontal and
  ``azimuth_deg`` off the edge's normal."""
  target = np.array([x, 0.0, table.height - below_edge])
  el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
  eye = target + distance * np.array(
    [math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)]
  )
  return camera_lib.look_at(eye, target, roll_deg=roll_deg)


def mjcf(strip: Strip, pose: camera_lib.Pose, table: Table = Table(),
         fovy_deg: float = 45.0) -> str:  # fmt: skip
  """The same scene for MuJoCo's own OpenGL renderer (an independent check of
  the ray-caster's): the table's top a box, the floor a box, the strip's
  upper face a two-sided mesh, and a camera ``cam`` at ``pose`` (OpenCV axes)
  with a vertical field of view of ``fovy_deg``."""
  v, f = strip_mesh(strip, table)
  faces = np.concatenate([f, f[:, ::-1]])
  r = np.asarray(pose.rotation, np.float64)
  xyaxes = np.concatenate([r[:, 0], -r[:, 1]])  # MuJoCo's camera: y up

  def fmt(a):
    return ' '.join(f'{x:.9g}' for x in np.ravel(a))

  h, t = table.height, table.thickness
  return f"""
<mujoco>
  <visual><map znear="0.01" zfar="30"/></visual>
  <asset>
    <mesh name="strip" vertex="{fmt(v)}" face="{fmt(faces)}" inertia="shell"/>
  </asset>
  <worldbody>
    <geom name="strip" type="mesh" mesh="strip" contype="0" conaffinity="0"/>
    <geom name="top" type="box" size="{table.width / 2} {table.depth / 2} {t / 2}"
      pos="0 {-table.depth / 2} {h - t / 2}" contype="0" conaffinity="0"/>
    <geom name="floor" type="box" size="4 4 0.05" pos="0 0 -0.05" contype="0"
      conaffinity="0"/>
    <camera name="cam" pos="{fmt(pose.position)}" xyaxes="{fmt(xyaxes)}" fovy="{fovy_deg}"/>
  </worldbody>
</mujoco>"""


def depth_frames(strip: Strip | None, pose: camera_lib.Pose, table: Table = Table(),
                 intrinsics: camera_lib.Intrinsics = RECORDING_CAMERA,
                 frames: int = 1, key=None) -> np.ndarray:  # fmt: skip
  """(frames, H, W) depth of the scene (the table alone for ``strip`` None)
  by the ray-caster from ``pose``, metres, 0 where nothing is hit; with
  ``key``, each frame with the sensor model's own noise, else all alike."""
  floor_to_y = float(np.asarray(pose.position)[1]) - 0.05  # in front of the camera
  if strip is None:
    v, f = table_mesh(table, floor_to_y)
    v, f = v.astype(np.float32), f.astype(np.int32)
  else:
    v, f = scene(strip, table, floor_to_y)
  clean = render.depth_image(v, f, intrinsics, pose)
  stack = np.broadcast_to(np.asarray(clean), (frames, *clean.shape))
  if key is not None:
    stack = np.asarray(sensor.apply_noise_frames(key, stack, intrinsics))
  return stack


def write_recording(root: str, strip: Strip, table: Table = Table(),
                    pose: camera_lib.Pose | None = None,
                    intrinsics: camera_lib.Intrinsics = RECORDING_CAMERA,
                    frames: int = 3, key=None) -> tuple[str, str]:  # fmt: skip
  """A recording of the scene as a depth camera's tools write it: ``frames``
  16-bit PNG frames in mm (the ray-caster's; with ``key``, the sensor
  model's noise on each) under ``<root>/strip`` and the camera's OpenCV-style
  JSON ``<root>/strip_camera.json``; the camera ``pose`` (default: 0.4 m in
  front of the edge, 28 degrees up, 10 to the side). Returns both paths."""
  pose = pose if pose is not None else camera(table, 0.4, 28.0, 10.0, x=strip.x)
  stack = depth_frames(strip, pose, table, intrinsics, frames, key)
  folder = os.path.join(root, 'strip')
  partial = folder + '.partial'  # renamed once every frame is written
  os.makedirs(partial)
  for k, mm in enumerate(dataset.depth_to_mm(stack)):
    if not cv2.imwrite(os.path.join(partial, f'{k:04d}.png'), mm):
      raise OSError(f'{partial}: could not write frame {k}')
  os.rename(partial, folder)
  cam = os.path.join(root, 'strip_camera.json')
  i = intrinsics
  dataset.write_json_atomic(
    cam, {'width': i.width, 'height': i.height, 'fx': i.fx, 'fy': i.fy,
          'cx': i.cx, 'cy': i.cy},
  )  # fmt: skip
  return folder, cam
