"""Tests of ``objective.distinct_worlds``: which of a call's candidate worlds
simulate alike, derived by hand from small calls; and the fused objective
around it, with a stand-in rollout, against each problem scored alone; and
the lockstep's time-limit forecast after a shared step."""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import physsim
from experiments.pipeline import embedding, search
from experiments.pipeline import objective as obj_lib
from tests.experiments.estimate_fixtures import CONFIG as FIXTURE_CONFIG
from tests.experiments.estimate_fixtures import (
  TRUTH,
  load,
  write_hand_made_model,
  write_recording,
)

# A posterior search: every evaluation its own gust key.
CONFIG = obj_lib.EstimateConfig().replace(material='gray_interlock', seed=0)
# The same worlds scored in another call shape or split over devices: float32
# rendering and the network's sums, in another batch.
_SAME = 1e-6


def _data(ratios, boxes=None) -> obj_lib.ProblemData:
  """Stacked problem data with only what a simulation reads: boxes and
  rigidity ratios (the rest is not looked at)."""
  p = len(ratios)
  lo = np.tile(np.array([-1.0, 0.5, 0.1], np.float32), (p, 1))
  hi = np.tile(np.array([1.0, 6.0, 0.4], np.float32), (p, 1))
  if boxes is not None:
    hi[:, 2] = boxes
  return obj_lib.ProblemData(
    lo, hi, np.tile(np.array([1.0, 0.0, 0.0], np.float32), (p, 1)),
    np.asarray(ratios, np.float32), None, None, None, None, None, None,
  )  # fmt: skip


def _keys(firsts, q, config=CONFIG):
  """(P, q) gust keys of searches at evaluations ``firsts[i] ..``."""
  return jax.numpy.stack(
    [obj_lib.candidate_keys(config.seed, config.search, f, q)[0] for f in firsts]
  )


def _points(p, q, seed=0):
  return np.random.default_rng(seed).uniform(-1, 1, (p, q, 3)).astype(np.float32)


def test_searches_sharing_a_design_simulate_it_once():
  # Problems 0-2: one fabric, the same design and keys (a calibration's
  # recordings); problem 3: the same fabric with other candidates.
  u = _points(4, 4)
  u[1:3] = u[0]
  rows, inverse = obj_lib.distinct_worlds(_data([1] * 4), u, _keys([0] * 4, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3, 12, 13, 14, 15])
  np.testing.assert_array_equal(inverse, [*range(4)] * 3 + [4, 5, 6, 7])


@pytest.mark.parametrize(
  'what',
  ['another fabric', 'another box', 'other keys', 'another point'],
)
def test_what_makes_a_simulation_differ(what):
  # Four searches given the same candidates; the fourth differs in one way.
  u = _points(4, 4)
  u[1:] = u[0]
  ratios, boxes, firsts = [1] * 4, None, [0] * 4
  if what == 'another fabric':
    ratios[3] = 0.5
  elif what == 'another box':
    boxes = [0.4, 0.4, 0.4, 0.5]
  elif what == 'other keys':
    firsts[3] = 4
  else:
    u[3, 2, 0] = np.nextafter(u[3, 2, 0], np.float32(2))  # one bit
  rows, inverse = obj_lib.distinct_worlds(_data(ratios, boxes), u, _keys(firsts, 4))
  if what == 'another point':  # only that world differs
    np.testing.assert_array_equal(rows, [0, 1, 2, 3, 14])
    np.testing.assert_array_equal(inverse[12:], [0, 1, 4, 3])
  else:  # all four of its worlds
    np.testing.assert_array_equal(rows, [0, 1, 2, 3, 12, 13, 14, 15])
    np.testing.assert_array_equal(inverse[12:], [4, 5, 6, 7])
  np.testing.assert_array_equal(inverse[:12], np.tile(np.arange(4), 3))


def test_common_random_numbers_repeat_a_candidate_within_a_search():
  # The paper's argmin scores every candidate with one key: a padded call's
  # repeated candidates are one simulation.
  config = CONFIG.replace(point='argmin')
  u = _points(1, 4)
  u[0, 1:] = u[0, 0]
  rows, inverse = obj_lib.distinct_worlds(_data([1]), u, _keys([0], 4, config))
  np.testing.assert_array_equal(rows, [0])
  np.testing.assert_array_equal(inverse, [0, 0, 0, 0])


def test_counts_are_padded_to_a_bucket_and_kept_only_where_they_halve_the_call():
  # 32 worlds: buckets of 32 // SIM_BUCKETS = 2 simulations.
  assert obj_lib.SIM_BUCKETS == 16
  u = _points(8, 4)
  u[1:] = u[0]  # 4 distinct simulations of 32
  rows, inverse = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3])
  np.testing.assert_array_equal(inverse, np.tile(np.arange(4), 8))
  u = _points(8, 4)
  u[4:] = u[:4]  # 16 distinct: half the call
  rows, inverse = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, np.arange(16))
  np.testing.assert_array_equal(inverse, np.tile(np.arange(16), 2))
  u[4, 0] += 0.5  # 17 distinct, padded to 18: more than half, the full call
  assert obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4)) is None
  u = _points(8, 4)
  u[1:4] = u[0]  # 4 + 16 = 20 distinct: the full call
  assert obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4)) is None
  u[4:6] = u[0]  # 4 + 8 = 12 distinct
  rows, _ = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3, *range(24, 32)])
  u[5, 0] += 0.5  # 13 distinct, padded to 14 with the last
  rows, _ = obj_lib.distinct_worlds(_data([1] * 8), u, _keys([0] * 8, 4))
  np.testing.assert_array_equal(rows, [0, 1, 2, 3, 20, *range(24, 32), 31])


# ------------------------------------------- the fused objective around them


def _stand_in_rollout(n_frames: int, rest: np.ndarray):
  """A deterministic traced rollout in place of the simulator: the rest mesh
  carried towards the camera by an amount each world's inputs set (wind,
  bending, masses, gusts), growing over the clip. Pure JAX, so it splits over
  devices like MuJoCo Warp does (MuJoCo C's callback does not split)."""

  def rollout(w):
    b = w.speed.shape[0]
    gust = sum(leaf.reshape(b, -1).sum(1) for leaf in jax.tree.leaves(w.gusts))
    amount = (
      0.02 * w.speed
      + 0.03 * jnp.log(w.bending)
      + 0.5 * w.body_mass.sum(1)
      + 0.01 * gust
    )
    t = jnp.linspace(0.0, 1.0, n_frames)
    shift = (
      amount[:, None, None, None] * t[None, :, None, None] * jnp.array([0, 0, 1.0])
    )
    return jnp.asarray(rest, jnp.float32)[None, None] + shift, jnp.ones(b, bool)

  return rollout


@pytest.fixture(scope='module')
def problems(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('distinct'))
  net = embedding.load_embedding(write_hand_made_model(os.path.join(root, 'model')))
  rec = load(write_recording(root, TRUTH))
  moved = rec._replace(depth=rec.depth * np.float32(1.03))  # another recording
  return [obj_lib.make_problem(FIXTURE_CONFIG, net, r) for r in (rec, moved)]


def test_shared_worlds_score_as_alone_on_one_device_and_split_over_two(
  problems, monkeypatch
):
  objective = obj_lib.Objective(problems[0])
  objective._rollout = _stand_in_rollout(problems[0].n_frames, objective.mesh.vertices)
  u = np.stack([np.zeros(3), np.array([0.5, -0.7, 0.9]), np.array([-0.3, 0.2, 0.1])])
  gust, noise = obj_lib.candidate_keys(
    FIXTURE_CONFIG.seed, FIXTURE_CONFIG.search, 0, len(u)
  )

  def call(ps):
    return objective(
      obj_lib.stack([p.data for p in ps]), np.stack([u] * len(ps)),
      jnp.stack([gust] * len(ps)), jnp.stack([noise] * len(ps)), positions=True,
    )  # fmt: skip

  alone = [call([p]) for p in problems]
  assert objective.simulated == 6
  both = call(problems)  # MuJoCo C's host path: every saved world counts
  assert objective.simulated == 9  # one simulation per candidate, not two
  objective.world_mesh = physsim.devices.world_mesh()  # conftest: two CPU devices
  assert objective.world_mesh.devices.size == 2
  # On devices a call must save DEVICE_SAVED_CALLS x FLAT_WORLDS worlds: these
  # 6 (one device's fixed cost) are simulated as they come, one program.
  flat = call(problems)
  assert objective.simulated == 15
  monkeypatch.setattr(physsim.devices, 'FLAT_WORLDS', 0)
  split = call(problems)  # now shared, and split over both devices
  assert objective.simulated == 18
  for got in (both, flat, split):
    for i in range(2):
      np.testing.assert_allclose(got.psd[i], alone[i].psd[0], rtol=_SAME)
      np.testing.assert_array_equal(got.positions[i], alone[i].positions[0])
  assert np.all(np.abs(both.psd[1] - both.psd[0]) > 1e-3)  # scored apart
  assert len(set(np.round(both.psd[0], 6))) == 3  # candidates differ


def test_a_step_after_a_shared_one_is_forecast_as_simulating_everything():
  # by hand: 8400 candidates in 640 simulations took 58 s; the next step
  # simulates its 8400 as they come
  assert search.step_forecast(58.0, 8400, 640) == pytest.approx(58.0 * 8400 / 640)
  assert search.step_forecast(368.0, 8400, 10240) == 368.0  # padding: as long
  assert search.step_forecast(10.0, 40, 40) == 10.0
  assert search.step_forecast(0.0, 0, 0) == 0.0  # the first step: free


def test_a_steps_compile_and_set_up_are_not_scaled_and_not_paid_twice():
  # by hand: 58 s of which 40 compiling; the next step, a new program, is
  # 18 s x 8400 / 640 of work and compiles again
  got = search.step_forecast(58.0, 8400, 640, one_off_s=40.0)
  assert got == pytest.approx(18.0 * 8400 / 640 + 40.0)
  # a step of the same program: its compile is not paid again
  assert search.step_forecast(190.0, 8400, 8960, 40.0, same_program=True) == 150.0
  assert search.step_forecast(190.0, 8400, 8960, 40.0) == 190.0  # a new program
  # a one-off longer than the step (a clock's rounding) is the whole step
  assert search.step_forecast(10.0, 40, 40, 12.0, same_program=True) == 0.0
