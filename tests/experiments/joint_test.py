"""Tests for joint estimates of one fabric in several recordings: the grid
posterior against brute-force enumeration, and the estimate end to end with a
wind reading at each recording."""

import dataclasses
import itertools
import os

import jax
import numpy as np
import pytest
from jax.scipy.special import logsumexp

import physsim
from experiments import estimate as estimate_script
from experiments.pipeline import (
  estimation,
  joint,
  layout,
  measurements,
  objective,
  report,
)
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline import recording as recording_lib
from tests.experiments import estimate_fixtures as fx

pytestmark = pytest.mark.slow  # joint searches over several recordings

GRID = (2, 3, 2)  # bending, wind, area weight cells


def _brute_force(log_liks, log_priors):
  """p(b, w, v_1, ..., v_K | data) by enumerating every cell combination:
  prior p(b, w) prod_k p_k(v_k | b, w), times prod_k L_k(b, v_k, w)."""
  nb, nv, nw = GRID
  ll = [x.reshape(GRID) for x in log_liks]
  lp = [p.reshape(GRID) for p in log_priors]
  log_bw = np.asarray(logsumexp(lp[0], axis=1))
  out = {}
  for b, w in itertools.product(range(nb), range(nw)):
    for vs in itertools.product(range(nv), repeat=len(ll)):
      t = log_bw[b, w]
      for k, v in enumerate(vs):
        t += lp[k][b, v, w] - float(logsumexp(lp[k][b, :, w])) + ll[k][b, v, w]
      out[(b, w, *vs)] = t
  z = float(logsumexp(np.array(list(out.values()))))
  return {k: np.exp(v - z) for k, v in out.items()}


@pytest.mark.parametrize('own_priors', [False, True])
def test_joint_posterior_matches_enumeration(own_priors):
  rng = np.random.default_rng(0)
  g = int(np.prod(GRID))
  log_liks = [rng.normal(0, 1.5, g) for _ in range(2)]
  base = np.log(rng.uniform(0.5, 1.5, GRID[0] * GRID[2]))  # a prior on (b, w)
  base = np.repeat(base.reshape(GRID[0], 1, GRID[2]), GRID[1], axis=1).ravel()
  if own_priors:  # each recording's wind measured apart: its own wind factor
    wind = [np.log(rng.uniform(0.1, 1.0, GRID[1])) for _ in range(2)]
    priors = [(base.reshape(GRID) + f[None, :, None]).ravel() for f in wind]
  else:
    priors = [base, base]
  exact = _brute_force(log_liks, priors)
  out = posterior_lib.joint(
    log_liks, GRID, priors if own_priors else base, jax.random.key(1), n=60_000
  )
  bw = np.zeros((GRID[0], GRID[2]))
  for (b, w, *_), p in exact.items():
    bw[b, w] += p
  np.testing.assert_allclose(np.exp(out['log_post_bw']), bw, rtol=1e-5)  # float32
  # Each recording's draws: its wind cell's marginal, by enumeration, within
  # 5 standard errors of 60,000 draws.
  for k, draws in enumerate(out['samples']):
    cells = np.floor((draws + 1.0) / 2.0 * np.array(GRID)).astype(int)
    for v in range(GRID[1]):
      want = sum(p for key, p in exact.items() if key[2 + k] == v)
      got = np.mean(cells[:, 1] == v)
      assert abs(got - want) < 5 * np.sqrt(want * (1 - want) / 60_000) + 1e-9, (k, v)
  with pytest.raises(ValueError, match='3 priors for 2 recordings'):
    posterior_lib.joint(log_liks, GRID, [base] * 3, jax.random.key(1), n=10)


def test_joint_winds_need_one_reading_per_recording():
  args = estimate_script.Args(recording=('a', 'b'), wind_speeds=(3.0, 4.0),
                              wind_speed_sds=(0.06,))  # fmt: skip
  with pytest.raises(
    ValueError, match='one reading and one uncertainty for each of the 2'
  ):
    estimate_script.joint_winds(args)
  with pytest.raises(ValueError, match='use --wind_speed'):
    estimate_script.joint_winds(
      estimate_script.Args(recording=('a',), wind_speeds=(3.0,), wind_speed_sds=(0.1,))
    )
  both = dataclasses.replace(args, wind_speed_sds=(0.06, 0.08))
  assert estimate_script.joint_winds(both) == [(3.0, 0.06), (4.0, 0.08)]
  assert estimate_script.joint_winds(estimate_script.Args(recording=('a', 'b'))) is None


def test_joint_estimate_with_a_wind_reading_at_each_recording(tmp_path):
  # Two fan settings of one fabric (same bending and area weight), each with
  # an anemometer reading: each search takes its own reading as its prior,
  # and the joint posterior keeps each recording's wind at its reading.
  model_dir = fx.write_hand_made_model(str(tmp_path / 'model'))
  truths = [fx.TRUTH, dict(fx.TRUTH, wind_speed=3.0)]
  # ArcSim's air (the default 'auto' would read the fabric's own: air_test)
  config = objective.PRESETS['smoke'].replace(backend='c', air_coefficient='fixed')
  recs = []
  for k, t in enumerate(truths):
    path = fx.write_recording(str(tmp_path / f'r{k}'), t)
    recs.append(
      recording_lib.load_recording(
        path,
        fps=config.simulation.fps,
        size=(fx.SIZE, fx.SIZE),
        frames=config.simulation.frames,
      )
    )
  winds = [(4.4, 0.09), (3.05, 0.06)]
  with pytest.raises(ValueError, match='1 wind readings for 2 recordings'):
    estimation.estimate_joint(config, recs, model_dir, str(tmp_path / 'x'), winds[:1])
  measured = config.replace(
    measured=measurements.Measured(wind_speed=4.0, wind_speed_sd=0.1)
  )
  with pytest.raises(ValueError, match='--wind_speeds'):
    estimation.estimate_joint(measured, recs, model_dir, str(tmp_path / 'x'))
  workdir = str(tmp_path / 'joint')
  out = estimation.estimate_joint(config, recs, model_dir, workdir, winds)
  cell = 5.0 / config.search.posterior_grid[1]  # the grid's wind cell, m/s
  for k, (v, sd) in enumerate(winds):
    r = out['recordings'][k]
    assert r['measured_wind'] == [v, sd] and r['truth'] == truths[k]
    # The reading dominates each wind (the video adds a little through the
    # shared area weight): a narrow interval near it, jointly and alone.
    for est in (r['wind_speed'], r['alone']['wind_speed']):
      lo, hi = est['interval_90']
      assert v - 4 * sd - cell < lo < hi < v + 4 * sd + cell, (k, lo, hi)
      assert hi - lo < cell + 2 * 1.645 * sd + 1e-9, (k, lo, hi)
    # the search's prior was its own reading's: highest in the reading's cell
    z = np.load(os.path.join(workdir, f'recording_{k}', layout.POSTERIOR_FILE))
    lp = z['log_prior'].reshape(config.search.posterior_grid)
    centre = 1.0 + (np.argmax(lp[0, :, 0]) + 0.5) * cell
    assert abs(centre - v) <= cell / 2 + 1e-9, (k, centre)
  # the shipped calibration has no tables for readings in a joint estimate
  # (nor for this test's settings): said so
  note = out['calibration']
  assert note is None or note['matches'] is False
  # no table covers it: the recordings share the simulator's error
  assert out['shared_bias'] == config.scoring.shared_bias > 0
  assert os.path.isfile(os.path.join(workdir, layout.JOINT_FILE))
  # experiments.plan reads the joint's shared draws: the fabric the
  # recordings told of together, its median the joint's own
  material, draws, _ = layout.read_draws(workdir)
  assert material == config.simulation.material
  assert np.exp(np.median(draws[:, 1])) == pytest.approx(
    out['area_weight']['median'], rel=0.02
  )
  assert np.exp(np.median(draws[:, 0])) == pytest.approx(
    out['bending_scale']['median'], rel=0.05
  )
  # the joint's settings are the shared ones (no one recording's reading)
  assert out['config']['measured']['wind_speed_sd'] == 0.0
  # the same searches run for many fabrics at once (joint_jobs, one
  # estimate_many, combine_joint) resume here and combine to the same joint
  jobs = joint.joint_jobs(config, recs, model_dir, workdir, winds)
  again = joint.combine_joint(jobs, estimation.estimate_many(jobs), workdir)
  assert again['area_weight'] == out['area_weight']
  assert again['recordings'][1]['wind_speed'] == out['recordings'][1]['wind_speed']


def test_a_bending_length_and_a_scale_give_the_estimate_the_fabrics_bending(tmp_path):
  """The video says little about bending; a cantilever test's bending length
  with the scale's area weight does (Peirce: D = w g c^3), and the estimate
  reports it, saying its calibration does not cover the reading."""
  model_dir = fx.write_hand_made_model(str(tmp_path / 'model'))
  config = objective.PRESETS['smoke'].replace(backend='c')
  rec = recording_lib.load_recording(
    fx.write_recording(str(tmp_path / 'r'), fx.TRUTH), fps=config.simulation.fps,
    size=(fx.SIZE, fx.SIZE), frames=config.simulation.frames,
  )  # fmt: skip
  space = physsim.search_space(config.simulation.material)
  b, w = 3.0, fx.TRUTH['area_weight']  # the strip says 3x the reference
  c = float(physsim.params.bending_length(b, w, space.rigidity))
  measured = measurements.Measured(
    area_weight=w, area_weight_sd=0.01 * w, bending_length=c, bending_length_sd=0.02 * c
  )
  out = estimation.estimate(
    config.replace(measured=measured), rec, model_dir, str(tmp_path / 'e'),
    progress=False,
  )  # fmt: skip
  bending = out['estimate']['bending_scale']
  lo, hi = bending['interval_90']
  # 2% on c and 1% on w: about 6.2% on b (1 sd), a 90% interval of about
  # x1.22, within the grid's bending cells (x1.47 at the smoke grid): the
  # draws placed within their cells by the reading (posterior.refine_draws)
  assert lo < b < hi and hi / lo < 1.35, (lo, hi)
  # narrowing is the video's over the prior with the readings: nothing here
  assert bending['narrowing_90'] == pytest.approx(1.0, abs=0.35)
  # a bending length with a scale's area weight: no calibration mode has both
  assert out['calibration'] is None or 'combination of measurements' in (
    out['calibration'].get('differs', [])
  )


def test_a_sheet_and_its_hemmed_twin_at_one_fan_setting_share_one_wind(tmp_path):
  """Two recordings of one fan setting, the second simulated with 0.3 kg at
  its hem (``overrides``): its search simulates the hem (its saved config),
  the joint draws one wind for both (the same interval in each), joint.json
  names the fan and the hem, and the calibration note says no calibration
  measured recordings sharing a fan setting."""
  model_dir = fx.write_hand_made_model(str(tmp_path / 'model'))
  config = objective.PRESETS['smoke'].replace(backend='c')
  recs = [
    recording_lib.load_recording(
      fx.write_recording(str(tmp_path / f'r{k}'), fx.TRUTH),
      fps=config.simulation.fps,
      size=(fx.SIZE, fx.SIZE),
      frames=config.simulation.frames,
    )  # fmt: skip
    for k in range(2)
  ]
  workdir = str(tmp_path / 'joint')
  with pytest.raises(ValueError, match='3 fan settings for 2 recordings'):
    estimation.estimate_joint(config, recs, model_dir, workdir, fans=['a', 'a', 'b'])
  out = estimation.estimate_joint(
    config, recs, model_dir, workdir, overrides=[{}, {'hem_mass': 0.3}],
    fans=['low', 'low'],
  )  # fmt: skip
  a, b = out['recordings']
  assert a['fan'] == b['fan'] == 'low' and 'hem_mass' not in a and b['hem_mass'] == 0.3
  assert a['wind_speed']['interval_90'] == b['wind_speed']['interval_90']
  saved = [
    recording_lib.read_json(
      os.path.join(workdir, f'recording_{k}', layout.ESTIMATE_FILE)
    )
    for k in range(2)
  ]
  # (a config without a hem is written as before hems: no key)
  assert [s['config'].get('hem_mass') for s in saved] == [None, 0.3]
  note = out['calibration']
  assert note is None or 'recordings sharing one fan setting' in note['differs']
  text = report.joint_table(out)
  assert "share fan setting 'low'" in text and 'recording 1 carries 300 g' in text
