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
face), and it may leave the edge at an angle (``yaw_deg``). A real table's
edge is rounded (``Table.edge_radius``): the top stops being flat that far
behind the line where its plane meets the front face's, and a strip lying on
it starts to bend there (its root curvature is below the rounding's for
radii of a few mm: it leaves the top where the rounding starts).

Where the overhang and the reach are measured (``physsim.overhang_depth`` and
``experiments.overhang`` read them so): from the front face's plane, the
table's outermost line seen from above. The overhang ``L`` is the strip's
length past the point of it above that plane (where a ruler laid along the
strip meets the edge), the reach its free end's horizontal distance out
from that plane. On a sharp edge both are the elastica's own; on a rounded
one the strip's free length is ``L`` plus the bit of it over the rounding
(about the radius).
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
    edge_radius: the rounding of the edge between the top and the front
      face, m (0: sharp): the top flat to y = -radius, the face flat from
      radius under the top.
  """

  height: float = 0.75
  thickness: float = 0.03
  width: float = 0.8
  depth: float = 0.6
  edge_radius: float = 0.0

  def __post_init__(self):
    r = self.edge_radius
    if not (math.isfinite(r) and 0.0 <= r < min(self.thickness, self.depth)):
      raise ValueError(
        f'Table.edge_radius must be >= 0 m and under the board, got {r!r}'
      )


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
  h, w, r = table.height, table.width, table.edge_radius
  # the top's section (y, z), back to front, over the rounding and down the face
  angle = np.linspace(0.0, np.pi / 2, 13 if r > 0 else 1)
  section = np.concatenate([
    np.stack([np.linspace(-table.depth, -r, 7)[:-1], np.full(6, h)], 1),
    np.stack([-r + r * np.sin(angle), h - r + r * np.cos(angle)], 1),
    [[0.0, h - table.thickness]],
  ])  # fmt: skip
  x = np.linspace(-w / 2, w / 2, 9)
  top = np.stack(np.broadcast_arrays(
    x[:, None], section[None, :, 0], section[None, :, 1]), -1)  # fmt: skip
  top = (top.reshape(-1, 3), _grid_faces(9, len(section)))
  floor = _rect((-3, -5, 0), (6, 0, 0), (0, 5 + floor_to_y, 0), 12, 12)
  return _join([top, floor])


def drape(strip: Strip, table: Table) -> tuple[float, float]:
  """How the strip's middle lies over the edge's rounding: (the angle below
  the horizontal at which it leaves the rounding, rad; its length from where
  the rounding starts to where its centre line is above the front face's
  plane, m, which ``strip_mesh`` adds to each fibre's overhang). The strip
  follows the rounding (its centre line a circle of the radius and half its
  thickness) as long as the free part's root curvature would exceed the
  circle's, and leaves it where they are equal (``cantilever.leaving``): a
  stiff strip at once, flat, a soft one some way round. (0, 0) on a sharp
  edge."""
  r = table.edge_radius
  if r <= 0:
    return 0.0, 0.0
  big = strip.thickness / 2 + r  # the centre line's radius over the rounding
  c = strip.bending_length
  ahead = r / math.cos(math.radians(strip.yaw_deg))  # to the face, along the fibre
  setback, angle = ahead, 0.0
  for _ in range(2):  # the setback holds the bit before the face, and sets it
    total = strip.overhang + setback
    flat, moment = cantilever.leaving(total / c, 0.0)
    angle = 0.0
    if moment > c / big:  # its root would bend tighter than the rounding
      angles = np.linspace(0.0, min(total / big, 1.5), 24)[1:]
      angles = angles[total - big * angles > 0.05 * c]
      _, moment = cantilever.leaving((total - big * angles) / c, angles)
      ask = np.concatenate([[1.0], moment - c / big])  # falls as it goes round
      k = int(np.argmax(ask <= 0)) or len(ask) - 1  # the first angle past it
      angle = float(np.interp(0.0, ask[[k, k - 1]], np.r_[0.0, angles][[k, k - 1]]))
    if big * math.sin(angle) >= ahead:  # above the face while on the rounding
      setback = big * math.asin(ahead / big)
      continue
    free = total - big * angle
    line = (cantilever.leaving(free / c, angle)[0] if angle else flat) * free
    arc = np.linspace(0.0, free, len(line))
    setback = big * angle + float(
      np.interp(ahead - big * math.sin(angle), line[:, 0], arc)
    )
  return angle, setback


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
  bends at the edge, where the table stops holding it (where a rounded
  edge's rounding starts), and hangs as the heavy elastica of its own
  overhang (``fibre_overhangs``; one length for all when the strip is square
  to the edge), over a rounded edge first round the rounding as far as it
  follows it and with the bit before the face added (``drape``), its centre
  line half the thickness above the top."""
  t, lengths = fibre_overhangs(strip, cols)
  angle, setback = drape(strip, table)
  big = strip.thickness / 2 + table.edge_radius
  free = lengths + setback - big * angle  # past where it leaves the rounding
  line = cantilever.leaving(free / strip.bending_length, angle)[0]
  line = line * free[:, None, None]
  pick = np.unique(np.round(np.linspace(0, line.shape[1] - 1, rows)).astype(int))
  along, drop = line[:, pick, 0].T, line[:, pick, 1].T  # (rows, cols)
  # over the rounding, a circle from where it starts to where the strip leaves
  a = np.linspace(0.0, angle, 9)[:-1, None] if angle > 0 else np.zeros((0, 1))
  along = np.concatenate([big * np.sin(a) + 0 * t, along + big * math.sin(angle)])
  drop = np.concatenate(
    [big * (1 - np.cos(a)) + 0 * t, drop + big * (1 - math.cos(angle))]
  )
  # the tangent's angle below the horizontal, and the upper face's normal
  theta = np.arctan2(np.gradient(drop, axis=0), np.gradient(along, axis=0))
  n_along, n_up = np.sin(theta), np.cos(theta)
  yaw = math.radians(strip.yaw_deg)
  # (cols,) where each fibre leaves the top, along it: at the edge, or where
  # its rounding starts
  start = t * math.tan(yaw) - table.edge_radius / math.cos(yaw)
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
  the ray-caster's): the table's top a box (a rounded edge: a box under a
  cylinder), the floor a box, the strip's
  upper face a two-sided mesh, and a camera ``cam`` at ``pose`` (OpenCV axes)
  with a vertical field of view of ``fovy_deg``."""
  v, f = strip_mesh(strip, table)
  faces = np.concatenate([f, f[:, ::-1]])
  r = np.asarray(pose.rotation, np.float64)
  xyaxes = np.concatenate([r[:, 0], -r[:, 1]])  # MuJoCo's camera: y up

  def fmt(a):
    return ' '.join(f'{x:.9g}' for x in np.ravel(a))

  h, t, r = table.height, table.thickness, table.edge_radius
  # a rounded edge: the board set back by r, a board under the rounding and
  # a cylinder along the edge
  rounding = (
    f"""
    <geom name="under" type="box" size="{table.width / 2} {r / 2} {(t - r) / 2}"
      pos="0 {-r / 2} {h - (t + r) / 2}" contype="0" conaffinity="0"/>
    <geom name="rounding" type="cylinder" size="{r} {table.width / 2}"
      pos="0 {-r} {h - r}" euler="0 90 0" contype="0" conaffinity="0"/>"""
    if r > 0
    else ''
  )
  return f"""
<mujoco>
  <visual><map znear="0.01" zfar="30"/></visual>
  <asset>
    <mesh name="strip" vertex="{fmt(v)}" face="{fmt(faces)}" inertia="shell"/>
  </asset>
  <worldbody>
    <geom name="strip" type="mesh" mesh="strip" contype="0" conaffinity="0"/>
    <geom name="top" type="box" size="{table.width / 2} {(table.depth - r) / 2} {t / 2}"
      pos="0 {-(table.depth + r) / 2} {h - t / 2}" contype="0" conaffinity="0"/>{rounding}
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
