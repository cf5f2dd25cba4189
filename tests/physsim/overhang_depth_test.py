"""physsim.overhang_depth: a strip's bending length read from rendered depth
frames of an overhang (physsim.tabletop), against the truth the scene was
made with, the elastica's tip (physsim.cantilever) and the camera's pose."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import physsim
from physsim import cantilever, gl_depth, overhang_depth, overhang_fit, tabletop

INTR = physsim.Intrinsics(320, 240, 58.0, 45.0)
TABLE = tabletop.Table()
# A clean render: the planes and the edge are exact up to the pixels, so the
# fit finds c to its grids' steps and the render's flat triangles (80 along
# the strip).
_CLEAN_TOL = 0.015
_TIP_TOL_M = 0.001
_HEIGHT_TOL_M = 0.002


def _pose(distance=0.4, elevation=28.0, azimuth=10.0, x=0.0):
  return tabletop.camera(TABLE, distance, elevation, azimuth, x=x)


def _render(strip, pose, key=None, frames=3, table=TABLE):
  """One clean frame, or ``frames`` noisy ones with ``key``."""
  d = tabletop.depth_frames(strip, pose, table, INTR, frames, key)
  return d if key is not None else d[0]


def _read_on(table, strip, distance, elevation, seed):
  """``strip`` over ``table`` in three noisy frames from ``distance`` m,
  ``elevation`` degrees above its top and 10 to the side: (depth, reading)."""
  pose = tabletop.camera(table, distance, elevation, 10.0)
  depth = _render(strip, pose, jax.random.key(seed), table=table)
  return depth, overhang_depth.read(depth, INTR, strip.overhang, 0.001)


def test_a_clean_strip_is_read_to_its_bending_length():
  strip = tabletop.Strip(overhang=0.04, bending_length=0.02)
  pose = _pose()
  r = overhang_depth.read(_render(strip, pose), INTR, 0.04, 0.001)
  assert r.bending_length == pytest.approx(0.02, rel=_CLEAN_TOL)
  reach, drop = cantilever.tip(0.04 / 0.02)
  assert r.reach == pytest.approx(0.04 * reach[0], abs=_TIP_TOL_M)
  assert r.drop == pytest.approx(0.04 * drop[0], abs=_TIP_TOL_M)
  # the camera above the table's top, from the pose it was rendered from
  height = float(np.asarray(pose.position)[2]) - TABLE.height
  assert r.camera_height_m == pytest.approx(height, abs=_HEIGHT_TOL_M)
  assert r.points > 100 and r.face_points > 500
  # its law: a t of DOF degrees of freedom whose scale is the fit's spread
  # and the floor in quadrature; its sd that scale times sqrt(dof / (dof - 2))
  assert r.bending_length_dof == overhang_depth.DOF == 10.0
  scale = np.hypot(r.fit_sd, overhang_depth.FLOOR * r.bending_length)
  assert r.bending_length_sd == pytest.approx(scale * np.sqrt(10.0 / 8.0), rel=1e-12)
  # the ruler's 1 mm is in it: its share of c, c x 1 mm / L, is a lower bound
  # (half of it here, loosely: the shape's own spread adds to it)
  assert r.fit_sd > 0.5 * 0.02 * 0.001 / 0.04


def test_a_real_strip_under_a_noisy_camera_is_within_its_interval():
  """Thickness, a curled cross-section, an askew strip, a Kinect-class
  camera's noise and holes: the reading moves, within its uncertainty."""
  strip = tabletop.Strip(
    overhang=0.05, bending_length=0.03, width=0.04, thickness=0.001, curl=0.001,
    yaw_deg=4.0, x=0.05,
  )  # fmt: skip
  pose = _pose(0.45, 32.0, -15.0, x=0.04)
  r = overhang_depth.read(_render(strip, pose, jax.random.key(3)), INTR, 0.05, 0.001)
  assert abs(r.bending_length - 0.03) < 2.0 * r.bending_length_sd, r
  assert r.fit_sd < r.bending_length_sd
  assert r.residual_m < 0.002


def test_an_askew_strips_fibres_each_bend_at_the_edge_and_hang_their_own_length():
  """A strip laid 5 degrees askew: no part of it below the table's top lies
  over the table (behind the edge, y < 0), and each fibre (a mesh column,
  thin and flat: its centre line) hangs by its own overhang, the middle's
  ``overhang`` less t tan(yaw) at t across (arc length from where it
  crosses the edge, the sum of its segments: 80 along it, so to 0.5%)."""
  strip = tabletop.Strip(overhang=0.03, bending_length=0.012, width=0.05, yaw_deg=5.0)
  v, _ = tabletop.strip_mesh(strip, TABLE, cols=9)
  v = v.reshape(-1, 9, 3)
  hanging = v[:, :, 2] < TABLE.height - 1e-6
  assert hanging.any() and (v[:, :, 1][hanging] >= -1e-9).all()
  t, lengths = tabletop.fibre_overhangs(strip, 9)
  assert lengths[4] == pytest.approx(0.03, rel=1e-12)
  assert lengths[0] - lengths[-1] == pytest.approx(0.05 * np.tan(np.radians(5.0)))
  for k in range(9):
    column = v[:, k]
    out = column[column[:, 1] >= -1e-9]  # from the edge on
    arc = np.linalg.norm(np.diff(out, axis=0), axis=1).sum()
    assert arc == pytest.approx(lengths[k], rel=0.005), k
  square = tabletop.strip_mesh(dataclasses.replace(strip, yaw_deg=0.0), TABLE)[0]
  ends = square.reshape(-1, 9, 3)[-1]
  assert np.ptp(ends[:, 1]) < 1e-12 and np.ptp(ends[:, 2]) < 1e-12


def test_the_overhang_is_the_rulers_the_curve_reads_the_shape():
  """A strip told 1 mm longer than it is: the reading keeps the ruler's L
  (what scales the curve besides L, noise and thickness, would move it) and
  reads L / c from the shape at each of the ruler's L, so c moves with part
  of L's error, and c's sd is that part of the ruler's 1 mm. The part is
  checked against an independent finite difference: the same points fitted
  at two exact lengths either side."""
  strip = tabletop.Strip(overhang=0.03, bending_length=0.015)
  told = 0.031
  r = overhang_depth.read(_render(strip, _pose()), INTR, told, 0.001)
  assert r.overhang == told
  # d log c / d log L of the shape fitted at an exact L
  at = [
    overhang_fit.fit(r.profile, told + d, 0.0, setback=r.edge_radius)['c']
    for d in (-0.001, 0.001)
  ]  # fmt: skip
  part = (at[1] - at[0]) / 0.002 * told / r.bending_length
  assert 0.3 < part < 0.95, part  # the curve's root holds c: not all of L
  moved = r.bending_length / 0.015 - 1.0
  assert moved == pytest.approx(part * (told / 0.03 - 1.0), abs=_CLEAN_TOL / 3)
  assert r.fit_sd == pytest.approx(part * r.bending_length * 0.001 / told, rel=0.2)


def test_the_fits_spread_is_the_spread_over_noise():
  """Points of a known elastica with independent noise: the fit's sd of c
  against the spread of its estimates over repeated noise (Monte Carlo)."""
  length, c, sd = 0.05, 0.025, 0.0007
  line = cantilever.shape(length / c) * length
  rng = np.random.default_rng(0)
  estimates, sds = [], []
  for _ in range(10):
    s = rng.uniform(0.25, 1.0, 200)  # the visible part: not the root
    i = np.round(s * (len(line) - 1)).astype(int)
    pts = line[i] + rng.normal(0.0, sd, (200, 2))
    f = overhang_fit.fit(pts, length, 0.0, point_sd=sd)
    estimates.append(f['c'])
    sds.append(f['c_sd'])
  spread = float(np.std(estimates, ddof=1))
  # ten draws know a standard deviation to about +-25%
  assert 0.5 < spread / np.mean(sds) < 2.0, (spread, np.mean(sds))
  assert abs(np.mean(estimates) - c) < 3 * spread / np.sqrt(10) + 1e-4


def test_no_strip_no_table_and_bad_frames_are_refused_by_name():
  pose = _pose()
  with pytest.raises(ValueError, match='rec: no strip hanging over the edge'):
    overhang_depth.read(_render(None, pose), INTR, 0.04, name='rec')
  wall = np.full((INTR.height, INTR.width), 1.5)  # a blank wall
  with pytest.raises(ValueError, match='rec: nothing under the table top'):
    overhang_depth.read(wall, INTR, 0.04, name='rec')
  with pytest.raises(ValueError, match=r'rec: frames of \(10, 10\) pixels'):
    overhang_depth.read(np.ones((10, 10)), INTR, 0.04, name='rec')
  with pytest.raises(ValueError, match='--overhang=0.0'):
    overhang_depth.read(wall, INTR, 0.0)
  with pytest.raises(ValueError, match='--overhang_sd=0.02'):
    overhang_depth.read(wall, INTR, 0.04, 0.02)


def test_a_strip_too_stiff_to_droop_is_refused():
  # 1 cm over a 4 cm bending length hardly bends: nothing to read c from
  strip = tabletop.Strip(overhang=0.012, bending_length=0.06)
  with pytest.raises(ValueError, match='hardly droops: slide more of it over'):
    overhang_depth.read(_render(strip, _pose()), INTR, 0.012, 0.001, name='rec')


def test_a_strip_past_the_elastica_or_of_no_size_is_refused():
  with pytest.raises(ValueError, match='bending lengths'):
    tabletop.Strip(overhang=0.3, bending_length=0.01)
  with pytest.raises(ValueError, match='Strip.width'):
    dataclasses.replace(tabletop.Strip(0.04, 0.02), width=float('nan'))


def test_a_strip_rendered_by_mujocos_own_renderer_is_read_too():
  """MuJoCo's OpenGL renderer (the table a box, square pixels), not the
  project's ray-caster: the reading does not lean on its conventions."""
  import math

  import mujoco

  from tests import mujoco_gl

  strip = tabletop.Strip(overhang=0.04, bending_length=0.02, thickness=0.001)
  pose = _pose()
  model = mujoco.MjModel.from_xml_string(tabletop.mjcf(strip, pose, TABLE, 45.0))
  renderer = mujoco_gl.offscreen_renderer(model, 240, 320)
  depth = gl_depth.mujoco_depth(model, renderer, far=25.0)
  f = 120 / math.tan(math.radians(22.5))
  intr = physsim.Intrinsics.from_pinhole(320, 240, f, f, 159.5, 119.5)
  r = overhang_depth.read(depth, intr, 0.04, 0.001)
  assert r.bending_length == pytest.approx(0.02, rel=2 * _CLEAN_TOL)
  height = float(np.asarray(pose.position)[2]) - TABLE.height
  assert r.camera_height_m == pytest.approx(height, abs=_HEIGHT_TOL_M)


def test_a_strip_short_of_the_protocols_overhang_is_told_how_far_to_slide_it():
  """Under ``SHORT_RATIO`` bending lengths, one line naming how many it hangs
  and the protocol's overhang in cm (three of the read c); none at three."""
  strip = tabletop.Strip(overhang=0.03, bending_length=0.015)  # two
  r = overhang_depth.read(_render(strip, _pose()), INTR, 0.03, 0.001)
  hint = overhang_depth.advice(r)
  assert hint.startswith('the strip hangs 2.0 bending lengths over the edge')
  assert f'about 3 ({100 * 3 * r.bending_length:.1f} cm' in hint
  assert overhang_depth.advice(dataclasses.replace(r, ratio=3.0)) is None


def _within(r, c, level=0.9):
  """Whether ``c`` lies in the reading's central ``level`` interval (its t
  law: the sd over sqrt(dof / (dof - 2)) its scale)."""
  from scipy import stats

  dof = r.bending_length_dof
  scale = r.bending_length_sd / np.sqrt(dof / (dof - 2.0))
  return abs(r.bending_length - c) <= stats.t.ppf((1 + level) / 2, dof) * scale


def test_a_rounded_edge_is_read_within_its_interval():
  """A 3 mm rounding: the strip bends from 3 mm behind the face (where the
  overhang is measured from). Read as a sharp edge (``known_radius=0``, the
  reader before issue 77) c comes out low; with the rounding fitted beside
  the strip, within its 90% interval and the radius to 0.5 mm."""
  table = tabletop.Table(edge_radius=0.003)
  strip = tabletop.Strip(overhang=0.036, bending_length=0.012, thickness=0.0005)
  depth, r = _read_on(table, strip, 0.45, 30.0, seed=5)
  assert r.edge_radius == pytest.approx(0.003, abs=0.0005)
  assert _within(r, 0.012), r
  sharp = overhang_depth.read(depth, INTR, 0.036, 0.001, known_radius=0.0)
  # 3 mm more strip bending: about 3 mm / 36 mm of c, less what the shape takes
  assert sharp.bending_length < 0.012 * 0.97 < r.bending_length


def test_a_mid_size_rounding_under_a_soft_thick_strip_is_read_to_its_radius():
  """A 1.5 mm rounding (of the order of the depth's noise and 1 mm steps at
  0.45 m) under a soft 1.2 mm thick strip: the radius is read along the
  camera's rays to 0.4 mm (the nearest-distance fit read such roundings at
  about half their size, c some 5% low), the strip's root lifted half its
  thickness (left on the top's plane, c came out about 3% low), and c within
  its 90% interval and 3%."""
  table = tabletop.Table(edge_radius=0.0015)
  strip = tabletop.Strip(overhang=0.024, bending_length=0.008, thickness=0.0012)
  _, r = _read_on(table, strip, 0.45, 25.0, seed=7)
  assert r.edge_radius == pytest.approx(0.0015, abs=0.0004)
  assert r.bending_length == pytest.approx(0.008, rel=0.03)
  assert _within(r, 0.008), r


def test_a_thin_board_far_and_high_is_read_within_its_interval():
  """A 1 cm top board from 0.55 m, 40 degrees above (the envelope's far
  corner): its face, a few pixels tall, is the longest line under the top
  (the strip's hanging part holds more points on a shorter one); read within
  its interval."""
  strip = tabletop.Strip(overhang=0.045, bending_length=0.015, thickness=0.0005)
  thin = tabletop.Table(thickness=0.01)
  _, r = _read_on(thin, strip, 0.55, 40.0, seed=6)
  assert _within(r, 0.015), r


def test_a_strip_over_a_rounded_edge_leaves_it_where_the_rounding_bends_it_no_more():
  """A stiff strip leaves a 2 mm rounding at once, flat, its length to above
  the face about the radius; a soft one (root curvature over 1/R at a flat
  start) follows a 3 mm rounding round to where its free part's root
  curvature is the centre line's 1/R (to the angle grid's 4 degrees)."""
  stiff = tabletop.Strip(overhang=0.06, bending_length=0.02)
  angle, setback = tabletop.drape(stiff, tabletop.Table(edge_radius=0.002))
  assert angle == 0.0 and setback == pytest.approx(0.002, rel=0.02)
  soft = tabletop.Strip(overhang=0.021, bending_length=0.006, thickness=0.001)
  angle, setback = tabletop.drape(soft, tabletop.Table(edge_radius=0.003))
  big = 0.0035
  assert 0.1 < angle < 1.0
  _, moment = cantilever.leaving((0.021 + setback - big * angle) / 0.006, angle)
  assert float(moment) == pytest.approx(0.006 / big, rel=0.05)
