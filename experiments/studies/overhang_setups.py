"""Overhang set-ups the depth reader (``physsim.overhang_depth``) was not
fitted to: a strip of known bending length over a table's edge, the strip,
table and camera drawn from ranges (``SETUPS``), its frames rendered by the
project's ray-caster or MuJoCo's OpenGL renderer, and read.

The strip hangs as the heavy elastica (``physsim.tabletop``); the camera is
Kinect-class (640 x 480, ``physsim.sensor``'s noise), five frames. A set-up
is a dict (JSON-ready: a results file keeps it) of the strip's, the table's
and the camera's numbers, the aim along the edge and the overhang the user
reads off the strip's marks.
"""

from __future__ import annotations

import math

import jax
import numpy as np

import physsim
from experiments.studies.overhang_law import with_law
from physsim import cantilever, gl_depth, overhang_depth, sensor, tabletop

INTRINSICS = physsim.Intrinsics(640, 480, 58.0, 45.0)
FRAMES = 5
RULER_SD = 0.001  # m: the overhang read off the strip's marks

# The ranges set-ups are drawn from: 'protocol' as README's "How to record"
# asks (the overhang in Peirce's two bending lengths: 1.25-1.75 of them is
# about three, the tip hanging nearly straight down; camera distance in m and
# angles in degrees); 'peirce' the same at Peirce's own overhang (0.8-1.3 of
# two bending lengths, the tip some 40 degrees down: the protocol before
# 2026-11-29, whose 1 mm of ruler was a larger share of a shorter strip);
# 'wide' as a user who reads it loosely might film: the overhang from one to
# four bending lengths, the camera up to 1 m away, 10-60 degrees above the
# table and 40 to the side, strips 1.5-8 cm wide.
_CAMERA = dict(
  width=(0.025, 0.05), distance=(0.35, 0.55), elevation=(20.0, 40.0), azimuth=25.0
)
SETUPS = {
  'protocol': dict(overhang=(1.25, 1.75), **_CAMERA),
  'peirce': dict(overhang=(0.8, 1.3), **_CAMERA),
  'wide': dict(overhang=(0.5, 2.0), width=(0.015, 0.08), distance=(0.3, 1.0),
               elevation=(10.0, 60.0), azimuth=40.0),
}  # fmt: skip


def bending_length_of(i: int, run: dict | None, rng: np.random.Generator) -> float:
  """The ``i``-th set-up's true bending length c, m: of a packed run's truth
  (``overhang_joint.packed_runs``), else of the fabrics in turn, each with
  a truth drawn from its search box by ``rng``."""
  if run is not None:
    t = run['truth']
    space = physsim.search_space(run['material'])
    b, w = t['bending_scale'], t['area_weight']
  else:
    material = sorted(physsim.FABRICS)[i % len(physsim.FABRICS)]
    space = physsim.search_space(material)
    u = rng.uniform(-1, 1, 3)
    p = physsim.params.from_unit(u, space)
    b, w = float(p.bending_scale), float(p.area_weight)
  return float(physsim.params.bending_length(b, w, space.rigidity))


def draw_setup(rng: np.random.Generator, c: float, ranges: str = 'protocol') -> dict:
  """A world's set-up for a strip of bending length ``c`` (m), drawn from
  ``SETUPS[ranges]``."""
  r = SETUPS[ranges]
  true_l = max(0.015, 2 * c * rng.uniform(*r['overhang']))
  told_l = round(true_l * 200) / 200  # read off the strip's 5 mm marks
  true_l = told_l + rng.normal(0, RULER_SD)
  setup = {
    'strip': dict(
      overhang=float(true_l), bending_length=float(c),
      width=float(rng.uniform(*r['width'])),
      thickness=float(rng.uniform(0.0003, 0.0015)),
      curl=float(rng.uniform(-0.001, 0.0015)),
      yaw_deg=float(rng.uniform(-5, 5)), x=float(rng.uniform(-0.1, 0.1)),
    ),
    'table': dict(height=float(rng.uniform(0.7, 0.8)),
                  thickness=float(rng.uniform(0.018, 0.04))),
    'camera': dict(distance=float(rng.uniform(*r['distance'])),
                   elevation_deg=float(rng.uniform(*r['elevation'])),
                   azimuth_deg=float(rng.uniform(-r['azimuth'], r['azimuth'])),
                   roll_deg=float(rng.uniform(-5, 5))),
    'aim': float(rng.uniform(-0.03, 0.03)),
    'told_overhang': float(told_l),
  }  # fmt: skip
  strip = setup['strip']  # its longest fibre within the elastica's table
  spread = tabletop.askew_spread(strip['width'], strip['yaw_deg'])
  strip['overhang'] = min(true_l, 0.98 * cantilever.MAX_RATIO * c - spread)
  return setup


MJ_FOVY = 45.0
_MJ_F = 0.5 * 480 / math.tan(math.radians(MJ_FOVY / 2))
MJ_INTRINSICS = physsim.Intrinsics.from_pinhole(640, 480, _MJ_F, _MJ_F, 319.5, 239.5)


def intrinsics(renderer: str) -> physsim.Intrinsics:
  """The camera a renderer's frames are made with: MuJoCo's square pixels
  (``MJ_FOVY`` vertical), or the Kinect-class ``INTRINSICS``."""
  return MJ_INTRINSICS if renderer == 'mujoco' else INTRINSICS


def _mujoco_depth(strip, table, pose) -> np.ndarray:
  """A clean depth frame by MuJoCo's OpenGL renderer (MUJOCO_GL=egl)."""
  import mujoco  # noqa: PLC0415 - only this renderer needs it here

  model = mujoco.MjModel.from_xml_string(tabletop.mjcf(strip, pose, table, MJ_FOVY))
  r = mujoco.Renderer(model, MJ_INTRINSICS.height, MJ_INTRINSICS.width)
  return gl_depth.mujoco_depth(model, r, far=25.0).astype(np.float32)


def render_setup(setup: dict, key, renderer: str = 'raycaster') -> np.ndarray:
  """(FRAMES, H, W) noisy depth frames of a set-up."""
  strip = tabletop.Strip(**setup['strip'])
  table = tabletop.Table(**setup['table'])
  cam = setup['camera']
  pose = tabletop.camera(table, cam['distance'], cam['elevation_deg'],
                         cam['azimuth_deg'], cam['roll_deg'],
                         x=strip.x + setup['aim'])  # fmt: skip
  intr = intrinsics(renderer)
  if renderer == 'raycaster':
    return tabletop.depth_frames(strip, pose, table, intr, FRAMES, key)
  clean = _mujoco_depth(strip, table, pose)
  frames = jax.numpy.broadcast_to(clean, (FRAMES, *clean.shape))
  return np.asarray(sensor.apply_noise_frames(key, frames, intr))


def read_setup(setup: dict, key, floor: float, dof: float,
               renderer: str = 'raycaster') -> dict:  # fmt: skip
  """The reader's c on a set-up, with its error under the law (``floor``,
  ``dof``: ``with_law``)."""
  depth = render_setup(setup, key, renderer)
  c = setup['strip']['bending_length']
  row = {'c': c, 'setup': setup}
  try:
    r = overhang_depth.read(
      depth, intrinsics(renderer), setup['told_overhang'], RULER_SD
    )
  except ValueError as e:
    return {**row, 'refused': str(e)}
  row = {**row, 'read': r.to_dict(), 'c_hat': r.bending_length,
         'error': r.bending_length / c - 1.0,
         'profile': r.profile[:: max(1, len(r.profile) // 1500)]}  # fmt: skip
  return with_law(row, floor, dof)
