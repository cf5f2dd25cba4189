"""Tests for experiments.estimate: recovery, stopping rule, resume, bad input.

The model and recording come from ``estimate_fixtures`` (a hand-made
embedding, not a trained network; see there why).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil

import cv2
import numpy as np
import pytest

import model as model_lib
import physsim
from experiments import estimate as est
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  load,
  write_hand_made_model,
  write_recording,
)

# ----------------------------------------------------------------- fixtures


@pytest.fixture(scope='module')
def env(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('estimate'))
  model_dir = write_hand_made_model(os.path.join(root, 'model'))
  seq = write_recording(root, TRUTH)
  return dict(root=root, model=model_dir, seq=seq, rec=load(seq))


_MAKE_OBJECTIVE = est.make_objective  # the real one, whatever is patched later


class _Interrupted(Exception):
  pass


class _Counting:
  """Wraps ``make_objective`` so that ``fun`` counts calls (and may fail)."""

  def __init__(self, fail_after: int | None = None):
    self.calls = 0
    self.fail_after = fail_after
    self._make = _MAKE_OBJECTIVE

  def __call__(self, *args, **kw):
    obj = self._make(*args, **kw)

    def fun(u):
      if self.fail_after is not None and self.calls >= self.fail_after:
        raise _Interrupted(f'after {self.calls} calls')
      self.calls += 1
      return obj.fun(u)

    return obj._replace(fun=fun)


def _state(workdir: str) -> dict:
  with np.load(os.path.join(workdir, 'bo_state.npz')) as z:
    return {k: z[k] for k in z.files}


@pytest.fixture(scope='module')
def recovery(env):
  workdir = os.path.join(env['root'], 'full')
  result = est.estimate(CONFIG, env['rec'], env['model'], workdir, progress=False)
  return result, _state(workdir)


# ------------------------------------------------------------------- tests

# The truth's PSD is zero but for the mm quantisation of the recording.
_TRUTH_PSD_TOLERANCE = 1e-3
# The same candidate scores the same in every objective (common random numbers,
# deterministic C backend and renderer).
_REPEAT_TOLERANCE = 1e-6


def test_recovers_known_parameters(env, recovery):
  result, state = recovery
  net, params, _ = model_lib.load_network(env['model'])
  obj = est.make_objective(CONFIG, net, params, 'metric', env['rec'])
  u_truth = physsim.to_unit(physsim.params.make(**TRUTH), obj.space)
  psd_truth, psd_centre = obj.fun(np.stack([u_truth, np.zeros(3)]))
  assert psd_truth < _TRUTH_PSD_TOLERANCE
  # the first evaluation is the range centre, scored as here
  np.testing.assert_allclose(state['Y'][0], psd_centre, rtol=_REPEAT_TOLERANCE)
  assert result['evaluations'] == CONFIG.n_init + CONFIG.q * CONFIG.max_iter
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
  for name in ('estimate.json', 'trace.png', 'montage.png', est.RUN_FILE):
    assert os.path.isfile(os.path.join(env['root'], 'full', name))


def test_candidates_go_through_the_sensor_model(env):
  # A recording made through the depth-sensor model (holes at edges and grazing
  # angles, axial noise) matches the truth only when the candidates go through
  # it too: the estimate draws the same sensor noise for every candidate.
  import jax

  rec = env['rec']
  noisy = est._sensor(rec.intrinsics)(
    jax.numpy.asarray(rec.depth)[None, None],
    jax.random.fold_in(jax.random.key(CONFIG.seed), 3)[None],
  )[0, 0]
  rec = rec._replace(depth=np.asarray(noisy))
  assert (rec.depth > 0).sum() < (env['rec'].depth > 0).sum()  # pixels dropped
  net, params, _ = model_lib.load_network(env['model'])
  u = physsim.to_unit(
    physsim.params.make(**TRUTH), physsim.search_space(CONFIG.material)
  )
  on = dataclasses.replace(CONFIG, sensor_noise=True)
  with_model = est.make_objective(on, net, params, 'metric', rec).fun(u[None])[0]
  without = est.make_objective(CONFIG, net, params, 'metric', rec).fun(u[None])[0]
  assert with_model < _TRUTH_PSD_TOLERANCE
  assert without > 10 * _TRUTH_PSD_TOLERANCE


def test_stopping_rule_and_min_iter(env, monkeypatch):
  # A rule that holds after any second iteration (nothing moves a whole range)
  # may only stop the run at min_iter, before max_iter.
  config = dataclasses.replace(
    CONFIG, stop_rel_change=1.0, stop_window=1, min_iter=3, max_iter=4
  )
  workdir = os.path.join(env['root'], 'stop')
  result = est.estimate(config, env['rec'], env['model'], workdir, progress=False)
  assert result['stopped_by_rule']
  assert result['iterations'] == config.min_iter < config.max_iter
  assert result['evaluations'] == config.n_init + config.q * config.min_iter
  # Rerun on the finished workdir: nothing is evaluated again.
  counting = _Counting()
  monkeypatch.setattr(est, 'make_objective', counting)
  again = est.estimate(config, env['rec'], env['model'], workdir, progress=False)
  assert counting.calls == 0
  assert again['estimate'] == result['estimate']
  assert again['iterations'] == result['iterations'] and again['stopped_by_rule']


def test_resume_after_interrupt(env, recovery, monkeypatch):
  result, state = recovery
  workdir = os.path.join(env['root'], 'resumed')
  done = 2  # the initial design and the first iteration
  monkeypatch.setattr(est, 'make_objective', _Counting(fail_after=done))
  with pytest.raises(_Interrupted):
    est.estimate(CONFIG, env['rec'], env['model'], workdir, progress=False)
  assert len(_state(workdir)['Y']) == CONFIG.n_init + CONFIG.q

  counting = _Counting()
  monkeypatch.setattr(est, 'make_objective', counting)
  resumed = est.estimate(CONFIG, env['rec'], env['model'], workdir, progress=False)
  assert counting.calls == 1 + CONFIG.max_iter - done  # finished batches not redone
  np.testing.assert_array_equal(_state(workdir)['X'], state['X'])
  np.testing.assert_allclose(_state(workdir)['Y'], state['Y'], rtol=_REPEAT_TOLERANCE)
  assert resumed['estimate'] == result['estimate']
  assert resumed['evaluations'] == result['evaluations']


def test_montage_frames_are_kept_not_resimulated(env, tmp_path, monkeypatch):
  # The best candidate's frames come from its scoring batch: no simulation
  # beyond the search's own batches, and the frames are what a fresh
  # simulation of the best candidate gives.
  config = dataclasses.replace(CONFIG, max_iter=1)
  sims, kept = [], []
  real_sim, real_finish = est.simulate_problems, est.finish
  monkeypatch.setattr(
    est, 'simulate_problems', lambda *a, **kw: sims.append(1) or real_sim(*a, **kw)
  )
  monkeypatch.setattr(
    est, 'finish', lambda *a, **kw: kept.append(a[5]) or real_finish(*a, **kw)
  )
  result = est.estimate(config, env['rec'], env['model'], str(tmp_path), progress=False)
  assert len(sims) == 1 + config.max_iter  # the design and one iteration
  net, params, _ = model_lib.load_network(env['model'])
  obj = _MAKE_OBJECTIVE(config, net, params, 'metric', env['rec'])
  x_best = _state(str(tmp_path))['X'][np.argmin(_state(str(tmp_path))['Y'])]
  fresh, _ = obj.simulate_frames(x_best[None])
  np.testing.assert_allclose(kept[0], np.asarray(fresh[0, 0]), atol=_REPEAT_TOLERANCE)
  assert result['evaluations'] == config.n_init + config.q


def test_errors_by_hand():
  truth = {'bending_scale': 2.0, 'wind_speed': 4.0, 'area_weight': 0.2}
  space = physsim.SearchSpace(area_weight=(0.1, 0.3))
  err = est.errors(physsim.params.make(0.5, 5.0, 0.25), truth, space)
  e = err['estimate']
  assert e['wind_speed_pct'] == pytest.approx(25.0, rel=1e-12)
  assert e['area_weight_pct'] == pytest.approx(25.0, rel=1e-12)
  assert e['bending_factor'] == pytest.approx(4.0, rel=1e-12)  # 0.5 vs 2: x4
  # load ratio ~ v^2 / w: (25 / 0.25) / (16 / 0.2) = 1.25
  assert e['load_ratio_pct'] == pytest.approx(25.0, rel=1e-12)
  # wind and weight off along the ratio's iso-line: the ratio is exact
  on_line = est.errors(physsim.params.make(2.0, 4.4, 0.242), truth, space)['estimate']
  assert on_line['load_ratio_pct'] == pytest.approx(0.0, abs=1e-9)
  # range centre: bending 1 (log centre), 3.5 m/s, 0.2 kg/m^2
  c = err['range_centre']
  assert c['wind_speed_pct'] == pytest.approx(12.5, rel=1e-12)
  assert c['area_weight_pct'] == pytest.approx(0.0, abs=1e-9)
  assert c['load_ratio_pct'] == pytest.approx(100 * (1 - 3.5**2 / 16), rel=1e-12)


def test_best_seen():
  best = est.BestSeen()
  assert best.frames_of(np.zeros(3)) is None  # nothing seen (a resumed search)
  u = np.arange(9.0).reshape(3, 3)
  frames = np.arange(3 * 2 * 4).reshape(3, 2, 4)  # (q, C, T)
  best.update(u, np.array([np.nan, 2.0, 1.0]), frames)
  np.testing.assert_array_equal(best.frames_of(u[2]), frames[2, 0])
  assert best.frames_of(u[1]) is None
  best.update(u[:2], np.array([1.0, np.nan]), frames[:2])  # not better: kept
  np.testing.assert_array_equal(best.frames_of(u[2]), frames[2, 0])
  best.update(u[:1], np.array([0.5]), frames[:1])
  np.testing.assert_array_equal(best.frames_of(u[0]), frames[0, 0])
  best.update(u, np.full(3, np.nan), frames)  # all failed: kept
  assert best.y == 0.5


def test_resume_refuses_another_run(env, recovery):
  other = dataclasses.replace(CONFIG, gusts=0.3)
  with pytest.raises(ValueError, match=r'run\.json.*config\.gusts'):
    est.estimate(other, env['rec'], env['model'], os.path.join(env['root'], 'full'))
  # the C worker count does not change results: it may differ on resume
  workers = dataclasses.replace(CONFIG, workers=2)
  est._check_run(os.path.join(env['root'], 'full'), workers, env['rec'], env['model'])


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
    est.estimate(CONFIG, env['rec'], empty, str(tmp_path / 'w1'))
  untrained = str(tmp_path / 'untrained')
  os.makedirs(untrained)
  with open(os.path.join(env['model'], 'config.json')) as f:
    text = f.read()
  with open(os.path.join(untrained, 'config.json'), 'w') as f:
    f.write(text)
  with pytest.raises(ValueError, match='no checkpoint'):
    est.estimate(CONFIG, env['rec'], untrained, str(tmp_path / 'w2'))
  small = env['rec']._replace(depth=env['rec'].depth[:, :16, :16])
  with pytest.raises(ValueError, match=r'takes \(32, 32\)'):
    est.estimate(CONFIG, small, env['model'], str(tmp_path / 'w3'))


def _blow_up(monkeypatch, worlds):
  """Marks ``worlds`` (indices in each batch) of every simulation invalid."""
  real = est.physsim.simulate

  def simulate(*args, **kw):
    out = real(*args, **kw)
    bad = np.zeros(len(out.valid), bool)
    bad[[w for w in worlds if w < len(bad)]] = True
    pos = np.where(bad[:, None, None, None], np.nan, out.positions)
    return out._replace(positions=pos, valid=out.valid & ~bad)

  monkeypatch.setattr(est.physsim, 'simulate', simulate)


def test_every_candidate_blowing_up_names_the_recording(env, tmp_path, monkeypatch):
  _blow_up(monkeypatch, range(CONFIG.q))
  config = dataclasses.replace(CONFIG, max_iter=1)
  with pytest.raises(ValueError, match=f'{env["seq"]}.*blew up'):
    est.estimate(config, env['rec'], env['model'], str(tmp_path / 'w'))


def test_a_blown_up_candidate_is_a_failure_and_the_run_goes_on(
  env, tmp_path, monkeypatch
):
  _blow_up(monkeypatch, [1])
  config = dataclasses.replace(CONFIG, max_iter=1, min_iter=1)
  workdir = str(tmp_path / 'w')
  result = est.estimate(config, env['rec'], env['model'], workdir, progress=False)
  y = _state(workdir)['Y']
  assert len(y) == config.n_init + config.q
  failed = np.flatnonzero(np.isnan(y))
  np.testing.assert_array_equal(failed, [1, config.n_init + 1])  # slot 1 of each
  assert result['failed_evaluations'] == 2
  assert np.isfinite(result['psd_best'])


def test_network_retrieval_of_the_shipped_epoch(tmp_path):
  def row(epoch, val, wind):
    chance = {'bending_scale': 2.0, 'wind_speed': 0.5, 'area_weight': 0.1}
    test = {'bending_scale': 2.0, 'wind_speed': wind, 'area_weight': 0.09}
    return {'eval': True, 'epoch': epoch, 'val_score': val,
            'test_retrieval': {**test, 'chance': chance, 'error': 0.0, 'queries': 4}}  # fmt: skip

  run = tmp_path / 'run'
  run.mkdir()
  assert est.network_retrieval(str(run)) is None  # no log: nothing claimed
  rows = [row(1, 0.7, 0.4), row(2, 0.9, 0.1), row(3, 0.8, 0.3)]
  (run / 'metrics.jsonl').write_text(''.join(json.dumps(r) + '\n' for r in rows))
  got = est.network_retrieval(str(run))  # epoch 2: the best validation score
  assert got == pytest.approx(
    {'bending_scale': 1.0, 'wind_speed': 0.2, 'area_weight': 0.9}
  )
  assert 'wind_speed 0.20' in est.retrieval_note(got)
  from experiments import train

  line = train.describe_eval({**rows[1], 'test_triplet_accuracy': 0.625})
  assert line.startswith(
    'epoch 2; held-out triplet accuracy 62.5%; retrieval over chance'
  )
  assert 'area_weight 0.90' in line


def test_report_table_shows_retrieval(env, recovery):
  result, _ = recovery
  assert 'network_retrieval_vs_chance' not in result  # the fixture logged none
  plain = est.report_table(result)
  assert plain.count('| n/a |') == 3
  ratio_row = next(x for x in plain.splitlines() if x.startswith('| load ratio'))
  t = result['truth']
  assert f'| {t["wind_speed"] ** 2 / (t["area_weight"] * 9.81):.3g} |' in ratio_row
  r = {'bending_scale': 1.05, 'wind_speed': 0.4, 'area_weight': 0.95}
  shown = est.report_table({**result, 'network_retrieval_vs_chance': r})
  assert '| 0.40 |' in shown and '| 1.05 |' in shown and 'n/a' not in shown
