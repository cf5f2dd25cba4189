"""The calibration study's analysis against a likelihood that is exact.

Synthetic saved posteriors stand in for estimates: each recording's "GP" of log
discrepancy is ``m + log(1 + a |u - u_obs|^2)`` on the grid, ``u_obs`` the
truth (unit cube) plus Gaussian noise of sd ``S``. The Gibbs likelihood
``-c (exp(f - m) - 1) / sn`` is then ``N(u_obs, S^2)`` exactly at
``c = C_TRUE``, so with truths drawn from the prior its intervals must hold the
truth as often as they say there and too rarely when sharper; the study's
choice must not be the sharper one.
"""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest

import bo
import physsim
from experiments.pipeline import (
  calibration_tables,
  layout,
  measurements,
  table_notes,
)
from experiments.pipeline import posterior as posterior_lib
from experiments.pipeline.objective import EstimateConfig
from experiments.studies import calibration, calibration_check

# These tests calibrate and quote the estimates of networks (the PSD); the
# estimate's default distance is the shape.
PSD_ESTIMATE = EstimateConfig().replace(distance='energy')

pytestmark = pytest.mark.slow  # the calibration study end to end

S = 0.3  # observation noise, unit-cube coordinates
SN, C_TRUE = 0.5, 1.0
A = SN / (2 * S**2 * C_TRUE)  # makes c = C_TRUE exact
GRID = (20, 20, 20)


def _fake_runs(
  config: calibration.Config, root: str, noise_seed: int = 1, blind=()
) -> list[dict]:
  """Saved GPs of an exact likelihood; the unit-cube dimensions in ``blind``
  are left out of it (the video says nothing about them)."""
  space = physsim.search_space(config.material)
  truths = calibration.truths(config)
  units = physsim.to_unit(truths, space)
  rng = np.random.default_rng(noise_seed)
  points = bo.posterior.grid_points(GRID)
  seen = np.array([d not in blind for d in range(3)], np.float64)
  runs = []
  for seq, u in enumerate(units):
    obs = u + S * rng.standard_normal(3)
    mean = -2.0 + np.log1p(A * np.sum(seen * (points - obs) ** 2, -1))
    wd = os.path.join(root, f'{seq:04d}')
    os.makedirs(wd)
    np.savez(os.path.join(wd, layout.POSTERIOR_FILE), gp_mean=mean,
             gp_var=np.zeros_like(mean), floor=mean.min(), noise_sd=SN)  # fmt: skip
    truth = {
      f: float(np.ravel(getattr(truths, f))[seq]) for f in physsim.Params._fields
    }
    runs.append({'seq': seq, 'truth': truth, 'workdir': wd})
  return runs


def test_analysis_recovers_the_exact_likelihoods_calibration(tmp_path):
  config = calibration.Config(
    pairs=100, sharpness_grid=(0.25, C_TRUE, 4.0),
    estimate=PSD_ESTIMATE.replace(posterior_grid=GRID),
  )  # fmt: skip
  runs = _fake_runs(config, str(tmp_path))
  analysis = calibration.analyse(config, runs)
  gibbs = analysis['sweep']['gibbs']
  raw = {c: gibbs[c]['uncalibrated']['video'] for c in config.sharpness_grid}
  for (
    f
  ) in physsim.Params._fields:  # 200 recordings: binomial sd 0.02 at 90%, 0.035 at 50%
    assert abs(raw[C_TRUE][f]['interval_90'] - 0.9) < 0.07, f
    assert abs(raw[C_TRUE][f]['interval_50'] - 0.5) < 0.11, f
    assert raw[4.0][f]['interval_90'] < 0.8, f  # sharper: too narrow
  # The recalibrated intervals score best at the exact likelihood, on every
  # fold; the older rule errs flat.
  assert analysis['best_sharpness']['gibbs'] == C_TRUE
  assert analysis['fold_sharpness']['gibbs'] == [C_TRUE] * analysis['folds']
  # Cross-fitted (every recording read with tables chosen without it): the
  # intervals hold the truth as often as they say, in every mode.
  cross = analysis['cross_validated']['gibbs']
  for mode in calibration.MODES:
    assert cross[mode]['n'] == 200, mode
    for f in calibration.FIELDS:
      assert abs(cross[mode][f]['interval_90'] - 0.9) < 0.07, (mode, f)
      assert abs(cross[mode][f]['interval_50'] - 0.5) < 0.11, (mode, f)
  # A measured wind (2%) narrows the wind's intervals and keeps them honest.
  known = cross['known wind']['wind_speed']
  assert (
    known['median_error_pct'] < cross['video']['wind_speed']['median_error_pct'] / 3
  )
  out = calibration.result(config, analysis)
  assert out['sharpness'] == C_TRUE and out['n'] == 200
  assert set(out['recalibration']['modes']) == set(calibration.MODES)
  assert 'recalibrated (held out)' in calibration.table(out)


def test_recalibration_repairs_a_too_sharp_likelihood_on_held_out_recordings(
  tmp_path,
):
  config = calibration.Config(
    pairs=100, estimate=PSD_ESTIMATE.replace(posterior_grid=GRID)
  )
  scores = calibration.posteriors(
    config, _fake_runs(config, str(tmp_path)), 'gibbs', 4.0
  )
  video = scores['video']
  halves = video[:100], video[100:]  # pairs 0-49 and 50-99
  space = physsim.search_space(config.material)
  raw = calibration.summarise(video, space)
  # Two folds: each half read with the levels the other half chose.
  held = [
    {**s, 'levels': calibration.recalibration(halves[1 - k])}
    for k in (0, 1)
    for s in halves[k]
  ]
  fixed = calibration.summarise(held, space)
  # 200 held out; pairs share bending and area weight, and an overconfident
  # posterior's ranks pile up at the ends, so the 50% level varies most.
  for f in calibration.FIELDS:
    assert raw[f]['interval_90'] < 0.8, f
    assert abs(fixed[f]['interval_90'] - 0.9) < 0.07, f
    assert abs(fixed[f]['interval_50'] - 0.5) < 0.12, f


def test_a_quantity_the_video_does_not_inform_keeps_its_nominal_levels(tmp_path):
  # Area weight left out of the likelihood: its posterior is the prior, whose
  # intervals hold truths drawn from the prior exactly as often as they say,
  # so the recalibration keeps its nominal levels (and fits the others).
  config = calibration.Config(
    pairs=40, estimate=PSD_ESTIMATE.replace(posterior_grid=GRID)
  )
  runs = _fake_runs(config, str(tmp_path), blind=(2,))
  video = calibration.posteriors(config, runs, 'gibbs', C_TRUE)['video']
  space = physsim.search_space(config.material)
  raw = calibration.summarise(video, space, bayes=False)
  assert raw['area_weight']['width_ratio'] > bo.calibration.UNINFORMED
  assert raw['wind_speed']['width_ratio'] < 0.7
  lv = calibration.recalibration(video)
  i = calibration.FIELDS.index('area_weight')
  np.testing.assert_array_equal(lv[:, i], bo.calibration.PROBS)
  fitted = calibration.FIELDS.index('wind_speed')
  assert not np.array_equal(lv[:, fitted], bo.calibration.PROBS)


def test_an_estimate_quotes_coverage_only_for_the_calibrated_settings(
  tmp_path, monkeypatch
):
  cal = {
    'n': 50, 'setting': 'gibbs likelihood, sharpness 0.7, demo-size', 'likelihood': 'gibbs',
    'sharpness': 0.7, 'coverage': {'wind_speed': {'interval_50': 0.48, 'interval_90': 0.88}},
  }  # fmt: skip
  path = tmp_path / 'calibration.json'
  path.write_text(json.dumps(cal))
  monkeypatch.setattr(calibration_tables, 'CALIBRATION_FILE', str(path))
  same = calibration_tables.calibration_note(PSD_ESTIMATE.replace(sharpness=0.7))
  assert 'wind 88%/48%' in table_notes.calibration_line(same)
  other = calibration_tables.calibration_note(PSD_ESTIMATE.replace(sharpness=1.4))
  assert other['matches'] is False
  assert 'not for this sharpness' in table_notes.calibration_line(other)
  other = calibration_tables.calibration_note(
    PSD_ESTIMATE.replace(sharpness=0.7, likelihood='threshold')
  )
  assert other['matches'] is False
  assert other['differs'] == ['likelihood']
  # A setting that changes what a score means (the mesh) also voids the quote.
  cal['config'] = {
    'estimate': {'cloth_resolution': 25, 'frames': 60, 'q': PSD_ESTIMATE.search.q}
  }
  path.write_text(json.dumps(cal))
  assert (
    calibration_tables.calibration_note(PSD_ESTIMATE.replace(sharpness=0.7))['matches']
    is True
  )
  other = calibration_tables.calibration_note(
    PSD_ESTIMATE.replace(sharpness=0.7, cloth_resolution=10)
  )
  assert other['differs'] == ['cloth_resolution']
  other = calibration_tables.calibration_note(
    PSD_ESTIMATE.replace(sharpness=0.7, q=8)
  )  # the budget
  assert other['differs'] == ['q']
  monkeypatch.setattr(
    calibration_tables, 'CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  assert 'not measured' in table_notes.calibration_line(
    calibration_tables.calibration_note()
  )


def test_calibration_modes_follow_what_was_measured():
  m = measurements.Measured
  assert calibration_tables.calibration_mode(m()) == 'video'
  assert (
    calibration_tables.calibration_mode(m(wind_speed=3.0, wind_speed_sd=0.06))
    == 'known wind'
  )
  both = m(wind_speed=3.0, wind_speed_sd=0.06, area_weight=0.2, area_weight_sd=0.004)
  assert calibration_tables.calibration_mode(both) is None
  assert calibration_tables.calibration_mode(
    m(area_weight=0.2, area_weight_sd=0.004)
  ) == ('known area weight')
  assert calibration_tables.calibration_mode(m(), joint=True) == 'joint pair'
  wind = m(wind_speed=3.0, wind_speed_sd=0.06)
  assert (
    calibration_tables.calibration_mode(wind, joint=True) == 'joint pair, known winds'
  )
  assert (
    calibration_tables.calibration_mode(
      m(area_weight=0.2, area_weight_sd=0.004), joint=True
    )
    is None
  )
  strip = m(bending_length=0.03, bending_length_sd=0.0012, bending_length_dof=4.0)
  assert calibration_tables.calibration_mode(strip) == 'bending length'
  assert calibration_tables.calibration_mode(dataclasses.replace(strip, wind_speed=3.0,
                                                     wind_speed_sd=0.06)) == (
    'known wind, bending length'
  )  # fmt: skip
  # a ruler's reading (Gaussian) has modes of its own
  ruler = dataclasses.replace(strip, bending_length_dof=0.0)
  assert calibration_tables.calibration_mode(ruler) == 'bending length (ruler)'
  assert (
    calibration_tables.calibration_mode(
      dataclasses.replace(ruler, wind_speed=3.0, wind_speed_sd=0.06)
    )
    == 'known wind, bending length (ruler)'
  )
  assert calibration_tables.calibration_mode(strip, joint=True) is None
  scale = dataclasses.replace(strip, area_weight=0.2, area_weight_sd=0.004)
  assert calibration_tables.calibration_mode(scale) is None


def test_a_group_of_recordings_shares_bending_and_area_weight_not_wind():
  config = calibration.Config(pairs=4, seed=3)
  space = physsim.search_space(config.material)
  u = physsim.to_unit(calibration.truths(config, group=3), space).reshape(4, 3, 3)
  assert np.all(u[:, :, [0, 2]] == u[:, :1, [0, 2]])  # shared within a group
  assert np.all(np.abs(np.diff(u[:, :, 1], axis=1)) > 1e-6)  # a wind each
  assert np.all(np.abs(u) <= 1 + 1e-9)
  pairs = physsim.to_unit(calibration.truths(config), space).reshape(4, 2, 3)
  assert np.all(pairs[:, 1, [0, 2]] == pairs[:, 0, [0, 2]])
  with pytest.raises(ValueError, match='two or more'):
    calibration.truths(config, group=1)


def _recalibrated_file(tmp_path, monkeypatch) -> dict:
  levels = {mode: [[0.01] * 4, [0.1] * 4, [0.4] * 4, [0.9] * 4, [0.99] * 4]
            for mode in calibration.MODES}  # fmt: skip
  held = {mode: {f: {'interval_50': 0.5, 'interval_90': 0.9} for f in calibration.FIELDS}
          for mode in calibration.MODES}  # fmt: skip
  cal = {
    'n': 200, 'setting': 'gibbs likelihood, sharpness 0.7, demo-size', 'likelihood': 'gibbs',
    'sharpness': 0.7, 'coverage': held['video'], 'held_out': held,
    'recalibration': {'probs': list(bo.calibration.PROBS), 'fields': list(calibration.FIELDS),
                      'modes': levels, 'n_calibration_recordings': 200, 'measured_sd': 0.02},
  }  # fmt: skip
  path = tmp_path / 'calibration.json'
  path.write_text(json.dumps(cal))
  monkeypatch.setattr(calibration_tables, 'CALIBRATION_FILE', str(path))
  return cal


def test_a_matching_estimate_gets_its_modes_recalibrated_levels(tmp_path, monkeypatch):
  _recalibrated_file(tmp_path, monkeypatch)
  m = measurements.Measured
  note = calibration_tables.calibration_note(PSD_ESTIMATE.replace(sharpness=0.7))
  assert note['recalibrated'] and note['mode'] == 'video'
  assert note['levels']['wind_speed'] == [0.01, 0.1, 0.4, 0.9, 0.99]
  assert 'recalibrated on 200' in table_notes.calibration_line(note)
  wind = PSD_ESTIMATE.replace(
    sharpness=0.7, measured=m(wind_speed=3.0, wind_speed_sd=0.06)
  )
  assert calibration_tables.calibration_note(wind)['mode'] == 'known wind'
  # A reading five times less certain than the calibrated 2% is another mode.
  loose = PSD_ESTIMATE.replace(
    sharpness=0.7, measured=m(wind_speed=3.0, wind_speed_sd=0.3)
  )
  note = calibration_tables.calibration_note(loose)
  assert note['matches'] is False and 'uncertainty' in note['differs'][0]
  joint = calibration_tables.calibration_note(
    PSD_ESTIMATE.replace(sharpness=0.7), joint=True, recordings=3
  )
  assert joint['matches'] is False
  assert calibration_tables.calibration_note(PSD_ESTIMATE.replace(sharpness=0.7), joint=True,
                                 recordings=2)['mode'] == 'joint pair'  # fmt: skip
  # A joint pair with a wind reading at each: its own tables, when calibrated.
  assert calibration_tables.calibration_note(wind, joint=True, recordings=2)[
    'mode'
  ] == ('joint pair, known winds')
  cal = json.loads((tmp_path / 'calibration.json').read_text())
  del cal['recalibration']['modes']['joint pair, known winds']
  (tmp_path / 'calibration.json').write_text(json.dumps(cal))
  older = calibration_tables.calibration_note(wind, joint=True, recordings=2)
  assert older['matches'] is False
  assert older['differs'] == ['joint pair, known winds (not in this calibration)']
  assert (
    calibration_tables.calibration_note(wind)['mode'] == 'known wind'
  )  # still there


def test_a_network_weaker_than_the_calibrations_is_said_to_be(tmp_path, monkeypatch):
  cal = _recalibrated_file(tmp_path, monkeypatch)
  cal['network'] = {'seeds': [0, 1], 'triplet_accuracy': [0.71, 0.88]}
  (tmp_path / 'calibration.json').write_text(json.dumps(cal))
  config = PSD_ESTIMATE.replace(sharpness=0.7)
  within = calibration_tables.calibration_note(config, accuracy=0.75)
  assert within['recalibrated'] and 'weaker_network' not in within
  weak = calibration_tables.calibration_note(config, accuracy=0.66)
  assert weak['recalibrated']  # the tables still apply: same recipe
  assert weak['weaker_network'] == {'accuracy': 0.66, 'calibrated': [0.71, 0.88]}
  line = table_notes.calibration_line(weak)
  assert '(66%) is below' in line and '(71-88%)' in line
  assert 'below' not in table_notes.calibration_line(within)


def test_recalibrated_summaries_read_the_defensive_mixture_at_the_levels():
  space = physsim.search_space('gray_interlock')
  rng = np.random.default_rng(0)
  post = np.clip(0.3 + 0.1 * rng.standard_normal((4000, 3)), -1, 1)
  prior = rng.uniform(-1, 1, (4000, 3))
  lv = [0.01, 0.1, 0.4, 0.9, 0.99]
  levels = {f: lv for f in (*calibration.FIELDS,)}
  got = posterior_lib.summarise(post, space, prior, levels)
  mix = bo.calibration.defensive(
    calibration._physical_with_ratio(post, space),
    calibration._physical_with_ratio(prior, space),
  )
  for i, f in enumerate(calibration.FIELDS):
    q = np.quantile(mix[:, i], lv)
    np.testing.assert_allclose(got[f]['interval_90'], q[[0, 4]], rtol=1e-12)
    np.testing.assert_allclose(got[f]['interval_50'], q[[1, 3]], rtol=1e-12)
    assert got[f]['median'] == pytest.approx(q[2], rel=1e-12)
  # Weight 0: the prior's own least-error point; 1: the posterior's.
  zero = posterior_lib.summarise(post, space, prior, levels, dict.fromkeys(levels, 0.0))
  prior_phys = calibration._physical_with_ratio(prior, space)
  for i, f in enumerate(calibration.FIELDS):
    loss = 'factor' if f == 'bending_scale' else 'relative'
    assert zero[f]['bayes'] == pytest.approx(
      bo.calibration.bayes_point(prior_phys[:, i], loss), rel=1e-12
    )
    assert got[f]['bayes_weight'] == 1.0 and zero[f]['bayes_weight'] == 0.0
  plain = posterior_lib.summarise(post, space, prior)  # nominal levels, no mixture
  w = np.quantile(calibration._physical_with_ratio(post, space)[:, 1], [0.05, 0.95])
  np.testing.assert_allclose(plain['wind_speed']['interval_90'], w, rtol=1e-12)


def test_without_calibration_an_uninformed_quantity_takes_the_priors_point():
  # No calibrated weights: a quantity whose posterior is as wide as the prior
  # (wind here: drawn like the prior, but leaning high) reports the prior's own
  # least-error point (weight 0); an informed one (area weight, sd 0.05 of the
  # unit box) its posterior's (weight 1).
  space = physsim.search_space('gray_interlock')
  rng = np.random.default_rng(1)
  prior = rng.uniform(-1, 1, (20000, 3))
  post = rng.uniform(-1, 1, (20000, 3))
  post[:, 1] = np.concatenate([rng.uniform(-1, 1, 15000), rng.uniform(0, 1, 5000)])
  post[:, 2] = np.clip(0.4 + 0.05 * rng.standard_normal(20000), -1, 1)
  got = posterior_lib.summarise(post, space, prior)
  prior_phys = calibration._physical_with_ratio(prior, space)
  post_phys = calibration._physical_with_ratio(post, space)
  wind = got['wind_speed']
  assert 1.0 / wind['narrowing_90'] >= bo.calibration.UNINFORMED
  assert wind['bayes_weight'] == 0.0
  assert wind['bayes'] == pytest.approx(
    bo.calibration.bayes_point(prior_phys[:, 1], 'relative'), rel=1e-12
  )
  # the posterior's own point leans high: the rule made a difference
  assert bo.calibration.bayes_point(post_phys[:, 1], 'relative') > wind['bayes'] * 1.05
  weight = got['area_weight']
  assert 1.0 / weight['narrowing_90'] < 0.5 and weight['bayes_weight'] == 1.0
  assert weight['bayes'] == pytest.approx(
    bo.calibration.bayes_point(post_phys[:, 2], 'relative'), rel=1e-12
  )
  # Calibrated weights, when given, are used as they are.
  ones = dict.fromkeys(calibration.FIELDS, 1.0)
  trusted = posterior_lib.summarise(post, space, prior, weights=ones)
  assert trusted['wind_speed']['bayes_weight'] == 1.0
  # The wind's and the load ratio's own point is their median (absolute log
  # error), the others' the least percent (bending: factor) error's.
  for i, f in enumerate(calibration.FIELDS):
    own = bo.calibration.bayes_point(post_phys[:, i], posterior_lib.POINT_LOSS[f])
    assert trusted[f]['bayes'] == pytest.approx(own, rel=1e-12)
  for f in ('wind_speed', 'load_ratio'):
    assert trusted[f]['bayes'] == pytest.approx(trusted[f]['median'], rel=2e-3)
  # here the percent error's action sits lower on the wind's wide posterior
  low = bo.calibration.bayes_point(post_phys[:, 1], 'relative')
  assert low < 0.95 * trusted['wind_speed']['bayes']


def test_saved_runs_read_back_a_workdirs_estimates(tmp_path):
  # The analysis can run apart from the searches (--analyse_only).
  with pytest.raises(ValueError, match='no finished estimates'):
    calibration.saved_runs(str(tmp_path))
  config = calibration.Config(
    pairs=2, estimate=PSD_ESTIMATE.replace(posterior_grid=GRID)
  )
  runs = _fake_runs(config, str(tmp_path / 'estimates'))
  for r in runs[:3]:  # the fourth has no estimate.json: not finished
    with open(os.path.join(r['workdir'], layout.ESTIMATE_FILE), 'w') as f:
      json.dump({'truth': r['truth']}, f)
  got = calibration.saved_runs(str(tmp_path))
  assert [r['seq'] for r in got] == [0, 1, 2]
  assert got[1]['truth'] == runs[1]['truth']


def _tables(sharpness: float, seed: int = 0) -> dict:
  """A calibration that reads every mode's posterior at the nominal levels,
  with full weight on the posterior's point (right at the exact sharpness)."""
  nominal = np.repeat(
    bo.calibration.nominal_levels()[:, None], len(calibration.FIELDS), axis=1
  )
  held = {m: {f: {'interval_50': 0.5, 'interval_90': 0.9} for f in calibration.FIELDS}
          for m in calibration.MODES}  # fmt: skip
  return {
    'n': 200, 'setting': f'gibbs likelihood, sharpness {sharpness:g}, exact',
    'likelihood': 'gibbs', 'sharpness': sharpness, 'held_out': held,
    'recalibration': {
      'fields': list(calibration.FIELDS),
      'modes': {m: nominal.tolist() for m in calibration.MODES},
      'weights': {m: dict.fromkeys(calibration.FIELDS, 1.0) for m in calibration.MODES},
      'n_calibration_recordings': 200, 'measured_sd': 0.02,
    },
    'config': {'seed': seed},
  }  # fmt: skip


def test_check_holds_an_exact_calibration_and_catches_a_too_sharp_one(tmp_path):
  # New recordings (another seed and noise) read with tables calibrated
  # elsewhere: the exact likelihood's intervals hold the truth as often as
  # they say; a four-times sharper one's are caught short.
  config = calibration.Config(
    pairs=60, seed=1, estimate=PSD_ESTIMATE.replace(posterior_grid=GRID)
  )  # fmt: skip
  runs = _fake_runs(config, str(tmp_path), noise_seed=2)
  good = calibration_check.check_analysis(config, runs, _tables(C_TRUE))
  bad = calibration_check.check_analysis(config, runs, _tables(4.0))
  # 120 recordings in 60 pairs: binomial sd 0.027 at 90%, 0.046 at 50%; the
  # pairs' shared parameters add to it; 3.5 sd.
  for mode in calibration.MODES:
    assert good[mode]['n'] == 120, mode
    for f in calibration.FIELDS:
      c = good[mode][f]
      assert abs(c['interval_90'] - 0.9) < 0.095, (mode, f)
      assert abs(c['interval_50'] - 0.5) < 0.16, (mode, f)
      lo, hi = c['interval_90_ci']
      assert lo < c['interval_90'] < hi or c['interval_90'] == 1.0, (mode, f)
      hist = c['recalibrated_rank_histogram']  # ranks in [0.1, 0.9]: 80%
      assert sum(hist) == 120 and abs(sum(hist[1:9]) / 120 - 0.8) < 0.11, (mode, f)
  for f in physsim.Params._fields:
    assert bad['video'][f]['interval_90'] < 0.8, f
    assert bad['video'][f]['interval_90_ci'][1] < 0.9, f  # significantly short
    # The prior's own intervals on the same truths (drawn from the prior):
    # about as often as they say; 60 pairs share bending and area weight.
    assert abs(good['video'][f]['prior_interval_90'] - 0.9) < 0.12, f
  # Network by network (pairs take the five networks in turn): 24 each.
  nets = good['video']['per_network']
  assert len(nets) == config.networks
  assert sum(c['n'] for c in nets.values()) == 120
  # Fabric by fabric: every recording counted once, each fabric's coverage
  # that of its own recordings (one fabric here: the mode's own).
  fab = good['video']['by_material']
  assert sum(c['n'] for c in fab.values()) == 120
  for m, c in fab.items():
    if c['n'] == 120:
      for f in calibration.FIELDS:
        assert c[f]['interval_90'] == good['video'][f]['interval_90'], (m, f)
  assert 'network by network' in calibration_check.check_table({
    'shipped': {**_tables(C_TRUE), 'held_out': {}}, 'n': 120, 'seed': 1,
    'printed': {'n': 120, 'recalibrated': 120, **{f: {
      'interval_50': 0.5, 'interval_50_ci': [0.4, 0.6], 'interval_90': 0.9,
      'interval_90_ci': [0.8, 0.95], 'estimate_error': 1.0,
      'range_centre_error': 2.0} for f in calibration.FIELDS}},
    'modes': good, 'config': {'network_seed': 0},
  })  # fmt: skip


def test_check_reports_what_the_estimates_printed(tmp_path, monkeypatch):
  config = calibration.Config(
    pairs=5, seed=3, estimate=PSD_ESTIMATE.replace(posterior_grid=GRID)
  )
  shipped = tmp_path / 'calibration.json'
  shipped.write_text(json.dumps(_tables(C_TRUE, seed=3)))
  with pytest.raises(ValueError, match="seed 3 is the calibration's own"):
    calibration_check.check(
      config, str(tmp_path / 'w'), str(shipped), analyse_only=True
    )
  shipped.write_text(json.dumps(_tables(C_TRUE, seed=0)))
  runs = _fake_runs(config, str(tmp_path / 'w' / 'estimates'))
  # What the estimates printed, by hand: 9 of 10 90% intervals and 4 of 10 50%
  # intervals hold the truth; 8 of 10 applied the tables.
  for r in runs:
    k = r['seq']
    covered = {
      f: {'interval_50': k < 4, 'interval_90': k < 9} for f in calibration.FIELDS
    }
    errors = {'estimate': {'wind_speed_pct': 10.0 * k, 'area_weight_pct': 5.0,
                           'bending_factor': 2.0, 'load_ratio_pct': 1.0},
              'range_centre': {'wind_speed_pct': 40.0, 'area_weight_pct': 9.0,
                               'bending_factor': 4.0, 'load_ratio_pct': 100.0}}  # fmt: skip
    est = {'truth': r['truth'], 'covered': covered, 'errors': errors,
           'calibration': {'matches': k < 8, 'recalibrated': True},
           'recording': f'rec/{k:04d}', 'material': 'gray_interlock',
           'estimate': {'wind_speed': {'interval_90': [1.0, 2.0]}}}  # fmt: skip
    with open(os.path.join(r['workdir'], layout.ESTIMATE_FILE), 'w') as f:
      json.dump(est, f)
  out = calibration_check.check(
    config, str(tmp_path / 'w'), str(shipped), analyse_only=True
  )
  pr = out['printed']
  assert pr['n'] == 10 and pr['recalibrated'] == 8
  assert (
    pr['wind_speed']['interval_90'] == 0.9 and pr['load_ratio']['interval_50'] == 0.4
  )
  assert pr['wind_speed']['estimate_error'] == pytest.approx(45.0)  # mean of 0..90
  # confidently wrong: more than 25% off and outside the 90% interval (only the
  # last: 90% off; 30-80% off held the truth)
  assert [m['recording'] for m in pr['confident_misses']] == ['rec/0009']
  np.testing.assert_allclose(
    pr['bending_scale']['interval_90_ci'], bo.calibration.binomial_interval(9, 10)
  )
  assert set(out['modes']) == set(calibration.MODES)
  saved = json.loads((tmp_path / 'w' / calibration_check.CHECK_FILE).read_text())
  assert saved['printed'] == pr and saved['n'] == 10
  text = (tmp_path / 'w' / 'check.md').read_text()
  assert '| video, as printed | wind_speed | 40% [' in text
  assert 'interval, as printed: 1 of 10; gray_interlock (0009): 90.0% off' in text
  # The same analysis from packed posteriors (another machine): no estimate.json
  # to read, so nothing printed is reported, and the modes are the same.
  calibration.pack_runs(
    calibration.saved_runs(str(tmp_path / 'w')), str(tmp_path / 'p')
  )
  packed = calibration_check.check(
    config, str(tmp_path / 'p'), str(shipped), analyse_only=True
  )
  assert packed['printed'] is None and set(packed['modes']) == set(out['modes'])
  assert 'read from packed posteriors' in (tmp_path / 'p' / 'check.md').read_text()
  # Checked with a reading (estimates given an anemometer's): the printed
  # intervals are that mode's, and only that mode is read from the GPs (the
  # searches were steered by the reading).
  knw = dataclasses.replace(config, check_reading='wind_speed')
  out_w = calibration_check.check(
    knw, str(tmp_path / 'w'), str(shipped), analyse_only=True
  )
  assert set(out_w['modes']) == {'known wind'} and out_w['printed'] == pr
  assert out_w['printed_mode'] == 'known wind'
  assert (
    '| known wind, as printed | wind_speed | 40% ['
    in (tmp_path / 'w' / 'check.md').read_text()
  )
  # The reading each estimate gets is the one the analysis's mode applies.
  truth = runs[3]['truth']
  est = calibration.with_reading(knw, PSD_ESTIMATE, 'wind_speed', truth, 3)
  assert est.measured == measurements.simulated_reading(
    'wind_speed', truth, knw.measured_sd, knw.seed, 3
  )
  assert calibration.with_reading(knw, PSD_ESTIMATE, 'none', truth, 3) == PSD_ESTIMATE
  assert '8 of 10 estimates applied' in text
  assert (tmp_path / 'w' / 'check_ranks.png').stat().st_size > 0
  # An estimate without intervals (the paper's argmin) cannot be checked.
  est = json.loads(open(os.path.join(runs[0]['workdir'], layout.ESTIMATE_FILE)).read())
  del est['covered']
  with open(os.path.join(runs[0]['workdir'], layout.ESTIMATE_FILE), 'w') as f:
    json.dump(est, f)
  with pytest.raises(ValueError, match='no credible intervals'):
    calibration_check.printed(calibration.saved_runs(str(tmp_path / 'w')))


# ------------------------------------------------- networks and their recipe


def _fake_network(root, *, seed=0, epochs=10, backend='c', accuracy=0.8, dataset=True):
  """A trained run's files as training writes them (no checkpoint: the
  recipe and the study's record read only these)."""
  data = root / 'data'
  data.mkdir(parents=True)
  if dataset:
    (data / 'dataset.json').write_text(json.dumps({
      'seed': seed, 'config': {'sequences': 24, 'frames': 16, 'seed': seed,
                               'backend': backend, 'batch_size': 8},
      'pose_ranges': {'distance': [1.8, 2.5]},
    }))  # fmt: skip
  run = root / 'model' / 'gray_interlock'
  run.mkdir(parents=True)
  (run / 'config.json').write_text(json.dumps(
    {'epochs': epochs, 'learning_rate': 1e-3, 'seed': seed, 'log_every': 50}
  ))  # fmt: skip
  (run / 'inputs.json').write_text(json.dumps({
    'modality': 'depth', 'input_mode': 'relative', 'materials': ['gray_interlock'],
    'dataset': str(data),
  }))  # fmt: skip
  (run / 'metrics.jsonl').write_text(json.dumps(
    {'epoch': epochs, 'eval': True, 'test_triplet_accuracy': accuracy}
  ) + '\n')  # fmt: skip
  return str(run)


def test_a_networks_recipe_is_how_it_was_made_apart_from_its_seeds(tmp_path):
  from experiments.pipeline import embedding

  a = embedding.network_recipe(_fake_network(tmp_path / 'a'))
  # Another seed, simulated on another backend: the same recipe.
  b = embedding.network_recipe(_fake_network(tmp_path / 'b', seed=3, backend='mjx'))
  assert a == b and embedding.recipe_differences(a, b) == []
  longer = embedding.network_recipe(_fake_network(tmp_path / 'c', epochs=20))
  assert embedding.recipe_differences(longer, a) == ['training.epochs']
  gone = embedding.network_recipe(_fake_network(tmp_path / 'd', dataset=False))
  assert gone['data'] is None and embedding.recipe_differences(gone, a) == ['data']
  with pytest.raises(ValueError, match='not a trained run'):
    embedding.network_recipe(str(tmp_path / 'a' / 'data'))


def test_the_tables_apply_only_to_a_network_of_their_recipe(tmp_path, monkeypatch):
  from experiments.pipeline import embedding

  cal = _recalibrated_file(tmp_path, monkeypatch)
  mine = embedding.network_recipe(_fake_network(tmp_path / 'a'))
  config = PSD_ESTIMATE.replace(sharpness=0.7)
  # A calibration that recorded no recipe checks none.
  assert calibration_tables.calibration_note(config, network=mine)['recalibrated']
  cal['network'] = {'recipe': mine, 'seeds': [0, 1]}
  (tmp_path / 'calibration.json').write_text(json.dumps(cal))
  other_seed = embedding.network_recipe(_fake_network(tmp_path / 'b', seed=7))
  note = calibration_tables.calibration_note(config, network=other_seed)
  assert note['recalibrated'] and note['networks'] == 2
  assert 'recordings of networks held out' in table_notes.calibration_line(note)
  longer = embedding.network_recipe(_fake_network(tmp_path / 'c', epochs=20))
  note = calibration_tables.calibration_note(config, network=longer)
  assert note['matches'] is False
  assert note['differs'] == ['network recipe (training.epochs)']
  assert 'network recipe (training.epochs)' in table_notes.calibration_line(note)
  assert 'levels' not in note  # nothing for the estimate to apply


def test_with_as_many_folds_as_networks_each_fold_is_one_networks(tmp_path):
  config = calibration.Config(pairs=10, networks=5, folds=5, network_seed=3)
  assert calibration.network_seeds(config) == (3, 4, 5, 6, 7)
  for seq in range(2 * config.pairs):
    assert calibration.network_of(config, seq) == calibration.fold_of(seq, config.folds)
    # a pair shares bending and area weight: one network reads both
    assert calibration.network_of(config, seq) == calibration.network_of(
      config, seq ^ 1
    )
  used = [calibration.network_of(config, s) for s in range(2 * config.pairs)]
  assert sorted(set(used)) == [0, 1, 2, 3, 4] and used.count(0) == 4
  # One network keeps the demo's layout; several get a folder per seed.
  one = calibration.Config(networks=1)
  assert calibration.network_dirs(one, 'w', 0) == ('w/data', 'w/model')
  assert calibration.network_dirs(config, 'w', 1) == (
    'w/networks/4/data',
    'w/networks/4/model',
  )


def test_the_study_records_its_networks_and_refuses_mixed_recipes(tmp_path):
  config = calibration.Config(networks=2, network_seed=3)
  for k, acc in enumerate((0.8, 0.7)):
    _, model = calibration.network_dirs(config, str(tmp_path), k)
    _fake_network(
      tmp_path / 'networks' / str(3 + k), seed=3 + k, accuracy=acc
    )  # fmt: skip
    assert os.path.isdir(model)
  rec = calibration.networks_record(config, str(tmp_path))
  assert rec['seeds'] == [3, 4] and rec['triplet_accuracy'] == [0.8, 0.7]
  assert rec['recipe']['training']['epochs'] == 10
  lines = calibration._network_lines(rec, {'cross_validated_by_fold': {'gibbs': [
    {f: {'interval_50': 0.5, 'interval_90': 0.9} for f in calibration.FIELDS},
    {f: {'interval_50': 0.4, 'interval_90': 0.8} for f in calibration.FIELDS},
  ]}})  # fmt: skip
  text = '\n'.join(lines)
  assert '3: 80%, 4: 70%' in text and '| 4 | 40% / 80% |' in text
  cfg = tmp_path / 'networks' / '4' / 'model' / 'gray_interlock' / 'config.json'
  cfg.write_text(json.dumps({'epochs': 5, 'learning_rate': 1e-3, 'seed': 4}))
  with pytest.raises(ValueError, match='another recipe'):
    calibration.networks_record(config, str(tmp_path))


def test_packed_runs_carry_what_the_analysis_reads(tmp_path):
  config = calibration.Config(
    pairs=30, estimate=PSD_ESTIMATE.replace(posterior_grid=GRID)
  )
  runs = _fake_runs(config, str(tmp_path / 'estimates'))  # 60: two packed files
  written = calibration.pack_runs(runs, str(tmp_path / 'study'))
  assert [os.path.basename(p) for p in written] == ['runs-000.npz', 'runs-001.npz']
  back = calibration.saved_runs(str(tmp_path / 'study'))  # no estimates: the packs
  assert [r['seq'] for r in back] == [r['seq'] for r in runs]
  for r, b in zip(runs, back, strict=True):
    assert b['truth'] == r['truth']
    want, got = calibration._saved(r), calibration._saved(b)
    for k in ('gp_mean', 'gp_var', 'floor', 'noise_sd'):
      np.testing.assert_allclose(got[k], want[k], rtol=1e-6)  # float32
  with pytest.raises(ValueError, match='nor packed'):
    calibration.saved_runs(str(tmp_path / 'empty'))


def test_an_estimate_applies_the_calibration_file_it_is_given(tmp_path, monkeypatch):
  cal = _recalibrated_file(tmp_path, monkeypatch)
  mine = tmp_path / 'mine.json'
  cal['recalibration']['n_calibration_recordings'] = 77
  mine.write_text(json.dumps(cal))
  monkeypatch.setattr(
    calibration_tables, 'CALIBRATION_FILE', str(tmp_path / 'none.json')
  )
  assert (
    calibration_tables.calibration_note(PSD_ESTIMATE.replace(sharpness=0.7)) is None
  )
  note = calibration_tables.calibration_note(
    PSD_ESTIMATE.replace(sharpness=0.7, calibration=str(mine))
  )
  assert note['recalibrated'] and note['n_calibration_recordings'] == 77
  with pytest.raises(ValueError, match='missing.json'):
    PSD_ESTIMATE.replace(calibration=str(tmp_path / 'missing.json')).check()


def test_a_corrupt_packed_file_is_named(tmp_path):
  (tmp_path / 'packed').mkdir()
  (tmp_path / 'packed' / 'runs-000.npz').write_bytes(b'not an npz')
  with pytest.raises(ValueError, match='runs-000.npz: not a file of packed runs'):
    calibration.saved_runs(str(tmp_path))
