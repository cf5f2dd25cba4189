"""Tests of experiments.pipeline.search (estimate_many): lockstep batching changes no search.

Recordings and the hand-made embedding come from ``estimate_fixtures``.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import physsim
from experiments.pipeline import estimation, evaluation, layout
from experiments.pipeline import objective as obj_lib
from experiments.pipeline import search as em
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  load,
  write_hand_made_model,
  write_recording,
)

pytestmark = pytest.mark.slow  # whole searches in lockstep, resumed and alone

OTHER_TRUTH = dict(bending_scale=3.0, wind_speed=2.0, area_weight=0.22)
# Another structure: a different gust intensity is another fused program, so
# this job is scored in a call of its own.
GUSTY = CONFIG.replace(gusts=0.3)
# The C backend and the renderer are deterministic per world, so a candidate
# scores the same whatever batch it is in, up to float32 rendering.
_REPEAT_TOLERANCE = 1e-6


@pytest.fixture(scope='module')
def env(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('many'))
  model = write_hand_made_model(os.path.join(root, 'model'))
  specs = [(CONFIG, TRUTH, 'a'), (CONFIG, OTHER_TRUTH, 'b'), (GUSTY, TRUTH, 'c')]
  recs = []
  for config, truth, name in specs:
    seq = write_recording(os.path.join(root, name), truth, config)
    recs.append((config, load(seq, config)))
  return dict(root=root, model=model, recs=recs)


def _state(workdir):
  with np.load(os.path.join(workdir, 'bo_state.npz')) as z:
    return {k: z[k] for k in z.files}


def _jobs(env, prefix):
  return [
    em.Job(config, rec, env['model'], os.path.join(env['root'], f'{prefix}{i}'))
    for i, (config, rec) in enumerate(env['recs'])
  ]


def _resumes_to(env, prefix, batched):
  """Runs the jobs of ``prefix`` again (they resume) and checks that they
  end where the uninterrupted lockstep did."""
  resumed = estimation.estimate_many(_jobs(env, prefix), progress=False)
  for i in range(3):
    a = _state(os.path.join(env['root'], f'many{i}'))
    b = _state(os.path.join(env['root'], f'{prefix}{i}'))
    np.testing.assert_allclose(b['X'], a['X'], atol=1e-9)
    assert resumed[i]['estimate'] == batched[i]['estimate']


@pytest.fixture(scope='module')
def batched(env):
  return estimation.estimate_many(_jobs(env, 'many'), progress=False)


def test_lockstep_equals_one_by_one(env, batched):
  for i, (config, rec) in enumerate(env['recs']):
    alone_dir = os.path.join(env['root'], f'alone{i}')
    alone = estimation.estimate(config, rec, env['model'], alone_dir, progress=False)
    a, b = _state(alone_dir), _state(os.path.join(env['root'], f'many{i}'))
    np.testing.assert_allclose(b['X'], a['X'], atol=1e-9)
    np.testing.assert_allclose(b['Y'], a['Y'], rtol=_REPEAT_TOLERANCE)
    assert batched[i]['estimate'] == alone['estimate']
    assert batched[i]['recordings_in_batch'] == 3
    for name in ('estimate.json', 'trace.png', 'montage.png', layout.RUN_FILE):
      assert os.path.isfile(os.path.join(env['root'], f'many{i}', name))
  # the two fabrics' searches differ: each scored against its own recording
  assert not np.allclose(batched[0]['psd_best'], batched[1]['psd_best'])


def test_a_bad_job_does_not_stop_the_others(env, tmp_path):
  config, rec = env['recs'][0]
  jobs = [
    em.Job(config, rec, str(tmp_path / 'no_model'), str(tmp_path / 'bad')),
    em.Job(config.replace(max_iter=1), rec, env['model'], str(tmp_path / 'ok')),
  ]
  out = estimation.estimate_many(jobs, progress=False)
  assert isinstance(out[0], Exception) and 'no_model' in str(out[0])
  assert isinstance(out[1], dict) and out[1]['evaluations'] == 8


def test_resume_after_interrupt(env, batched, monkeypatch):
  real = obj_lib.Objective.__call__
  calls = {'n': 0}

  def dying(*a, **kw):
    if calls['n'] == 3:  # two structures: the initial design and one iteration
      raise RuntimeError('machine taken back')
    calls['n'] += 1
    return real(*a, **kw)

  monkeypatch.setattr(obj_lib.Objective, '__call__', dying)
  with pytest.raises(RuntimeError):
    estimation.estimate_many(_jobs(env, 'resumed'), progress=False)
  monkeypatch.setattr(obj_lib.Objective, '__call__', real)
  _resumes_to(env, 'resumed', batched)


def test_a_search_lands_as_soon_as_it_stops(env, tmp_path, monkeypatch):
  (config, rec) = env['recs'][0]
  short = str(tmp_path / 'short')
  jobs = [
    em.Job(config, rec, env['model'], str(tmp_path / 'long')),
    em.Job(config.replace(max_iter=1), rec, env['model'], short),
  ]
  real = evaluation.Evaluator.__call__
  seen = []

  def watching(self, problems, us, firsts, **kw):
    seen.append((len(problems), os.path.isfile(os.path.join(short, 'estimate.json'))))
    return real(self, problems, us, firsts, **kw)

  monkeypatch.setattr(evaluation.Evaluator, '__call__', watching)
  out = estimation.estimate_many(jobs, progress=False)
  # steps: initial design (both), iteration 1 (both; the short one stops),
  # then the long one alone, with the short one's result already written
  assert seen == [(2, False), (2, False), (1, True), (1, True)]
  assert out[1]['evaluations'] == config.search.n_init + config.search.q


def test_a_lockstep_compiles_its_steps_program_while_the_design_runs(
  env, tmp_path, monkeypatch
):
  # Off MuJoCo C (here: made to look so) two searches sharing their design
  # simulate it as a program of its own (distinct worlds once); a thread
  # compiles their steps' program meanwhile (started once the design's own
  # program is compiled), so step 1 compiles nothing on the driver's thread
  # (physsim.one_off) and scores as before.
  config, rec = env['recs'][0]
  config = config.replace(max_iter=1)
  jobs = [em.Job(config, rec, env['model'], str(tmp_path / f'w{i}')) for i in (0, 1)]
  monkeypatch.setattr(evaluation, 'on_mujoco_c', lambda configs: False)
  compiled, compiles_in_call, lowered, design_first = [], [], [], []
  real_compile, real_call = evaluation.Evaluator.compile, evaluation.Evaluator.__call__
  real_init = obj_lib.Objective.__init__

  class Lowering:  # an objective's program, its lowerings counted
    def __init__(self, program):
      self.program = program

    def lower(self, *a, **kw):
      lowered.append(1)
      return self.program.lower(*a, **kw)

    def __call__(self, *a, **kw):
      return self.program(*a, **kw)

  def init(self, problem):
    real_init(self, problem)
    self._program = Lowering(self._program)

  def compile_(self, problems, sizes, **kw):
    design_first.append(len(lowered) == 1)  # the design's, on the driver's thread
    try:
      real_compile(self, problems, sizes, **kw)
      compiled.append(list(sizes))
    except Exception as e:  # the driver's thread drops it: keep it to fail on
      compiled.append(e)

  def call(self, *a, **kw):
    meter = physsim.one_off.Meter()
    out = real_call(self, *a, **kw)
    compiles_in_call.append(meter.seconds())
    return out

  monkeypatch.setattr(obj_lib.Objective, '__init__', init)
  monkeypatch.setattr(evaluation.Evaluator, 'compile', compile_)
  monkeypatch.setattr(evaluation.Evaluator, '__call__', call)
  out = estimation.estimate_many(jobs, progress=False)
  assert compiled == [[config.search.q] * 2] and design_first == [True]
  assert len(compiles_in_call) == 2  # the design, then step 1
  assert compiles_in_call[0] > 0.0 and compiles_in_call[1] == 0.0
  for o in out:
    assert o['evaluations'] == config.search.n_init + config.search.q


def test_lockstep_rows_pad_by_at_most_an_eighth_beyond_sixteen():
  # Up to 16 searches: the next power of two (few shapes where a compile costs
  # more than the padding); beyond, at most 1/8 more rows and at most eight
  # shapes per doubling (210 -> 224, where a power of two gave 256).
  assert [evaluation.padded_rows(n) for n in (1, 2, 3, 5, 9, 16)] == [
    1,
    2,
    4,
    8,
    16,
    16,
  ]
  assert (
    evaluation.padded_rows(210) == 224
    and evaluation.padded_rows(17) == 18
    and evaluation.padded_rows(256) == 256
  )
  for lo in (16, 32, 64, 128, 256):
    ns = np.arange(lo + 1, 2 * lo + 1)
    rows = np.array([evaluation.padded_rows(int(n)) for n in ns])
    assert (rows >= ns).all() and (rows / ns).max() <= 1.125
    assert len(set(rows)) <= 8


def test_one_structure_is_one_call(env, monkeypatch):
  # The two recordings of one structure (same mesh, clock, camera model,
  # network) are scored in one fused call per step, the gusty one in another.
  calls = []
  real = obj_lib.Objective.__call__

  def call(obj, data, u, *a, **kw):
    calls.append(u.shape)
    return real(obj, data, u, *a, **kw)

  monkeypatch.setattr(obj_lib.Objective, '__call__', call)
  estimation.estimate_many(_jobs(env, 'counted'), progress=False)
  n_init, q = CONFIG.search.n_init, CONFIG.search.q
  # (P, q, 3) per call: P padded to a power of two (2 recordings, then 1)
  assert calls[:2] == [(2, n_init, 3), (1, n_init, 3)]
  assert calls[2:4] == [(2, q, 3), (1, q, 3)]


# A posterior search alone and inside a batch runs its GP steps as one row of
# the same program (bo.batched): its candidates agree to the last bits, its
# grid posterior and summaries to round-off.
_BATCH_TOLERANCE = 1e-9
POSTERIOR = CONFIG.replace(point='median', posterior_grid=(4, 8, 4), q=4, replicates=1)


def _posterior_state(workdir):
  with np.load(os.path.join(workdir, layout.POSTERIOR_STATE)) as z:
    return {k: z[k] for k in z.files}


def _assert_close(a, b, path=''):
  """Nested JSON values equal, numbers to ``_BATCH_TOLERANCE``."""
  if isinstance(a, dict):
    assert set(a) == set(b), path
    for k in a:
      _assert_close(a[k], b[k], f'{path}.{k}')
  elif isinstance(a, list):
    assert len(a) == len(b), path
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
      _assert_close(x, y, f'{path}[{i}]')
  elif isinstance(a, float):
    np.testing.assert_allclose(b, a, rtol=_BATCH_TOLERANCE, err_msg=path)
  else:
    assert a == b, path


def test_a_posterior_alone_and_in_a_batch_of_three(env):
  jobs = [
    em.Job(POSTERIOR.replace(gusts=config.simulation.gusts), rec, env['model'],
           os.path.join(env['root'], f'post_many{i}'))
    for i, (config, rec) in enumerate(env['recs'])
  ]  # fmt: skip
  together = estimation.estimate_many(jobs, progress=False, figures=False)
  pictures = []  # drawn when the caller asks (after its table)
  alone = estimation.estimate(*jobs[1][:3], os.path.join(env['root'], 'post_alone'),
                      progress=False, pictures=pictures)  # fmt: skip
  names = ('posterior.png', 'trace.png', 'montage.png')
  for workdir in (jobs[1].workdir, os.path.join(env['root'], 'post_alone')):
    assert not any(os.path.exists(os.path.join(workdir, n)) for n in names)
  assert len(pictures) == len(names)
  for draw in pictures:
    draw()
  for n in names:
    assert os.path.getsize(os.path.join(env['root'], 'post_alone', n)) > 0
  a = _posterior_state(os.path.join(env['root'], 'post_alone'))
  b = _posterior_state(jobs[1].workdir)
  np.testing.assert_allclose(b['X'], a['X'], rtol=0, atol=_BATCH_TOLERANCE)
  np.testing.assert_allclose(b['Y'], a['Y'], rtol=_REPEAT_TOLERANCE)
  np.testing.assert_allclose(b['history'], a['history'], atol=_BATCH_TOLERANCE)
  with (
    np.load(os.path.join(env['root'], 'post_alone', layout.POSTERIOR_FILE)) as pa,
    np.load(os.path.join(jobs[1].workdir, layout.POSTERIOR_FILE)) as pb,
  ):
    np.testing.assert_allclose(pb['log_post'], pa['log_post'], atol=_BATCH_TOLERANCE)
    np.testing.assert_allclose(pb['samples'], pa['samples'], atol=_BATCH_TOLERANCE)
  for key in ('estimate', 'load_ratio', 'point_unit', 'argmin', 'evaluations'):
    _assert_close(alone[key], together[1][key], key)
  # each recording's posterior is its own
  assert together[0]['estimate'] != together[1]['estimate']


def test_a_time_limit_stops_between_steps_and_the_rerun_resumes(
  env, batched, monkeypatch
):
  # --time_limit: before each step the last step's duration is the forecast;
  # a step that would end after the deadline does not start (no simulation of
  # it is paid for), and the same call resumes to the uninterrupted result.
  from experiments.pipeline import deadline

  real = evaluation.Evaluator.__call__
  clock = {'t': 0.0}
  monkeypatch.setattr(deadline.time, 'monotonic', lambda: clock['t'])
  steps = []

  def slow(self, problems, us, firsts, **kw):
    steps.append(len(problems))
    clock['t'] += 100.0  # each step "takes" 100 s of the budget
    return real(self, problems, us, firsts, **kw)

  monkeypatch.setattr(evaluation.Evaluator, '__call__', slow)
  deadline.set_limit(250.0, start=0.0)
  try:
    with pytest.raises(deadline.Reached, match='stopped before step 3'):
      estimation.estimate_many(_jobs(env, 'limited'), progress=False)
  finally:
    deadline.set_limit(0.0)
  # steps 0-2 began inside the budget (300 s on the clock); step 3 did not
  assert len(steps) == 3
  monkeypatch.setattr(evaluation.Evaluator, '__call__', real)
  _resumes_to(env, 'limited', batched)
