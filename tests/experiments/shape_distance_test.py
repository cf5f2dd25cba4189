"""Tests of the estimate's shape discrepancy (``--distance=shape``,
``'energy+shape'``): the sheet's mean place in the world, compared inside the
fused objective.

References: the candidate's own frames (returned by the objective) summarised
by the float64 NumPy reference of tests/physsim/shape_test.py, and the energy
PSD from its own program.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re

import jax
import numpy as np
import pytest

import physsim
from experiments import estimate as estimate_cli
from experiments.pipeline import (
  advice,
  calibration_tables,
  embedding,
  estimation,
  evaluation,
  layout,
)
from experiments.pipeline import objective as obj_lib
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  load,
  write_hand_made_model,
  write_recording,
)
from tests.physsim.shape_test import reference_summary

pytestmark = pytest.mark.slow  # whole searches with the shape distance

# float32 summaries of points ~2 m away, squared: m^2.
_SHAPE_ATOL = 1e-8
# The truth's discrepancy: the recording went through 16-bit mm PNGs.
_TRUTH_SHAPE_MAX = 1e-6  # m^2, a 1 mm centroid difference
_MEAN_RTOL = 1e-4
_RESIDUAL_ATOL_M = 1e-5  # float32 centroids of points ~2 m away
_CAMERA_SD_M, _CAMERA_SD_DEG = 0.05, 3.0


@pytest.fixture(scope='module')
def env(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('shape'))
  seq = write_recording(root, TRUTH)
  model_dir = write_hand_made_model(f'{root}/model')
  net = embedding.load_embedding(model_dir)
  return dict(rec=load(seq), net=net, model_dir=model_dir)


def _scores(env, distance: str, u, frames: bool = False):
  config = CONFIG.replace(distance=distance)
  problem = obj_lib.make_problem(config, env['net'], env['rec'])
  gust, noise = obj_lib.candidate_keys(config.seed, config.search, 0, len(u))
  out = obj_lib.Objective(problem)(
    obj_lib.stack([problem.data]), np.asarray(u)[None], gust[None], noise[None],
    frames=frames,
  )  # fmt: skip
  assert out.valid.all()
  return out, problem


def test_shape_distance_is_the_summaries_squared_distance(env):
  space = physsim.search_space(CONFIG.simulation.material)
  truth_u = np.asarray(physsim.to_unit(physsim.params.make(**TRUTH), space))
  truth_u = truth_u.reshape(1, 3)
  far = np.array([[0.0, -0.8, 0.5]])
  at_truth, problem = _scores(env, 'shape', truth_u)
  assert at_truth.psd[0, 0] < _TRUTH_SHAPE_MAX
  out, _ = _scores(env, 'shape', far, frames=True)
  pose = env['rec'].pose
  intr = problem.intr
  want = np.sum(
    (reference_summary(out.frames[0], intr, pose)
     - reference_summary(env['rec'].depth, intr, pose)) ** 2
  )  # fmt: skip
  assert want > 100 * _TRUTH_SHAPE_MAX  # a weaker wind sits elsewhere
  np.testing.assert_allclose(out.psd[0, 0], want, rtol=1e-3, atol=_SHAPE_ATOL)
  # The residual the 'synthetic' likelihood is told: the same summaries' difference.
  resid = reference_summary(out.frames[0], intr, pose) - reference_summary(
    env['rec'].depth, intr, pose
  )
  np.testing.assert_allclose(out.residual[0, 0], resid, atol=_RESIDUAL_ATOL_M)
  assert not np.any(_scores(env, 'energy', far)[0].residual)  # no shape: zeros


def test_energy_plus_shape_is_the_geometric_mean(env):
  u = np.array([[0.0, 0.0, 0.0], [0.5, -0.6, 0.7], [-0.8, 0.3, -0.4]])
  energy = _scores(env, 'energy', u)[0].psd[0]
  shape = _scores(env, 'shape', u)[0].psd[0]
  both = _scores(env, 'energy+shape', u)[0].psd[0]
  assert np.all(energy > 0) and np.all(shape > 0)
  np.testing.assert_allclose(both, np.sqrt(energy * shape), rtol=_MEAN_RTOL)


def test_shape_needs_the_recordings_camera_pose(env):
  rec = env['rec']._replace(pose=None)
  config = CONFIG.replace(distance='energy+shape')
  with pytest.raises(ValueError, match='seq: distance .energy.shape. .*camera pose'):
    obj_lib.make_problem(config, env['net'], rec)
  obj_lib.make_problem(CONFIG, env['net'], rec)  # the PSD alone needs none


def test_a_misplaced_camera_renders_from_its_error(env):
  # Candidates at the truth with the recording's own gusts, each rendered from
  # the recording's camera moved by its own error (the candidate's camera
  # key) and lifted with the given pose: the discrepancy must be that of the
  # frames rendered here from the same moved cameras, summarised by the
  # float64 reference. The errors must matter: several cm, not mm.
  config = CONFIG.replace(
    distance='shape', camera_sd_m=_CAMERA_SD_M, camera_sd_deg=_CAMERA_SD_DEG
  )
  problem = obj_lib.make_problem(config, env['net'], env['rec'])
  space = physsim.search_space(CONFIG.simulation.material)
  u = np.repeat(np.asarray(physsim.to_unit(physsim.params.make(**TRUTH), space)), 4, 0)
  # common: the recording's gusts
  gust, _ = obj_lib.candidate_keys(CONFIG.seed, CONFIG.search, 0, 4)
  noise = jax.random.split(jax.random.key(11), 4)
  out = obj_lib.Objective(problem)(
    obj_lib.stack([problem.data]), u.reshape(1, 4, 3), gust[None], noise[None],
    positions=True,
  )  # fmt: skip
  mesh = physsim.square(CONFIG.simulation.cloth_resolution)
  pins = mesh.vertices[mesh.pinned].mean(0)
  rec_summary = reference_summary(env['rec'].depth, problem.intr, env['rec'].pose)
  want = []
  for k, pos in zip(noise, out.positions[0], strict=True):
    moved = physsim.shape.misplaced_poses(
      obj_lib.camera_key(k), problem.data.poses, _CAMERA_SD_M, _CAMERA_SD_DEG, pins
    )
    frames = physsim.render_depth(
      pos[None], mesh.faces, problem.intr, jax.tree.map(lambda a: a[None], moved)
    )[0, 0]
    got = reference_summary(np.asarray(frames), problem.intr, env['rec'].pose)
    want.append(np.sum((got - rec_summary) ** 2))
  assert min(want) > 10 * _TRUTH_SHAPE_MAX
  np.testing.assert_allclose(out.psd[0], want, rtol=1e-3, atol=_SHAPE_ATOL)


def test_recordings_carrying_other_camera_errors_are_scored_in_one_call(env):
  # A camera error's size is each problem's data, not the program's
  # structure (a calibration study draws each recording its own): two
  # problems carrying different errors share one compiled objective, and
  # scored together each gets what it gets alone, with its own error.
  u = np.repeat(np.zeros((1, 3), np.float32), 3, 0)
  gust, _ = obj_lib.candidate_keys(CONFIG.seed, CONFIG.search, 0, 3)
  noise = jax.random.split(jax.random.key(5), 3)
  problems = [
    obj_lib.make_problem(
      CONFIG.replace(distance='shape', camera_sd_m=m, camera_sd_deg=d),
      env['net'],
      env['rec'],
    )
    for m, d in ((_CAMERA_SD_M, _CAMERA_SD_DEG), (0.01, 0.5))
  ]
  exact = obj_lib.make_problem(CONFIG.replace(distance='shape'), env['net'], env['rec'])
  assert problems[0].structure() == problems[1].structure() != exact.structure()
  run = obj_lib.Objective(problems[0])
  both = run(
    obj_lib.stack([p.data for p in problems]),
    np.stack([u, u]),
    jax.numpy.stack([gust, gust]),
    jax.numpy.stack([noise, noise]),
  ).psd
  for k, p in enumerate(problems):
    alone = run(obj_lib.stack([p.data]), u[None], gust[None], noise[None]).psd[0]
    np.testing.assert_allclose(both[k], alone, rtol=1e-5, atol=1e-9)
  assert not np.allclose(both[0], both[1], rtol=1e-2)  # each its own error


def test_the_shape_needs_no_network(env):
  # The same candidates and keys scored with the hand-made network and with
  # none: the shape never embeds, so discrepancies and residuals are equal.
  u = np.array([[0.0, 0.0, 0.0], [0.5, -0.6, 0.7]])
  config = CONFIG.replace(distance='shape')
  gust, noise = obj_lib.candidate_keys(config.seed, config.search, 0, len(u))
  none = embedding.no_network(env['rec'].depth.shape[1:])
  assert none.network is None and none.image_size == env['net'].image_size
  got = []
  for net in (env['net'], none):
    problem = obj_lib.make_problem(config, net, env['rec'])
    got.append(
      obj_lib.Objective(problem)(
        obj_lib.stack([problem.data]), u[None], gust[None], noise[None]
      )
    )
  assert np.all(got[0].psd > 0)
  np.testing.assert_array_equal(got[1].psd, got[0].psd)
  np.testing.assert_array_equal(got[1].residual, got[0].residual)
  for distance in ('energy', 'energy+shape', 'centroid'):
    with pytest.raises(
      ValueError, match=f"seq: distance '{re.escape(distance)}' embeds"
    ):
      obj_lib.make_problem(CONFIG.replace(distance=distance), none, env['rec'])
  with pytest.raises(ValueError, match=r'image size \(0, 32\)'):
    embedding.no_network((0, 32))
  # Nothing about a network is claimed: no recipe, accuracy or retrieval.
  assert embedding.network_recipe('') is None
  assert embedding.network_accuracy('') is None
  assert embedding.network_retrieval('') is None


def test_the_command_line_asks_for_a_network_only_where_one_is_used(env):
  shape = estimate_cli.Args(search=CONFIG.replace(distance='shape'), image_size=48)
  assert estimate_cli.network(shape).embedding.image_size == (48, 48)
  with pytest.raises(
    ValueError, match='missing --model: --distance=energy embeds frames'
  ):
    estimate_cli.network(estimate_cli.Args(search=CONFIG))
  with pytest.raises(ValueError, match='--image_size=8: need 16-1024'):
    estimate_cli.network(dataclasses.replace(shape, image_size=8))
  given = dataclasses.replace(shape, model=env['model_dir'])  # a network still loads
  assert estimate_cli.network(given).embedding.network is not None


def test_the_synthetic_likelihood_needs_the_shape_distance():
  with pytest.raises(ValueError, match="synthetic.*distance 'shape', got 'energy'"):
    CONFIG.replace(likelihood='synthetic').check()
  CONFIG.replace(likelihood='synthetic', distance='shape').check()


def test_an_estimate_with_the_synthetic_likelihood(env, tmp_path):
  # The whole estimate, told the shape summaries' residuals: the saved search
  # holds one residual pair per simulation (the objective's), its posterior
  # narrows the wind around the truth, and the result names the scatter.
  config = obj_lib.PRESETS['smoke'].replace(
    backend='c', distance='shape', likelihood='synthetic', sharpness=1.0,
  )  # fmt: skip
  sim = CONFIG.simulation
  config = config.replace(
    cloth_resolution=sim.cloth_resolution, frames=sim.frames, warmup=sim.warmup
  )
  workdir = str(tmp_path / 'est')
  # No network ('': the shape needs none); rescored below with the hand-made one.
  out = estimation.estimate(config, env['rec'], '', workdir, progress=False)
  assert json.load(open(os.path.join(workdir, layout.RUN_FILE)))['model_dir'] == ''
  z = np.load(os.path.join(workdir, layout.POSTERIOR_STATE))
  n = config.search.n_init + config.search.q * config.search.max_iter
  assert z['Y'].shape == (n, 2) and np.isfinite(z['Y']).all()
  problem = obj_lib.make_problem(config, env['net'], env['rec'])
  again = evaluation.score(problem, z['X'][:1])  # the first simulation, rescored
  np.testing.assert_allclose(again.residual[0], z['Y'][0], atol=_RESIDUAL_ATOL_M)
  wind = out['estimate']['wind_speed']
  assert wind['narrowing_90'] > 1.5, wind
  assert wind['interval_90'][0] <= TRUTH['wind_speed'] <= wind['interval_90'][1]
  saved = json.load(open(os.path.join(workdir, layout.ESTIMATE_FILE)))
  assert len(saved['noise_sd_shape_m']) == 2 and saved['noise_sd_log_psd'] is None
  assert 0 < min(saved['noise_sd_shape_m']) < 0.05  # metres of centroid scatter
  assert advice.synthetic_warning(config.scoring).startswith(
    'warning: --likelihood=synthetic'
  )
  assert advice.synthetic_warning(CONFIG.scoring) is None
  _requotes_after_new_tables(config, env, workdir, out, z)


def _requotes_after_new_tables(config, env, workdir, out, z):
  # Rerun on the finished workdir after its tables changed (here: another file
  # given, as after an install): the result is read again with the new note
  # from the search it kept (nothing searched again); unchanged, it stands.
  theirs = calibration_tables.calibration_file(config)
  cal = json.load(open(theirs))
  cal['setting'] += ' (refit)'
  refit = os.path.join(os.path.dirname(workdir), 'refit.json')
  with open(refit, 'w') as f:
    json.dump(cal, f)
  requoted = estimation.estimate(
    config.replace(calibration=refit), env['rec'], '', workdir, progress=False
  )
  assert requoted['calibration']['setting'].endswith(' (refit)')
  saved = json.load(open(os.path.join(workdir, layout.ESTIMATE_FILE)))
  assert saved['calibration'] == requoted['calibration']
  after = np.load(os.path.join(workdir, layout.POSTERIOR_STATE))
  np.testing.assert_array_equal(after['X'], z['X'])
  assert requoted['evaluations'] == out['evaluations']
  stood = os.path.getmtime(os.path.join(workdir, layout.ESTIMATE_FILE))
  again = estimation.estimate(
    config.replace(calibration=refit), env['rec'], '', workdir, progress=False
  )
  assert again == saved
  assert os.path.getmtime(os.path.join(workdir, layout.ESTIMATE_FILE)) == stood


def test_camera_error_out_of_range_is_refused():
  for bad in (dict(camera_sd_m=0.5), dict(camera_sd_deg=-1.0)):
    with pytest.raises(ValueError, match='camera_sd_m <= 0.2 .metres.'):
      CONFIG.replace(**bad).check()


def test_estimate_warns_when_a_shape_distance_trusts_an_aligned_camera():
  base = obj_lib.PRESETS['smoke'].replace(distance='energy')
  shape = base.replace(distance='shape')
  warn = advice.shape_camera_warning
  assert 'camera_sd_m=0.02' in warn(shape.scoring, aligned=True)
  assert 'energy+shape' in warn(shape.replace(distance='energy+shape').scoring, True)
  # a simulated recording's exact camera
  assert warn(shape.scoring, aligned=False) is None
  # the PSD does not read the world's frame
  assert warn(base.scoring, aligned=True) is None
  assert warn(shape.replace(camera_sd_m=0.02).scoring, aligned=True) is None
  assert warn(shape.replace(camera_sd_deg=3.0).scoring, aligned=True) is None
