"""Tests for physsim.scene and physsim.alignment: background planes, the cloth's
pins and the camera's pose in the simulator's world, against scenes whose depth
is computed here by float64 ray-plane intersection (not the ray-caster)."""

import numpy as np
import pytest

from physsim import alignment, camera, scene

_PIN_TOL = 0.02  # metres: pixel centres sit up to ~1 px (9 mm here) inside the outline
_ANGLE_TOL = np.deg2rad(2.0)
_INTR = camera.Intrinsics.from_pinhole(160, 120, 150.0, 150.0, 88.0, 52.0)
_PINS_WORLD = np.array([[-0.5, 0.0, 1.5], [0.5, 0.0, 1.5]])


def _scene_depth(pose, intr, *, floor=True, wall=True, swing_deg=0.0):
  """(H, W) z-depth of a 1 m cloth hanging from the pins (swung about them),
  a floor z = 0 and a wall y = 1.2, in float64."""
  r = np.asarray(pose.rotation, np.float64)
  c = np.asarray(pose.position, np.float64)
  v, u = np.mgrid[0 : intr.height, 0 : intr.width].astype(np.float64)
  rays_cam = np.stack(
    [(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1
  )
  rays = rays_cam @ r.T  # world directions, unit camera z: t is the z-depth
  best = np.full(u.shape, np.inf)

  def hit(normal, point, inside=None):
    nonlocal best
    with np.errstate(all='ignore'):
      t = ((point - c) @ normal) / (rays @ normal)
    ok = t > 0
    if inside is not None:
      ok &= inside(c + t[..., None] * rays)
    best = np.where(ok & (t < best), t, best)

  a = np.deg2rad(swing_deg)
  down = np.array([0.0, np.sin(a), -np.cos(a)])  # from the top edge along the cloth
  normal = np.cross([1.0, 0, 0], down)

  def in_cloth(x):
    rel = x - _PINS_WORLD.mean(axis=0)
    return (np.abs(rel[..., 0]) <= 0.5) & (rel @ down >= 0) & (rel @ down <= 1.0)

  hit(normal, _PINS_WORLD[0], in_cloth)
  if floor:
    hit(np.array([0, 0, 1.0]), np.zeros(3))
  if wall:
    hit(np.array([0, 1.0, 0]), np.array([0, 1.2, 0]))
  return np.where(np.isfinite(best), best, 0.0)


def _pose():
  return camera.look_at([0.45, -2.0, 1.2], [0.0, 0.1, 1.0], roll_deg=3.0)


def test_fit_plane_recovers_a_noisy_plane_among_outliers():
  rng = np.random.default_rng(0)
  n = np.array([0.2, -0.3, 0.93])
  n /= np.linalg.norm(n)
  basis = scene.plane_basis(n)
  pts = (
    rng.uniform(-1, 1, (700, 2)) @ basis + 2.0 * n + rng.normal(0, 0.003, (700, 1)) * n
  )
  outliers = rng.uniform(-1, 3, (300, 3))
  plane, inliers = scene.fit_plane(np.concatenate([pts, outliers]), 0.01)
  assert abs(plane.normal @ n) > np.cos(np.deg2rad(0.5))
  assert inliers[:700].mean() > 0.99 and inliers[700:].mean() < 0.1


def test_background_removal_keeps_exactly_the_cloth():
  pose = _pose()
  full = _scene_depth(pose, _INTR)
  cloth_only = _scene_depth(pose, _INTR, floor=False, wall=False)
  # The true cloth pixels: where the cloth is the nearest surface.
  truth = (cloth_only > 0) & (np.abs(cloth_only - full) < 1e-9)
  bg = scene.remove_background(np.stack([full, full]), _INTR)
  assert len(bg.planes) == 2
  assert alignment.iou(bg.cloth[0], truth) > 0.99
  assert bg.fraction[0] == pytest.approx(truth.mean(), rel=0.02)
  # A depth range that cuts the cloth's far half away is honoured.
  near = scene.remove_background(
    full[None], _INTR, depth_range=(0.5, 2.05), planes=False
  )
  assert near.cloth[0].sum() < truth.sum() and not (near.depth[0] > 2.05).any()


@pytest.mark.parametrize(
  'floor, swing, up_from',
  [(True, 0.0, 'floor'), (False, 0.0, 'cloth plane'), (True, 35.0, 'floor')],
)
def test_fitted_pins_and_pose(floor, swing, up_from):
  pose = _pose()
  depth = _scene_depth(pose, _INTR, floor=floor, swing_deg=swing)
  bg = scene.remove_background(depth[None], _INTR)
  fit = alignment.fit_pins(bg.depth, _INTR, background=bg.planes)
  assert fit.up_from == up_from
  got, pins = alignment.camera_pose(fit.pins, fit.up, _PINS_WORLD)
  want = alignment.pins_in_camera(pose, _PINS_WORLD)
  np.testing.assert_array_less(np.linalg.norm(pins - want, axis=1), _PIN_TOL)
  r_err = np.asarray(got.rotation, np.float64).T @ np.asarray(pose.rotation, np.float64)
  angle = np.arccos(np.clip((np.trace(r_err) - 1) / 2, -1, 1))
  assert angle < _ANGLE_TOL, np.rad2deg(angle)
  np.testing.assert_allclose(got.position, pose.position, atol=3 * _PIN_TOL)


def test_camera_pose_from_exact_pins_is_exact_whatever_their_order():
  pose = _pose()
  pins = alignment.pins_in_camera(pose, _PINS_WORLD)
  up = np.asarray(pose.rotation, np.float64).T @ [0, 0, 1.0]
  for order in (pins, pins[::-1]):
    got, ordered = alignment.camera_pose(order, up, _PINS_WORLD)
    np.testing.assert_allclose(got.rotation, pose.rotation, atol=1e-5)
    np.testing.assert_allclose(got.position, pose.position, atol=1e-5)
    np.testing.assert_allclose(ordered, pins, atol=1e-9)
  # The wind toward the camera: the same pins, the world turned about z.
  flipped, _ = alignment.camera_pose(pins, up, _PINS_WORLD, wind_toward_camera=True)
  assert np.asarray(flipped.position)[1] > 0
  assert alignment.visible_share(_PINS_WORLD, pose, _INTR) == 1.0
  far = camera.Pose(pose.rotation, np.asarray(pose.position) - [0, 100.0, 0])
  assert alignment.visible_share(_PINS_WORLD, far, _INTR) == 1.0  # still in front


def test_track_pins_takes_each_pin_from_its_most_upwind_stretch(monkeypatch):
  """The camera looks along +z at pins 2.5 m away, level (up = -y): downwind
  (away from the camera) is +z. Scripted stretch fits move the left pin back
  (a corner fitted behind its pin) while the right one holds: the track keeps
  the left pin's nearest fit and the right's, and its scatter is the left
  pin's RMS spread by hand; with the wind toward the camera, the farthest."""
  first = np.array([[-0.5, 0.0, 2.70], [0.5, 0.0, 2.5]])
  fits = [
    np.array([[-0.49, 0.0, 2.58], [0.5, 0.0, 2.5]]),
    np.array([[0.5, 0.0, 2.5], [-0.51, 0.0, 2.64]]),  # either order
    np.array([[-0.5, 0.0, 2.76], [0.5, 0.0, 2.5]]),
  ]
  calls = iter(fits)
  monkeypatch.setattr(
    alignment,
    'fit_pins',
    lambda *a, **k: alignment.ClothFit(next(calls), None, None, ''),
  )
  depth = np.zeros((15, 4, 4))
  up = np.array([0.0, -1.0, 0.0])
  track = alignment.track_pins(depth, None, first, up, windows=3, frames=5)
  np.testing.assert_allclose(track.pins, [[-0.49, 0.0, 2.58], [0.5, 0.0, 2.5]])
  left = np.array([first[0], fits[0][0], fits[1][1], fits[2][0]])
  rms = np.sqrt(((left - left.mean(0)) ** 2).sum(1).mean())
  assert track.scatter == pytest.approx(rms, rel=1e-12) and len(track.candidates) == 4
  calls = iter(fits)
  toward = alignment.track_pins(
    depth, None, first, up, windows=3, frames=5, wind_toward_camera=True
  )
  np.testing.assert_allclose(toward.pins[0], [-0.5, 0.0, 2.76])


def test_a_stretch_that_fitted_another_corner_is_left_out(monkeypatch):
  """One stretch's fit lands 0.74 m from the left pin (a sliver of cloth seen
  edge-on, as on a windy rig recording): it is neither chosen, though it is
  the most upwind, nor counted in the scatter, which is the others' RMS
  spread by hand; with most stretches in disagreement, all are kept."""
  first = np.array([[-0.5, 0.0, 2.60], [0.5, 0.0, 2.5]])
  good = [
    np.array([[-0.5, 0.0, 2.56], [0.5, 0.0, 2.52]]),
    np.array([[-0.5, 0.0, 2.62], [0.5, 0.0, 2.49]]),
  ]
  misfit = np.array([[-0.2, 0.0, 1.92], [0.5, 0.0, 2.5]])  # upwind of all
  depth = np.zeros((20, 4, 4))
  up = np.array([0.0, -1.0, 0.0])

  def track(fits):
    calls = iter(fits)
    monkeypatch.setattr(
      alignment, 'fit_pins',
      lambda *a, **k: alignment.ClothFit(next(calls), None, None, ''),
    )  # fmt: skip
    return alignment.track_pins(depth, None, first, up, windows=len(fits), frames=5)

  t = track([good[0], misfit, good[1]])
  assert t.kept.tolist() == [True, True, False, True]
  np.testing.assert_allclose(t.pins, [[-0.5, 0.0, 2.56], [0.5, 0.0, 2.49]])
  kept = np.array([first, good[0], good[1]])
  rms = np.sqrt(((kept - kept.mean(0)) ** 2).sum(2).mean(0)).max()
  assert t.scatter == pytest.approx(rms, rel=1e-12) and t.scatter < 0.04
  # Every fit with all its spread again if at most one would be kept.
  far = [misfit + [0.0, 0.0, 0.5 * i] for i in range(3)]
  spread = track(far)
  assert spread.kept.all() and spread.scatter > 0.3
