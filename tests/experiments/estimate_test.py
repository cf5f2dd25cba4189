"""Tests of the estimate pipeline: the fused objective, the search, resume, bad input.

The model and recording come from ``estimate_fixtures`` (a hand-made
embedding, not a trained network; see there why).
"""

from __future__ import annotations

import json
import os
import shutil
import threading

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import model as model_lib
import physsim
from experiments.pipeline import (
  embedding,
  estimation,
  evaluation,
  layout,
  report,
  results,
  resume,
  search,
  search_figures,
  summaries,
  table_notes,
)
from experiments.pipeline import objective as obj_lib
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  load,
  write_hand_made_model,
  write_recording,
)

pytestmark = pytest.mark.slow  # whole searches on the estimate fixtures

# The truth's PSD is zero but for the mm quantisation of the recording.
_TRUTH_PSD_TOLERANCE = 1e-3
# The same candidate scores the same in every call (common random numbers,
# deterministic C backend and renderer).
_REPEAT_TOLERANCE = 1e-6
# The fused program against the same stages run one by one on the host:
# float32 parameters in the fused path, float64 in the reference.
_FUSED_TOLERANCE = 1e-4

# ----------------------------------------------------------------- fixtures


# One evaluator for the whole file: each fused program compiles once (per
# structure and shape), as it would for a user's many estimates in one process.
EVALUATOR = evaluation.Evaluator()


def _estimate(config, rec, model, workdir, **kw):
  return estimation.estimate(
    config, rec, model, workdir, progress=False, evaluator=EVALUATOR, **kw
  )


@pytest.fixture(scope='module')
def env(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('estimate'))
  model_dir = write_hand_made_model(os.path.join(root, 'model'))
  seq = write_recording(root, TRUTH)
  net = embedding.load_embedding(model_dir)
  rec = load(seq)
  problem = obj_lib.make_problem(CONFIG, net, rec)
  return dict(
    root=root, model=model_dir, seq=seq, rec=rec, net=net, problem=problem,
    objective=EVALUATOR.objective(problem),
  )  # fmt: skip


def _score(env, u, config=CONFIG, problem=None, objective=None, **kw):
  """PSD of unit points ``u (q, 3)`` of one problem through the fused program."""
  problem = problem or env['problem']
  objective = objective or env['objective']
  gust, noise = obj_lib.candidate_keys(config.seed, config.search, 0, len(u))
  return objective(
    obj_lib.stack([problem.data]), np.asarray(u)[None], gust[None], noise[None], **kw
  )


def test_a_design_larger_than_q_is_scored_in_calls_of_q(env, monkeypatch):
  # Ten candidates of a search with q = 4: three calls of one program shape
  # (the last padded), each candidate with its own keys (a posterior search's
  # fresh gusts), so the scores, positions and best frames are those of one
  # call of all ten (the reference: the same problem told q = 10).
  config = CONFIG.replace(point='median', sensor_noise=True)
  u = np.random.default_rng(0).uniform(-1, 1, (10, 3))
  whole = evaluation.score(
    obj_lib.make_problem(config.replace(q=10), env['net'], env['rec']), u,
    first=3, frames=True, positions=True,
  )  # fmt: skip
  counting = _CountCalls(monkeypatch)
  chunked = evaluation.score(
    obj_lib.make_problem(config, env['net'], env['rec']), u,
    first=3, frames=True, positions=True,
  )  # fmt: skip
  assert counting.calls == 3
  assert chunked.psd.shape == (10,) and np.isfinite(chunked.psd).all()
  assert len(np.unique(chunked.psd)) == 10  # fresh keys: no two alike
  np.testing.assert_allclose(chunked.psd, whole.psd, rtol=1e-5)
  np.testing.assert_allclose(chunked.positions, whole.positions, rtol=1e-5, atol=1e-6)
  np.testing.assert_allclose(chunked.frames, whole.frames, rtol=1e-5, atol=1e-6)


def _state(workdir: str) -> dict:
  with np.load(os.path.join(workdir, 'bo_state.npz')) as z:
    return {k: z[k] for k in z.files}


class _Interrupted(Exception):
  pass


_REAL_CALL = obj_lib.Objective.__call__  # whatever is patched later


class _CountCalls:
  """Patches ``Objective.__call__`` to count calls, failing after ``fail_after``."""

  def __init__(self, monkeypatch, fail_after: int | None = None):
    self.calls = 0
    real = _REAL_CALL

    def call(obj, *a, **kw):
      if fail_after is not None and self.calls >= fail_after:
        raise _Interrupted(f'after {self.calls} calls')
      self.calls += 1
      return real(obj, *a, **kw)

    monkeypatch.setattr(obj_lib.Objective, '__call__', call)


@pytest.fixture(scope='module')
def recovery(env):
  workdir = os.path.join(env['root'], 'full')
  result = _estimate(CONFIG, env['rec'], env['model'], workdir)
  return result, _state(workdir)


def _u_truth():
  space = physsim.search_space(CONFIG.simulation.material)
  return physsim.to_unit(physsim.params.make(**TRUTH), space)


# ------------------------------------------------------------ the objective


def test_fused_objective_equals_its_stages_run_one_by_one(env):
  # Reference: the documented stages, each on the host or in its own call,
  # with float64 parameters: simulate (MuJoCo C), rest mesh for blown-up
  # worlds, render, embed, energy distance.
  u = np.stack([_u_truth(), np.zeros(3), np.array([0.5, -0.7, 0.9])])
  fused = _score(env, u)
  sim = CONFIG.simulation
  space = physsim.search_space(sim.material)
  model = obj_lib.cloth(sim)
  out = physsim.simulate(
    model, physsim.from_unit(u, space), frames=sim.frames, fps=sim.fps,
    warmup=sim.warmup, wind=physsim.Wind(gust_intensity=sim.gusts),
    key=jnp.stack([jax.random.fold_in(jax.random.key(CONFIG.seed), 2)] * len(u)),
    backend='c', workers=1, material=CONFIG.simulation.material,
  )  # fmt: skip
  poses = jax.tree.map(
    lambda a: jnp.repeat(a[None], len(u), 0), env['problem'].data.poses
  )
  depth = physsim.render_depth(
    out.positions, model.mesh.faces, env['problem'].intr, poses
  )
  net = env['net']
  x = embedding.network_inputs(depth[:, 0], net.modality, net.input_mode)
  pts = embedding.embed_video(net.network, net.params, x)
  rec = env['problem'].data.rec_points
  ref = np.array([float(model_lib.psd.psd(p, rec)) for p in pts])
  np.testing.assert_allclose(fused.psd[0], ref, rtol=_FUSED_TOLERANCE, atol=1e-6)
  assert fused.psd[0, 0] < _TRUTH_PSD_TOLERANCE  # the truth scores ~0
  assert fused.valid.all()


def test_one_compile_per_shape_and_repeats_score_alike(env):
  u = np.stack([_u_truth(), np.zeros(3)])
  first = _score(env, u)
  size = env['objective']._program._cache_size()
  again = _score(env, u[::-1])  # new values, same shape: no recompile
  assert env['objective']._program._cache_size() == size
  np.testing.assert_allclose(again.psd[0], first.psd[0, ::-1], rtol=_REPEAT_TOLERANCE)


def test_worlds_simulating_alike_run_once_and_score_as_alone(env):
  # Two recordings of one fabric given the same candidates and keys (as a
  # calibration's searches share their design): one simulation per candidate,
  # each scored against its own recording as it would be alone.
  rec2 = env['rec']._replace(depth=env['rec'].depth * np.float32(1.03))
  other = obj_lib.make_problem(CONFIG, env['net'], rec2)
  u = np.stack([_u_truth(), np.zeros(3), np.array([0.5, -0.7, 0.9])])
  gust, noise = obj_lib.candidate_keys(CONFIG.seed, CONFIG.search, 0, len(u))
  objective = env['objective']
  alone = [
    objective(obj_lib.stack([p.data]), u[None], gust[None], noise[None], positions=True)
    for p in (env['problem'], other)
  ]
  before = objective.simulated
  both = objective(
    obj_lib.stack([env['problem'].data, other.data]), np.stack([u, u]),
    jax.numpy.stack([gust, gust]), jax.numpy.stack([noise, noise]), positions=True,
  )  # fmt: skip
  assert objective.simulated - before == len(u)  # not 2 x 3
  for i in range(2):
    np.testing.assert_allclose(both.psd[i], alone[i].psd[0], rtol=_REPEAT_TOLERANCE)
    np.testing.assert_array_equal(both.positions[i], alone[i].positions[0])
  assert np.all(np.abs(both.psd[1] - both.psd[0]) > 10 * _REPEAT_TOLERANCE)


def test_fresh_keys_draw_other_gusts(env):
  # Without common random numbers, evaluations draw their own gusts: the same
  # candidate scores differently (the simulator's noise a posterior needs).
  config = CONFIG.replace(point='median')
  u = np.stack([_u_truth()] * 3)
  gust, noise = obj_lib.candidate_keys(config.seed, config.search, 0, 3)
  s = env['objective'](
    obj_lib.stack([env['problem'].data]), u[None], gust[None], noise[None]
  )
  assert np.ptp(s.psd) > 0
  # and they are the search's evaluations 0..2: a resume draws the same
  g2, _ = obj_lib.candidate_keys(config.seed, config.search, 1, 2)
  assert np.array_equal(jax.random.key_data(g2), jax.random.key_data(gust[1:]))


def test_candidates_go_through_the_sensor_model(env):
  # A recording made through the depth-sensor model (holes at edges and grazing
  # angles, axial noise) matches the truth only when the candidates go through
  # it too, with the same noise (common random numbers).
  rec = env['rec']
  key = jax.random.fold_in(jax.random.key(CONFIG.seed), 3)
  noisy = physsim.apply_noise_frames(key, jnp.asarray(rec.depth)[None], rec.intrinsics)
  rec = rec._replace(depth=np.asarray(noisy[0]))
  assert (rec.depth > 0).sum() < (env['rec'].depth > 0).sum()  # pixels dropped
  u = _u_truth()[None]
  psd = {}
  for on in (True, False):
    config = CONFIG.replace(sensor_noise=on)
    problem = obj_lib.make_problem(config, env['net'], rec)
    psd[on] = _score(env, u, config, problem, EVALUATOR.objective(problem)).psd[0, 0]
  assert psd[True] < _TRUTH_PSD_TOLERANCE
  assert psd[False] > 10 * _TRUTH_PSD_TOLERANCE


def test_candidates_outside_the_cube_are_refused(env):
  with pytest.raises(ValueError, match='inside'):
    _score(env, np.array([[0.0, 1.5, 0.0]]))
  with pytest.raises(ValueError, match='finite'):
    _score(env, np.array([[np.nan, 0.0, 0.0]]))


# --------------------------------------------------------------- the search


def test_recovers_known_parameters(env, recovery):
  result, state = recovery
  psd_centre = _score(env, np.zeros((1, 3))).psd[0, 0]
  # the first evaluation is the range centre, scored as here
  np.testing.assert_allclose(state['Y'][0], psd_centre, rtol=_REPEAT_TOLERANCE)
  assert (
    result['evaluations']
    == CONFIG.search.n_init + CONFIG.search.q * CONFIG.search.max_iter
  )
  assert result['failed_evaluations'] == 0
  assert result['truth'] == TRUTH
  err = result['errors']
  assert result['psd_best'] < 0.5 * psd_centre
  assert err['estimate']['wind_speed_pct'] < err['range_centre']['wind_speed_pct']
  # the load ratio is the best candidate's, its interval from the GP samples
  e, ratio = result['estimate'], result['load_ratio']
  v, w = e['wind_speed']['value'], e['area_weight']['value']
  assert ratio['value'] == pytest.approx(v**2 / (w * 9.81), rel=1e-12)
  lo, hi = ratio['interval_90']
  assert lo <= ratio['posterior_median'] <= hi
  assert 0 < result['seconds_in_objective'] < result['seconds']
  for name in ('estimate.json', 'trace.png', 'montage.png', layout.RUN_FILE):
    assert os.path.isfile(os.path.join(env['root'], 'full', name))


def test_stopping_rule_and_min_iter(env, monkeypatch):
  # A rule that holds after any second iteration (nothing moves a whole range)
  # may only stop the run at min_iter, before max_iter.
  config = CONFIG.replace(stop_rel_change=1.0, stop_window=1, min_iter=3, max_iter=4)
  workdir = os.path.join(env['root'], 'stop')
  result = _estimate(config, env['rec'], env['model'], workdir)
  assert result['stopped_by_rule']
  assert result['iterations'] == config.search.min_iter < config.search.max_iter
  assert (
    result['evaluations']
    == config.search.n_init + config.search.q * config.search.min_iter
  )
  # Rerun on the finished workdir: nothing is evaluated again.
  counting = _CountCalls(monkeypatch)
  again = _estimate(config, env['rec'], env['model'], workdir)
  assert counting.calls == 0
  assert again['estimate'] == result['estimate']
  assert again['iterations'] == result['iterations'] and again['stopped_by_rule']


def test_resume_after_interrupt(env, recovery, monkeypatch):
  result, state = recovery
  workdir = os.path.join(env['root'], 'resumed')
  done = 2  # the initial design and the first iteration
  _CountCalls(monkeypatch, fail_after=done)
  with pytest.raises(_Interrupted):
    _estimate(CONFIG, env['rec'], env['model'], workdir)
  assert len(_state(workdir)['Y']) == CONFIG.search.n_init + CONFIG.search.q
  counting = _CountCalls(monkeypatch)
  resumed = _estimate(CONFIG, env['rec'], env['model'], workdir)
  # finished batches are not redone; one more call renders the best candidate
  # if it was found before the interruption (the resumed search has not seen
  # its frames)
  best_before = np.nanargmin(state['Y']) < CONFIG.search.n_init + CONFIG.search.q
  assert counting.calls == 1 + CONFIG.search.max_iter - done + int(best_before)
  np.testing.assert_array_equal(_state(workdir)['X'], state['X'])
  np.testing.assert_allclose(_state(workdir)['Y'], state['Y'], rtol=_REPEAT_TOLERANCE)
  assert resumed['estimate'] == result['estimate']
  assert resumed['evaluations'] == result['evaluations']


def test_montage_frames_are_kept_not_resimulated(env, tmp_path, monkeypatch):
  # The best candidate's frames come from its scoring batch: no call beyond
  # the search's own batches, and they are what a fresh call gives.
  config = CONFIG.replace(max_iter=1)
  kept = []
  real = results.write_result
  monkeypatch.setattr(
    results, 'write_result', lambda *a, **kw: kept.append(a[3]) or real(*a, **kw)
  )
  counting = _CountCalls(monkeypatch)
  result = _estimate(config, env['rec'], env['model'], str(tmp_path))
  assert counting.calls == 1 + config.search.max_iter  # the design and one iteration
  state = _state(str(tmp_path))
  x_best = state['X'][np.nanargmin(state['Y'])]
  fresh = _score(env, x_best[None], frames=True).frames[0]
  np.testing.assert_allclose(kept[0], fresh, atol=_REPEAT_TOLERANCE)
  assert result['evaluations'] == config.search.n_init + config.search.q


def test_resume_refuses_another_run(env, recovery):
  other = CONFIG.replace(gusts=0.3)
  full = os.path.join(env['root'], 'full')
  with pytest.raises(ValueError, match=r'run\.json.*config\.gusts'):
    estimation.estimate(other, env['rec'], env['model'], full)
  # another camera is another run
  moved = env['rec'].pose._replace(position=env['rec'].pose.position + 0.1)
  with pytest.raises(ValueError, match=r'run\.json.*camera'):
    estimation.estimate(CONFIG, env['rec']._replace(pose=moved), env['model'], full)
  # the C worker count does not change results: it may differ on resume
  workers = CONFIG.replace(workers=2)
  job = search.Job(workers, env['rec'], env['model'], full)
  resume.check_run(job, obj_lib.make_problem(workers, env['net'], env['rec']))


def _blow_up(monkeypatch, worlds):
  """Marks ``worlds`` (indices in each fused batch) blown up: NaN positions."""
  real = physsim.rollout_fn

  def rollout_fn(*a, **kw):
    fn = real(*a, **kw)

    def run(w):
      xs, valid = fn(w)
      bad = jnp.isin(jnp.arange(xs.shape[0]), jnp.asarray(list(worlds)))
      return jnp.where(bad[:, None, None, None], jnp.nan, xs), valid & ~bad

    return run

  monkeypatch.setattr(obj_lib.physsim, 'rollout_fn', rollout_fn)


def test_every_candidate_blowing_up_names_the_recording(env, tmp_path, monkeypatch):
  _blow_up(monkeypatch, range(max(CONFIG.search.q, CONFIG.search.n_init)))
  config = CONFIG.replace(max_iter=1)
  with pytest.raises(ValueError, match=f'{env["seq"]}.*blew up'):
    estimation.estimate(config, env['rec'], env['model'], str(tmp_path / 'w'))


def test_a_blown_up_candidate_is_a_failure_and_the_run_goes_on(
  env, tmp_path, monkeypatch
):
  _blow_up(monkeypatch, [1])
  config = CONFIG.replace(max_iter=1, min_iter=1)
  workdir = str(tmp_path / 'w')
  # a fresh evaluator: its objectives are built with the patched rollout
  result = estimation.estimate(
    config, env['rec'], env['model'], workdir, progress=False
  )
  y = _state(workdir)['Y']
  assert len(y) == config.search.n_init + config.search.q
  failed = np.flatnonzero(np.isnan(y))
  np.testing.assert_array_equal(failed, [1, config.search.n_init + 1])  # slot 1 of each
  assert result['failed_evaluations'] == 2
  assert np.isfinite(result['psd_best'])


# ----------------------------------------------------------------- reports


def test_errors_by_hand():
  truth = {'bending_scale': 2.0, 'wind_speed': 4.0, 'area_weight': 0.2}
  space = physsim.SearchSpace(area_weight=(0.1, 0.3))
  err = summaries.errors(physsim.params.make(0.5, 5.0, 0.25), truth, space)
  e = err['estimate']
  assert e['wind_speed_pct'] == pytest.approx(25.0, rel=1e-12)
  assert e['area_weight_pct'] == pytest.approx(25.0, rel=1e-12)
  assert e['bending_factor'] == pytest.approx(4.0, rel=1e-12)  # 0.5 vs 2: x4
  # load ratio ~ v^2 / w: (25 / 0.25) / (16 / 0.2) = 1.25
  assert e['load_ratio_pct'] == pytest.approx(25.0, rel=1e-12)
  # wind and weight off along the ratio's iso-line: the ratio is exact
  on_line = summaries.errors(physsim.params.make(2.0, 4.4, 0.242), truth, space)
  assert on_line['estimate']['load_ratio_pct'] == pytest.approx(0.0, abs=1e-9)
  # range centre: bending 1 (log centre), 3.5 m/s, 0.2 kg/m^2
  c = err['range_centre']
  assert c['wind_speed_pct'] == pytest.approx(12.5, rel=1e-12)
  assert c['area_weight_pct'] == pytest.approx(0.0, abs=1e-9)
  assert c['load_ratio_pct'] == pytest.approx(100 * (1 - 3.5**2 / 16), rel=1e-12)


def test_best_seen():
  best = obj_lib.BestSeen()
  assert best.frames_of(np.zeros(3)) is None  # nothing seen (a resumed search)
  u = np.arange(9.0).reshape(3, 3)
  best.update(u, np.array([np.nan, 2.0, 1.0]), 'frames of 2')
  assert best.frames_of(u[2]) == 'frames of 2'
  assert best.frames_of(u[1]) is None
  best.update(u[:2], np.array([1.0, np.nan]), 'frames of 0')  # not better: kept
  assert best.frames_of(u[2]) == 'frames of 2'
  best.update(u[:1], np.array([0.5]), 'frames of 0')
  assert best.frames_of(u[0]) == 'frames of 0'
  best.update(u, np.full(3, np.nan), None)  # all failed: kept
  assert best.y == 0.5


def test_iterations_of_evaluations():
  np.testing.assert_array_equal(
    search_figures.iterations_of(11, n_init=3, q=4), [0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2]
  )


def test_network_retrieval_of_the_shipped_epoch(tmp_path):
  def row(epoch, val, wind):
    chance = {'bending_scale': 2.0, 'wind_speed': 0.5, 'area_weight': 0.1}
    test = {'bending_scale': 2.0, 'wind_speed': wind, 'area_weight': 0.09}
    return {'eval': True, 'epoch': epoch, 'val_score': val,
            'test_retrieval': {**test, 'chance': chance, 'error': 0.0, 'queries': 4}}  # fmt: skip

  run = tmp_path / 'run'
  run.mkdir()
  assert embedding.network_retrieval(str(run)) is None  # no log: nothing claimed
  rows = [row(1, 0.7, 0.4), row(2, 0.9, 0.1), row(3, 0.8, 0.3)]
  (run / 'metrics.jsonl').write_text(''.join(json.dumps(r) + '\n' for r in rows))
  got = embedding.network_retrieval(str(run))  # epoch 2: the best validation score
  assert got == pytest.approx(
    {'bending_scale': 1.0, 'wind_speed': 0.2, 'area_weight': 0.9}
  )
  assert 'wind_speed 0.20' in table_notes.retrieval_note(got)
  from experiments.pipeline import training

  line = training.describe_eval({**rows[1], 'test_triplet_accuracy': 0.625})
  assert line.startswith(
    'epoch 2; held-out triplet accuracy 62.5%; retrieval over chance'
  )
  assert 'area_weight 0.90' in line


def test_report_table_shows_retrieval(env, recovery):
  result, _ = recovery
  assert 'network_retrieval_vs_chance' not in result  # the fixture logged none
  plain = report.report_table(result)
  assert 'retrieval' not in plain  # no column, no note
  ratio_row = next(x for x in plain.splitlines() if x.startswith('| load ratio'))
  t = result['truth']
  assert f'| {t["wind_speed"] ** 2 / (t["area_weight"] * 9.81):.3g} ' in ratio_row
  r = {'bending_scale': 1.05, 'wind_speed': 0.4, 'area_weight': 0.95}
  shown = report.report_table({**result, 'network_retrieval_vs_chance': r})
  rows = [x.rstrip(' |').rsplit('|', 1)[-1].strip() for x in shown.splitlines()[2:6]]
  assert rows == ['1.05', '0.40', '0.95', '-']  # the last column, per quantity


# -------------------------------------------------------------- bad input


def test_missing_recording(env):
  path = os.path.join(env['root'], 'nowhere')
  with pytest.raises(ValueError, match='nowhere'):
    load(path)


def test_corrupt_frame_is_named(env, tmp_path):
  seq = str(tmp_path / 'seq')
  shutil.copytree(env['seq'], seq)
  with open(os.path.join(seq, 'cam0', '0003.png'), 'wb') as f:
    f.write(b'\x89PNG\r\n\x1a\n not really')
  with pytest.raises(ValueError, match='0003.png'):
    load(seq)


def test_normalised_recording_is_refused(env, tmp_path):
  frames = str(tmp_path / 'png8')
  os.makedirs(frames)
  for t, d in enumerate(env['rec'].depth):
    valid = d > 0
    lo, hi = d[valid].min(), d[valid].max()
    img = np.where(valid, 64 + 191 * (hi - d) / (hi - lo), 0).astype(np.uint8)
    cv2.imwrite(os.path.join(frames, f'{t:04d}.png'), img)
  with open(os.path.join(frames, 'fps.txt'), 'w') as f:
    f.write('20')
  with pytest.raises(ValueError, match=r'png8.*normalised'):
    load(frames)


def test_camera_json(env, tmp_path):
  npy = str(tmp_path / 'rec.npy')
  np.save(npy, env['rec'].depth)
  with open(str(tmp_path / 'fps.txt'), 'w') as f:
    f.write('20')
  # a good file gives the recording's camera
  good = str(tmp_path / 'cam.json')
  with open(os.path.join(env['seq'], 'meta.json')) as f:
    meta = json.load(f)
  with open(good, 'w') as f:
    json.dump({k: meta[k] for k in ('intrinsics', 'extrinsics')}, f)
  rec = load(npy, camera_json=good)
  np.testing.assert_allclose(rec.pose.position, env['rec'].pose.position)
  assert rec.truth is None and load(npy).pose is None
  bad = {
    'missing.json': None,
    'broken.json': '{"intrinsics": {"width": 32,',
    'no_intrinsics.json': json.dumps({'extrinsics': meta['extrinsics']}),
    'bad_pose.json': json.dumps(
      {'intrinsics': meta['intrinsics'], 'extrinsics': [{'rotation': [[1, 0]]}]}
    ),
    'bad_fov.json': json.dumps({'intrinsics': {'fov_x_deg': 200}}),
  }
  for name, text in bad.items():
    path = str(tmp_path / name)
    if text is not None:
      with open(path, 'w') as f:
        f.write(text)
    with pytest.raises(ValueError, match=name):
      load(npy, camera_json=path)


def test_model_dir_must_be_a_trained_physnet_run(env, tmp_path):
  empty = str(tmp_path / 'empty')
  os.makedirs(empty)
  with pytest.raises(ValueError, match='not a fit workdir'):
    estimation.estimate(CONFIG, env['rec'], empty, str(tmp_path / 'w1'))
  untrained = str(tmp_path / 'untrained')
  os.makedirs(untrained)
  with open(os.path.join(env['model'], 'config.json')) as f:
    text = f.read()
  with open(os.path.join(untrained, 'config.json'), 'w') as f:
    f.write(text)
  with pytest.raises(ValueError, match='no checkpoint'):
    estimation.estimate(CONFIG, env['rec'], untrained, str(tmp_path / 'w2'))
  small = env['rec']._replace(depth=env['rec'].depth[:, :16, :16])
  with pytest.raises(ValueError, match=r'takes \(32, 32\)'):
    estimation.estimate(CONFIG, small, env['model'], str(tmp_path / 'w3'))


def test_bad_config_is_refused_before_anything_is_written(env, tmp_path):
  workdir = str(tmp_path / 'w')
  for bad, match in (
    (CONFIG.replace(material='denim'), 'material'),
    (CONFIG.replace(fps=1e-9), 'fps'),
    (CONFIG.replace(q=0), 'q must be'),
  ):
    with pytest.raises(ValueError, match=match):
      estimation.estimate(bad, env['rec'], env['model'], workdir)
  assert not os.path.exists(workdir)


def test_fused_objective_on_mjx_matches_mujoco_c(env):
  # The same fused program with MJX (MuJoCo Warp, traced) in place of the
  # MuJoCo C callback: PSDs agree to the two simulators' parity (float32
  # MJX vs float64 forces in C; physsim's rollout test bounds positions by 5 mm).
  config = CONFIG.replace(backend='mjx', n_init=2)
  problem = obj_lib.make_problem(config, env['net'], env['rec'])
  u = np.stack([_u_truth(), np.zeros(3)])
  objective = obj_lib.Objective(problem)
  mjx = _score(env, u, config, problem, objective)
  c = _score(env, u)
  assert mjx.valid.all()
  np.testing.assert_allclose(mjx.psd, c.psd, rtol=0.2, atol=5e-3)
  assert mjx.psd[0, 0] < 0.5 * mjx.psd[0, 1]  # the truth still scores best
  # Off MuJoCo C one candidate is scored in a call padded to the design's
  # size (evaluation.FLAT_WORLDS): the program above, the same score (common
  # random numbers: a candidate's score does not depend on its neighbours).
  shapes = []

  def spy(data, u, *args, **kw):
    shapes.append(np.shape(u))
    return objective(data, u, *args, **kw)

  evaluator = evaluation.Evaluator()
  evaluator.objectives[problem.structure()] = spy
  one = evaluation.score(problem, u[:1], evaluator=evaluator)
  assert shapes == [(1, 2, 3)]  # (problems, candidates, 3)
  assert one.psd.shape == (1,)
  np.testing.assert_allclose(one.psd, mjx.psd[0, :1], rtol=1e-5)
  # A call this small runs on one device; made to split over the two CPU
  # devices (conftest), the same candidates score alike: float32 MJX in
  # another batch shape rounds differently, and the clip amplifies it (1% here).
  assert objective.world_mesh.devices.size == 2
  with pytest.MonkeyPatch.context() as mp:
    mp.setattr(physsim.devices, 'FLAT_WORLDS', 0)
    split = _score(env, u, config, problem, objective)
  np.testing.assert_allclose(split.psd, mjx.psd, rtol=0.05, atol=2e-3)
  assert split.psd[0, 0] < 0.5 * split.psd[0, 1]


def test_a_program_compiled_ahead_is_the_one_the_call_runs(env):
  # Evaluator.compile in a thread, as a lockstep's design does for its steps:
  # the call afterwards compiles nothing on its own thread (physsim.one_off's
  # count of JAX's compile events) and scores bit for bit as an evaluator that
  # compiled at the call. (Split over several devices: devices_test.)
  problems = [
    env['problem'],
    obj_lib.make_problem(CONFIG.replace(seed=1), env['net'], env['rec']),
  ]
  us = [
    np.stack([_u_truth(), np.zeros(3)]),
    np.array([[0.3, -0.2, 0.1], [-0.5, 0.4, 0.6]]),
  ]
  ahead, late = evaluation.Evaluator(), evaluation.Evaluator()
  t = threading.Thread(
    target=ahead.compile, args=(problems, [2, 2]), kwargs=dict(frames=True)
  )
  t.start()
  t.join()
  meter = physsim.one_off.Meter()
  got = ahead(problems, us, [0, 0], frames=True)
  assert meter.seconds() == 0.0
  meter.mark()
  want = late(problems, us, [0, 0], frames=True)
  assert meter.seconds() > 0.0  # the meter sees a compile where there is one
  for g, w in zip(got, want, strict=True):
    np.testing.assert_array_equal(g.psd, w.psd)
    np.testing.assert_array_equal(g.frames, w.frames)
