"""Up from what the user knows (issue 40, item 1): the camera file's world
axis (``--world_up``) or its IMU's gravity before a floor, before the cloth
plane; sources that disagree by more than 3 degrees are reported.

The scene is issue 40's confident failure: the floor out of view, the cloth
blown back 35 degrees about its pins in the first frames, and a rig
calibrated in a z-up world (turned and shifted from the simulator's); its
depth is float64 ray-plane intersection (``tests.physsim.alignment_test``)."""

from __future__ import annotations

import dataclasses
import json
import types

import numpy as np
import pytest

from experiments import estimate
from experiments.pipeline import (
  intake,
  intake_alignment,
  intake_files,
  intake_record,
  objective,
  user_recordings,
)
from physsim import alignment, camera, camera_files, scene
from tests.physsim.alignment_test import _INTR, _PINS_WORLD, _pose, _scene_depth

_CONFIG = objective.PRESETS['smoke'].replace(cloth_resolution=10)
_SWING = 35.0
_ANGLE = np.deg2rad(30.0)
# The rig's world: z up, turned 30 degrees about z and shifted (metres).
_USER_FROM_SIM = np.array(
  [[np.cos(_ANGLE), -np.sin(_ANGLE), 0], [np.sin(_ANGLE), np.cos(_ANGLE), 0], [0, 0, 1]]
)
_SHIFT = np.array([2.0, -1.0, 0.3])


def _rotation_error_deg(a: camera.Pose, b: camera.Pose) -> float:
  r = np.asarray(a.rotation, np.float64).T @ np.asarray(b.rotation, np.float64)
  return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))))


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
  root = tmp_path_factory.mktemp('windy')
  pose = _pose()
  depth = _scene_depth(pose, _INTR, floor=False, wall=True, swing_deg=_SWING)
  path = root / 'windy.npz'
  np.savez(path, depth=np.repeat(depth[None], 24, axis=0).astype(np.float32))
  r_sim = np.asarray(pose.rotation, np.float64)
  cam_to_world = np.eye(4)
  cam_to_world[:3, :3] = _USER_FROM_SIM @ r_sim
  cam_to_world[:3, 3] = _USER_FROM_SIM @ np.asarray(pose.position) + _SHIFT
  cam = {
    'width': _INTR.width, 'height': _INTR.height, 'fx': _INTR.fx, 'fy': _INTR.fy,
    'cx': _INTR.cx, 'cy': _INTR.cy, 'fps': 20, 'cam_to_world': cam_to_world.tolist(),
  }  # fmt: skip
  down = r_sim.T @ [0.0, 0.0, -9.81]  # gravity in the camera frame
  return str(path), cam, down, pose, root


def _camera(root, cam, name, **extra):
  path = root / f'{name}.json'
  d = {k: v for k, v in dict(cam, **extra).items() if v is not None}
  path.write_text(json.dumps(d))
  return str(path)


def test_a_given_up_fits_a_swung_cloth_where_the_cloth_plane_cannot():
  pose = _pose()
  depth = _scene_depth(pose, _INTR, floor=False, swing_deg=_SWING)
  up = np.asarray(pose.rotation, np.float64).T @ [0, 0, 1.0]
  bg = scene.remove_background(depth[None], _INTR)
  guessed = alignment.fit_pins(bg.depth, _INTR, background=bg.planes)
  given = alignment.fit_pins(
    bg.depth, _INTR, background=bg.planes, up=up, up_from='world_up'
  )
  assert (guessed.up_from, given.up_from) == ('cloth plane', 'world_up')
  errors = {}
  for name, fit in (('guessed', guessed), ('given', given)):
    got, pins = alignment.camera_pose(fit.pins, fit.up, _PINS_WORLD)
    errors[name] = _rotation_error_deg(got, pose)
    if name == 'given':
      want = alignment.pins_in_camera(pose, _PINS_WORLD)
      np.testing.assert_array_less(np.linalg.norm(pins - want, axis=1), 0.02)
  # The guess is off by about the swing; the given up by under 2 degrees.
  assert errors['given'] < 2.0 < 20.0 < errors['guessed'], errors
  assert alignment.angle_deg(guessed.cloth_up, up) == pytest.approx(_SWING, abs=3)


def test_world_up_and_gravity_come_from_the_camera_file(recording, tmp_path):
  _, cam, down, pose, _ = recording
  up_sim = np.asarray(pose.rotation, np.float64).T @ [0, 0, 1.0]
  path = _camera(tmp_path, cam, 'cam', gravity=list(down))
  read = camera_files.read_camera(path)
  np.testing.assert_allclose(read.world_up('z'), up_sim, atol=1e-6)
  np.testing.assert_allclose(read.world_up('-z'), -up_sim, atol=1e-6)
  np.testing.assert_allclose(-read.gravity, up_sim, atol=1e-9)
  # OpenGL axes (y up, looking along -z): gravity given in them too.
  gl = camera_files.read_camera(
    _camera(
      tmp_path,
      cam,
      'gl',
      axes='opengl',
      gravity=list(down * [1, -1, -1]),
      cam_to_world=None,
    )  # fmt: skip
  )
  np.testing.assert_allclose(-gl.gravity, up_sim, atol=1e-9)
  with pytest.raises(ValueError, match='"gravity" must be a direction'):
    camera_files.read_camera(_camera(tmp_path, cam, 'zero', gravity=[0, 0, 0]))
  bare = camera_files.read_camera(_camera(tmp_path, cam, 'bare', cam_to_world=None))
  with pytest.raises(
    ValueError, match=r'--world_up=z: .*bare.json has no "cam_to_world"'
  ):
    bare.world_up('z')
  with pytest.raises(ValueError, match='--world_up=up: must be one of'):
    intake.IntakeConfig(world_up='up').check()


def test_the_intake_takes_up_from_the_rig_not_the_swung_cloth(recording):
  path, cam, down, pose, root = recording
  plain = _camera(root, cam, 'plain')

  def take(camera_json, **kw):
    config = intake.IntakeConfig(min_overlap=0.3, **kw)
    return intake.take_in(path, config, camera_json, _CONFIG.simulation)

  guessed = take(plain)
  rigged = take(plain, world_up='z')
  imu = take(_camera(root, cam, 'imu', gravity=list(down)))
  assert guessed.up_from == 'cloth plane' and not guessed.warnings
  assert rigged.up_from == 'world_up' and imu.up_from == 'gravity'
  assert _rotation_error_deg(guessed.pose, pose) > 20.0  # issue 40's failure
  for ik in (rigged, imu):
    assert _rotation_error_deg(ik.pose, pose) < 2.0
    np.testing.assert_allclose(ik.pose.position, pose.position, atol=0.05)
  assert 'up from --world_up' in intake_record.summary(rigged)
  # Both, agreeing: no warning; an IMU 10 degrees off: reported, and the
  # rig's axis (more trusted) used.
  both = take(_camera(root, cam, 'imu', gravity=list(down)), world_up='z')
  assert both.up_from == 'world_up' and not both.warnings
  tilt = np.deg2rad(10.0)
  turn = np.array(
    [[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]]
  )
  off = take(_camera(root, cam, 'off', gravity=list(turn @ down)), world_up='z')
  assert off.up_from == 'world_up' and len(off.warnings) == 1
  assert 'differ by 10.0 degrees' in off.warnings[0]
  assert (
    'warning: up from --world_up and from the camera file' in intake_record.summary(off)
  )
  assert intake_files.to_json(off)['warnings'] == list(off.warnings)


def test_the_alignment_error_follows_where_up_came_from(recording):
  path, cam, down, pose, root = recording
  plain = _camera(root, cam, 'plain')
  config = intake.IntakeConfig(min_overlap=0.3)
  guessed = intake.take_in(path, config, plain, _CONFIG.simulation)
  rigged = intake.take_in(
    path, dataclasses.replace(config, world_up='z'), plain, _CONFIG.simulation
  )
  assert guessed.up_is_guess and not rigged.up_is_guess
  assert guessed.alignment_sd[1] == intake_alignment.UP_SD_DEG['cloth plane'] == 20.0
  # a given up's degree, and the pins' small error's turn in quadrature
  assert 1.0 == intake_alignment.UP_SD_DEG['world_up'] <= rigged.alignment_sd[1] < 1.5
  # Two pixels at the pins' ~2.1 m with fx 150: about 2.8 cm.
  assert rigged.alignment_sd[0] == pytest.approx(2 * 2.1 / 150, rel=0.1)
  assert 'up is a guess' in intake_record.summary(guessed)
  assert 'up is a guess' not in intake_record.summary(rigged)
  assert intake_files.to_json(guessed)['up_is_guess'] is True
  # The estimate carries it unless the user gave a camera error or said no.
  carried, line = user_recordings.with_alignment_error(_CONFIG, [guessed, None])
  assert (
    carried.scoring.camera_sd_m,
    carried.scoring.camera_sd_deg,
  ) == guessed.alignment_sd
  assert 'alignment' in line and '20 degrees' in line
  mine = _CONFIG.replace(camera_sd_m=0.05)
  assert user_recordings.with_alignment_error(mine, [guessed]) == (mine, None)
  off = user_recordings.with_alignment_error(_CONFIG, [guessed], carry=False)
  assert off == (_CONFIG, None)  # --noalignment_sd
  record = user_recordings.alignment_record([guessed], carried)
  assert record['up_is_guess'] and record['camera_sd_deg'] == 20.0
  assert (
    record['up_from'] == ['cloth plane'] and 'up is a guess' in record['warnings'][0]
  )
  assert not user_recordings.alignment_record([rigged], _CONFIG)['up_is_guess']
  assert user_recordings.alignment_record([None], _CONFIG) is None


@pytest.fixture(scope='module')
def lifted(tmp_path_factory):
  """Issue 40's recording, simulated: 3.52 m/s on a cloth pinned at its two
  top corners, whose middle the wind lifts above them; the camera of
  ``scratch`` (2.5 m off, to the side), its first 5 frames, the floor out of
  view; frames and an OpenCV camera file in a z-up rig world."""
  import jax  # noqa: PLC0415

  import physsim  # noqa: PLC0415
  from physsim import dataset  # noqa: PLC0415

  truth = dict(bending_scale=1.0, wind_speed=3.52, area_weight=0.185)
  mesh = physsim.square(25)
  out = physsim.simulate(
    physsim.build(mesh, 'gray_interlock'), physsim.params.make(**truth), frames=24,
    fps=20.0, warmup=1.0, wind=physsim.Wind(gust_intensity=0.2),
    key=jax.random.key(11)[None], backend='c', workers=1,
    space=physsim.search_space('gray_interlock'),
  )  # fmt: skip
  intr = camera.Intrinsics.from_pinhole(320, 240, 260.0, 260.0, 158.0, 121.0)
  pose = camera.look_at((0.8, -2.3, 1.45), (0.0, 0.25, 1.05))
  render = physsim.make_depth_renderer(mesh.faces, intr)
  poses = jax.tree.map(lambda a: np.asarray(a)[None, None], pose)
  depth = np.asarray(render(np.asarray(out.positions), poses))[0, 0]
  root = tmp_path_factory.mktemp('lifted')
  folder = root / 'depth'
  folder.mkdir()
  for t, f in enumerate(dataset.depth_to_mm(depth)):
    dataset.imwrite(str(folder / f'{t:04d}.png'), f)
  m = np.eye(4)
  m[:3, :3] = _USER_FROM_SIM @ np.asarray(pose.rotation, np.float64)
  m[:3, 3] = _USER_FROM_SIM @ np.asarray(pose.position) + _SHIFT
  cam = root / 'camera.json'
  cam.write_text(json.dumps({
    'width': 320, 'height': 240, 'fx': 260.0, 'fy': 260.0, 'cx': 158.0, 'cy': 121.0,
    'fps': 20, 'cam_to_world': m.tolist(),
  }))  # fmt: skip
  return str(folder), str(cam), depth, intr, pose


def test_pins_of_a_cloth_lifted_above_them(lifted):
  _, _, depth, intr, pose = lifted
  up = np.asarray(pose.rotation, np.float64).T @ [0, 0, 1.0]
  want = alignment.pins_in_camera(pose, _PINS_WORLD)
  points = alignment._cloth_points(depth, intr, 5)
  assert (points @ up).max() > (want @ up).max() + 0.03  # lifted above its pins
  band = alignment.fit_pins(depth, intr, up=up)  # the highest band's ends only
  fit = alignment.fit_pins(depth, intr, up=up, spacing=1.0)
  err = lambda p: np.linalg.norm(np.sort(p, axis=0) - np.sort(want, axis=0), axis=1)
  assert err(band.pins).max() > 0.08 and err(fit.pins).max() < 0.03


def test_a_guessed_up_is_refused_with_the_flags_that_fix_it(lifted, tmp_path):
  frames, cam, _, _, pose = lifted
  args = estimate.Args(
    recording=(frames,), camera_json=cam, workdir=str(tmp_path / 'w'),
    search=_CONFIG.replace(distance='shape', likelihood='gibbs'),
  )  # fmt: skip
  with pytest.raises(
    ValueError, match=r'depth: up is a guess .*--world_up=AXIS.*--allow_guessed_up'
  ):
    estimate.main(args)
  ik = intake.take_in(
    frames, intake.IntakeConfig(world_up='z'), cam, _CONFIG.simulation
  )
  assert ik.up_from == 'world_up' and _rotation_error_deg(ik.pose, pose) < 2.0
  np.testing.assert_allclose(ik.pose.position, pose.position, atol=0.05)
  guessed = intake.take_in(frames, intake.IntakeConfig(), cam, _CONFIG.simulation)
  assert guessed.up_is_guess
  # Issue 40's failure, now refused: the camera placed over a metre too high.
  assert np.asarray(guessed.pose.position)[2] - pose.position[2] > 1.0


def test_the_claim_is_the_pins_shortfall_and_noise_not_their_flutter():
  """By hand: pins 0.94 m apart where the cloth's are 1 m (3 cm short each
  side), 2 cm of noise left in the chosen fit: a 3.6 cm shift in no known
  direction, 2.08 cm per axis; it turns the 1 m line by 1.19 degrees, in
  quadrature with a given up's 1 degree."""
  fit = types.SimpleNamespace(
    up_from='world_up', floor_up=None, up=np.array([0, -1.0, 0])
  )
  pins = np.array([[-0.47, 0.0, 2.4], [0.47, 0.0, 2.4]])
  intr = types.SimpleNamespace(fx=520.0)
  m, deg = intake_alignment.alignment_error(fit, pins, 1.0, intr, (), 0.02)
  per_axis = np.hypot(0.03, 0.02) / np.sqrt(3)
  assert m == pytest.approx(per_axis, abs=1e-4)  # rounded to 0.1 mm
  assert deg == pytest.approx(np.hypot(1.0, np.degrees(np.arctan(per_axis))), abs=0.01)
  # pins at the cloth's spacing and still: two pixels at their depth, or 1 cm
  exact = np.array([[-0.5, 0.0, 2.4], [0.5, 0.0, 2.4]])
  m0, deg0 = intake_alignment.alignment_error(fit, exact, 1.0, intr, (), 0.0)
  assert m0 == intake_alignment.MIN_SD_M and deg0 == 1.0
  far = intake_alignment.alignment_error(fit, exact * [1, 1, 3], 1.0, intr, (), 0.0)
  assert far[0] == pytest.approx(2 * 7.2 / 520, abs=1e-4)
  # a guessed up stays at its 20 degrees, the most the estimate allows
  fit.up_from = 'cloth plane'
  assert intake_alignment.alignment_error(fit, pins, 1.0, intr, (), 0.02)[1] == 20.0
