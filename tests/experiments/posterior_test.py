"""experiments.pipeline.posterior: readings, the prior they make, and the joint."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import bo
import physsim
from experiments.pipeline import files, measurements, posterior, units

SPACE = physsim.SearchSpace()  # wind 1-6 m/s, area weight 0.1-0.37 kg/m^2


@pytest.mark.parametrize(
  'reading, message',
  [
    (
      dict(wind_speed=-3.0, wind_speed_sd=0.1),
      r'--wind_speed=-3.0: a reading must be > 0',
    ),
    (dict(wind_speed=3.0), r'--wind_speed=3.0 needs --wind_speed_sd > 0'),
    (dict(area_weight=0.9, area_weight_sd=0.01), r'outside the search range'),
    (
      dict(area_weight_sd=1e300),
      r'--area_weight_sd=1e\+300 was given without --area_weight',
    ),
  ],
)
def test_readings_are_refused_with_their_own_reason(reading, message):
  with pytest.raises(ValueError, match=message):
    measurements.Measured(**reading).check(SPACE)


def test_a_reading_in_range_passes():
  measurements.Measured(wind_speed=3.0, wind_speed_sd=0.06).check(SPACE)


def test_the_prior_is_a_gaussian_of_the_reading_in_physical_units():
  """log prior at the box centre and one reading sd away, by hand."""
  measured = measurements.Measured(wind_speed=3.5, wind_speed_sd=0.25)
  # Unit cube -> wind 1 + (u + 1) / 2 * 5: u = 0 is 3.5 m/s, u = 0.1 is 3.75.
  points = np.array([[0.0, 0.0, 0.0], [0.0, 0.1, 0.0]])
  lp = measurements.log_prior(points, SPACE, measured)
  np.testing.assert_allclose(lp, [0.0, -0.5], atol=1e-12)
  assert np.all(measurements.log_prior(points, SPACE, measurements.Measured()) == 0.0)


def test_simulated_readings_repeat_by_seed_and_recording():
  truth = {'bending_scale': 1.0, 'wind_speed': 3.0, 'area_weight': 0.2}
  a = measurements.simulated_reading('wind_speed', truth, 0.02, seed=4, seq=7)
  assert a == measurements.simulated_reading('wind_speed', truth, 0.02, seed=4, seq=7)
  assert a.wind_speed_sd == pytest.approx(0.06)
  assert abs(a.wind_speed - 3.0) < 5 * 0.06
  assert a != measurements.simulated_reading('wind_speed', truth, 0.02, seed=4, seq=8)
  with pytest.raises(ValueError, match="no instrument reads 'bending_scale'"):
    measurements.simulated_reading('bending_scale', truth, 0.02, seed=4, seq=7)


def test_the_picture_draws_the_intervals_the_table_prints(tmp_path, monkeypatch):
  """The load ratio's iso-lines are the summary's (recalibrated) 90% interval
  and median, not the draws' raw quantiles; the point is marked."""
  figs = []
  monkeypatch.setattr(
    posterior.files, 'savefig', lambda fig, path, dpi=100: figs.append(fig)
  )
  rng = np.random.default_rng(0)
  samples = rng.uniform(-0.3, 0.3, (400, 3))
  prior = rng.uniform(-1, 1, (400, 3))
  entry = lambda m, lo, hi: {
    'median': m, 'bayes': 1.1 * m, 'interval_50': [0.9 * m, 1.1 * m], 'interval_90': [lo, hi]
  }  # fmt: skip
  summary = {
    'bending_scale': entry(1.0, 0.5, 2.0), 'wind_speed': entry(3.5, 3.0, 4.0),
    'area_weight': entry(0.23, 0.2, 0.26), 'load_ratio': entry(5.6, 4.1, 7.3),
  }  # fmt: skip
  posterior.plot(samples, prior, SPACE, None, str(tmp_path / 'p.png'),
                 title='gray_interlock: posterior given rec_7', summary=summary,
                 point='bayes')  # fmt: skip
  (fig,) = figs
  ax = fig.axes[4]  # wind x area weight
  drawn = []
  for line in ax.get_lines():
    if line.get_linestyle() == '--':
      v, w = line.get_data()
      drawn.append(float(np.median(v**2 / (9.81 * w))))  # rho = 1
  np.testing.assert_allclose(sorted(drawn), [4.1, 5.6, 7.3], rtol=1e-9)
  marks = [line.get_data() for line in ax.get_lines() if line.get_marker() == 'x']
  np.testing.assert_allclose(
    np.ravel(marks), [3.85, 0.253], rtol=1e-9
  )  # the Bayes point
  assert fig._suptitle.get_text().endswith('rec_7')


def test_the_picture_reads_in_the_tables_units():
  """Given the table's units (``units.in_units``), the picture's axes are
  bending rigidity in uN m and area weight in g/m^2, not the search's scales:
  the labels the table's, the draws, the point, the truth and the box each
  times the table's factor; the load ratio's iso-lines still rho v^2 / (w g)."""
  space = physsim.search_space('gray_interlock')
  names, factors = units.in_units('gray_interlock')
  assert factors['bending_scale'] == pytest.approx(1e6 * space.rigidity)
  assert factors['area_weight'] == 1e3
  rng = np.random.default_rng(1)
  samples = rng.uniform(-0.3, 0.3, (400, 3))
  prior = rng.uniform(-1, 1, (400, 3))
  summary = posterior.summarise(samples, space, prior)
  truth = {'bending_scale': 1.2, 'wind_speed': 3.0, 'area_weight': 0.2}
  fig = posterior.figure(samples, prior, space, truth, summary=summary,
                         point='bayes', units=(names, factors))  # fmt: skip
  bending, wind, weight, _, pair = fig.axes[:5]
  assert bending.get_xlabel() == 'bending rigidity (uN m)'
  assert weight.get_xlabel() == 'area weight (g/m^2)' == pair.get_ylabel()
  assert wind.get_xlabel() == 'wind (m/s)' == pair.get_xlabel()
  for ax, name in ((bending, 'bending_scale'), (weight, 'area_weight')):
    k = factors[name]
    drawn = {line.get_color(): line.get_xdata()[0] for line in ax.get_lines()}
    assert drawn['k'] == pytest.approx(k * summary[name]['bayes'], rel=1e-12)
    assert drawn['r'] == pytest.approx(k * truth[name], rel=1e-12)
    lo, hi = space.bounds()[posterior.FIELDS.index(name)]
    a, b = ax.get_xlim()
    assert k * lo / 2 < a < b < k * hi * 2, (name, a, b)  # margins: a log axis's wide
  (true,) = [line.get_data() for line in pair.get_lines() if line.get_marker() == '+']
  np.testing.assert_allclose(np.ravel(true), [3.0, 200.0], rtol=1e-12)
  ratios = [
    float(np.median(v**2 / (9.81 * w / 1e3)))  # w drawn in g/m^2
    for v, w in (line.get_data() for line in pair.get_lines())
    if len(v) > 1
  ]
  lr = summary['load_ratio']
  np.testing.assert_allclose(
    sorted(ratios), [lr['interval_90'][0], lr['median'], lr['interval_90'][1]],
    rtol=1e-9,
  )  # fmt: skip
  files.pyplot().close(fig)


# ------------------------------------------------ a cantilever's bending length

FABRIC = physsim.search_space('gray_interlock')  # its rigidity D0 with the box


def test_a_bending_length_reads_bending_from_the_area_weight_by_peirces_formula():
  # c = (b D0 / (w g))^(1/3) by hand: a fabric of bending 2 and 0.2 kg/m^2
  b, w = 2.0, 0.2
  c = (b * FABRIC.rigidity / (w * 9.81)) ** (1 / 3)
  assert physsim.params.bending_length(b, w, FABRIC.rigidity) == pytest.approx(
    c, rel=1e-12
  )
  # weighed to 1% and the bending length read to 2%: bending to about 6% (3 x 2%)
  m = measurements.Measured(area_weight=w, area_weight_sd=0.002, bending_length=c,
                         bending_length_sd=0.02 * c)  # fmt: skip
  m.check(FABRIC)
  points = posterior.prior_points(FABRIC, m)
  assert points['bending_scale'] == pytest.approx(b, rel=0.03)
  assert points['area_weight'] == pytest.approx(w, rel=0.01)
  # on the grid: the prior's mass sits where c holds, along b / w = const
  pts = np.stack(np.meshgrid(np.linspace(-1, 1, 41), [0.0], np.linspace(-1, 1, 41),
                             indexing='ij'), -1).reshape(-1, 3)  # fmt: skip
  without_scale = measurements.Measured(bending_length=c, bending_length_sd=0.02 * c)
  lp = measurements.log_prior(pts, FABRIC, without_scale)
  phys = measurements.physical(pts, FABRIC)
  best = phys[lp > lp.max() - 0.5]
  ratio = best[:, 0] / best[:, 2]  # b / w of the most probable cells
  assert np.all(np.abs(np.log(ratio / (b / w))) < np.log(1.25)), ratio


def test_prior_points_factor_a_bending_length_as_the_full_grid_does():
  """``prior_points`` takes the (bending x area weight) prior apart (each
  one's own terms on a line, the strip's reading by broadcasting): its points
  are those of ``log_prior`` on every point of the grid, to rounding."""
  n = 201
  m = measurements.Measured(wind_speed=3.0, wind_speed_sd=0.06, area_weight=0.2,
                         area_weight_sd=0.01, bending_length=0.02,
                         bending_length_sd=0.0006, bending_length_dof=10.0)  # fmt: skip
  got = posterior.prior_points(FABRIC, m, n=n)
  u = -1.0 + (2.0 * np.arange(n) + 1.0) / n
  b, w = np.meshgrid(u, u, indexing='ij')
  pts = np.stack([b.ravel(), np.zeros(n * n), w.ravel()], axis=1)
  lp = measurements.log_prior(pts, FABRIC, m).reshape(n, n)
  weight = np.exp(lp - lp.max())
  phys = measurements.physical(pts, FABRIC)
  for i, axis, nodes in ((0, 1, phys[::n, 0]), (2, 0, phys[:n, 2])):
    name = posterior.FIELDS[i]
    want = bo.calibration.bayes_point(
      nodes, posterior.ERROR_LOSS[name], weights=weight.sum(axis=axis)
    )
    assert got[name] == pytest.approx(want, rel=1e-12), name


# Quantiles of 20,000 draws against quadrature: about 1% in the median of a
# 6% wide distribution, and the cells' x1.47 would be off by up to x1.21.
_QUANTILE_TOL = 0.015


def test_draws_on_a_coarse_grid_follow_a_bending_length_within_their_cells():
  """The paper's grid has 12 bending cells (x1.47 each) and a strip reads c
  to 2%, b to about 6%: the cell-averaged prior and the within-cell draws
  (``refine_draws``) give the bending a posterior that matches a fine
  quadrature of the same prior, where the cells' centres alone could not."""
  b, w = 1.7, 0.2  # not at a cell's centre
  c = float(physsim.params.bending_length(b, w, FABRIC.rigidity))
  m = measurements.Measured(area_weight=w, area_weight_sd=0.004, bending_length=c,
                         bending_length_sd=0.02 * c)  # fmt: skip
  grid = (12, 4, 24)

  pts = np.asarray(bo.posterior.grid_points(grid))
  lp = measurements.log_prior(pts, FABRIC, m, grid)
  p = np.exp(lp - lp.max())
  rng = np.random.default_rng(0)
  idx = rng.choice(len(pts), 20000, p=p / p.sum())
  draws = pts[idx] + (rng.random((20000, 3)) - 0.5) * 2.0 / np.array(grid)
  refined = posterior.refine_draws(draws, grid, FABRIC, m, seed=1)
  got = np.quantile(measurements.physical(refined, FABRIC)[:, 0], [0.05, 0.5, 0.95])
  # the reference: the same prior on a fine (b, w) grid
  ub, uw = np.linspace(-1, 1, 2001), np.linspace(-1, 1, 401)
  bb, ww = np.meshgrid(ub, uw, indexing='ij')
  fine = np.stack([bb.ravel(), np.zeros(bb.size), ww.ravel()], axis=1)
  lpf = measurements.log_prior(fine, FABRIC, m).reshape(bb.shape)
  pb = np.exp(lpf - lpf.max()).sum(axis=1)
  bs = measurements.physical(fine[:: len(uw)], FABRIC)[:, 0]
  cdf = np.cumsum(pb) / pb.sum()
  want = np.interp([0.05, 0.5, 0.95], cdf, bs)
  np.testing.assert_allclose(got, want, rtol=_QUANTILE_TOL)
  assert want[0] < b < want[2]
  # the cells' centres alone: every draw's bending is one of 12 values
  centres = measurements.physical(pts[idx], FABRIC)[:, 0]
  assert len(np.unique(np.round(centres, 9))) <= 3
  assert len(np.unique(np.round(refined[:, 0], 9))) > 1000
  # without a bending length the draws are untouched
  plain = measurements.Measured(area_weight=w, area_weight_sd=0.004)
  np.testing.assert_array_equal(
    posterior.refine_draws(draws, grid, FABRIC, plain, seed=1), draws
  )


@pytest.mark.parametrize(
  'reading, message',
  [
    (dict(bending_length=0.02), r'--bending_length=0.02 needs --bending_length_sd'),
    (dict(bending_length=0.5, bending_length_sd=0.01), r'outside the search range'),
    (dict(bending_length_sd=0.01), r'given without --bending_length'),
  ],
)
def test_a_bad_bending_length_is_refused_naming_the_flag(reading, message):
  with pytest.raises(ValueError, match=message):
    measurements.Measured(**reading).check(FABRIC)


def test_a_bending_length_needs_a_box_that_knows_its_fabric():
  m = measurements.Measured(bending_length=0.02, bending_length_sd=0.002)
  with pytest.raises(ValueError, match='no reference rigidity'):
    m.check(SPACE)


# 20,000 draws know a standard deviation to about 1%; the grid's 200 w cells
# and the 9 Gauss-Hermite nodes add less.
_SD_TOL = 0.05


@pytest.mark.parametrize('shared', [0.0, 0.05])
def test_a_shared_discrepancy_keeps_the_joint_area_weight_from_narrowing(shared):
  """Three recordings, each with Gaussian evidence of sd s about one area
  weight: independent, their joint has sd s / sqrt(3); with a discrepancy
  common to all, of sd d in log area weight, the joint is about the
  convolution, sqrt(s^2 / 3 + (d w)^2), by hand."""
  lo, hi = 0.1, 0.3
  grid = (1, 1, 200)
  w = lo + (np.arange(200) + 0.5) / 200 * (hi - lo)
  w0, s = 0.2, 0.01
  ll = [-0.5 * ((w - w0) / s) ** 2 for _ in range(3)]
  prior = np.zeros(200)
  out = posterior.joint(ll, grid, prior, jax.random.key(0), n=20_000,
                        shared_bias_sd=shared, area_weight_range=(lo, hi))  # fmt: skip
  draws = lo + (out['samples'][0][:, 2] + 1) / 2 * (hi - lo)
  want = np.sqrt(s**2 / 3 + (shared * w0) ** 2)
  assert np.std(draws) == pytest.approx(want, rel=_SD_TOL)
  assert np.mean(draws) == pytest.approx(w0, abs=0.002)
  if shared:
    with pytest.raises(ValueError, match='area weight range'):
      posterior.joint(ll, grid, prior, jax.random.key(0), n=10, shared_bias_sd=shared)


def test_a_depth_readings_t_law_is_scipys_with_the_readings_sd():
  """The bending length's term with a t law: SciPy's log density of Student's
  t (its scale sd sqrt((dof - 2) / dof)), up to a constant, at bending
  values around the reading; 0 dof is the Gaussian."""
  from scipy import stats

  c0, sd, dof = 0.02, 0.0008, 4.0
  m = measurements.Measured(
    bending_length=c0, bending_length_sd=sd, bending_length_dof=dof
  )
  w = np.full(7, 0.2)
  b = np.geomspace(0.5, 2.0, 7)
  c = np.asarray(physsim.params.bending_length(b, w, FABRIC.rigidity))
  mine = measurements.length_term(b, w, FABRIC, m)
  want = stats.t.logpdf(c, dof, loc=c0, scale=sd * np.sqrt((dof - 2) / dof))
  np.testing.assert_allclose(mine - mine[0], want - want[0], rtol=1e-9, atol=1e-9)
  gauss = measurements.length_term(
    b, w, FABRIC, dataclasses.replace(m, bending_length_dof=0.0)
  )
  np.testing.assert_allclose(gauss, -0.5 * ((c - c0) / sd) ** 2, rtol=1e-12)
  m.check(FABRIC)


@pytest.mark.parametrize('dof', [1.0, 2.0, -3.0, float('nan'), float('inf'), 1e4])
def test_a_t_law_without_a_finite_variance_is_refused(dof):
  m = measurements.Measured(
    bending_length=0.02, bending_length_sd=0.001, bending_length_dof=dof
  )
  with pytest.raises(ValueError, match='--bending_length_dof'):
    m.check(FABRIC)


def test_simulated_t_readings_have_the_sd_they_say_and_gaussian_ones_are_unchanged():
  truth = {'bending_scale': 1.0, 'wind_speed': 3.0, 'area_weight': 0.2}
  c = float(physsim.params.bending_length(1.0, 0.2, FABRIC.rigidity))
  draw = lambda k, dof: measurements.simulated_reading(
    'bending_length', truth, 0.05, seed=1, seq=k, space=FABRIC, dof=dof
  )
  t = np.array([draw(k, 4.0).bending_length for k in range(20_000)]) / c - 1.0
  # the t of 4 dof scaled to sd 5%: its sample sd to a few percent (the
  # fourth moment is infinite: a looser bound than a Gaussian's), its
  # quartiles at +-0.741 sqrt(1/2) 5% (a Gaussian's would be at +-0.674 x 5%)
  assert np.std(t) == pytest.approx(0.05, rel=0.1)
  assert np.quantile(np.abs(t), 0.5) == pytest.approx(
    0.7407 * np.sqrt(0.5) * 0.05, rel=0.04
  )
  r = draw(3, 4.0)
  assert r.bending_length_dof == 4.0 and r.bending_length_sd == pytest.approx(0.05 * c)
  # dof 0: the Gaussian draw of before, the same number
  rng = np.random.default_rng([1, 13, 3, len(posterior.FIELDS)])
  assert draw(3, 0.0).bending_length == pytest.approx(
    c * (1 + 0.05 * rng.standard_normal())
  )
  assert draw(3, 0.0).bending_length_dof == 0.0
  with pytest.raises(ValueError, match='only a bending length'):
    measurements.simulated_reading('wind_speed', truth, 0.02, seed=1, seq=0, dof=4.0)
