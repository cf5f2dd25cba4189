"""physsim.cantilever: the heavy elastica of a strip overhanging a table,
against the small-deflection beam by hand and Peirce's cantilever relation."""

from __future__ import annotations

import numpy as np
import pytest

from physsim import cantilever

# Peirce's relation c = L (cos(a/2) / (8 tan a))^(1/3), a the angle from the
# edge to the free end, is his fit to the elastica near his test's angle
# (41.5 degrees, two bending lengths out): within a few percent there (at
# three bending lengths it is 6% off).
_PEIRCE_TOL = 0.03


def test_a_short_overhang_is_the_small_deflection_beam():
  # Euler-Bernoulli: a uniformly loaded cantilever's tip drops q L^4 / (8 D),
  # over L: (L / c)^3 / 8, and hardly moves in.
  reach, droop = cantilever.tip([0.1, 0.3])
  np.testing.assert_allclose(droop, np.array([0.1, 0.3]) ** 3 / 8, rtol=1e-4)
  np.testing.assert_allclose(reach, 1.0, atol=1e-5)


def test_peirces_relation_at_his_angle():
  # two bending lengths out: his 41.5 degree test; and one and three
  ratio = np.array([1.0, 2.0, 3.0])
  reach, droop = cantilever.tip(ratio)
  a = np.arctan2(droop, reach)
  peirce = (np.cos(a / 2) / (8 * np.tan(a))) ** (1 / 3)
  np.testing.assert_allclose(peirce[:2], 1 / ratio[:2], rtol=_PEIRCE_TOL)
  assert np.degrees(a[1]) == pytest.approx(41.5, abs=1.5)
  # a longer overhang droops further and reaches out less
  assert np.all(np.diff(reach) < 0) and np.all(np.diff(droop) > 0)


def test_the_bending_length_of_a_measured_reach():
  overhang = 0.05
  for c in (0.012, 0.025):
    reach = overhang * cantilever.tip(overhang / c)[0][0]
    assert cantilever.bending_length(overhang, reach) == pytest.approx(c, rel=1e-6)
  assert cantilever.rigidity(0.02, 0.2) == pytest.approx(0.2 * 9.81 * 0.02**3)


def test_out_of_range_is_refused():
  with pytest.raises(ValueError, match='bending lengths'):
    cantilever.tip(cantilever.MAX_RATIO * 1.1)
  with pytest.raises(ValueError, match='bending lengths'):
    cantilever.tip(np.nan)
  with pytest.raises(ValueError, match='reach of 0.06 m over an overhang of 0.05'):
    cantilever.bending_length(0.05, 0.06)


# The secant spread against a Monte-Carlo spread of the same ruler errors:
# 300 draws know a standard deviation to about 4%, and the secant is first
# order (c is convex in the reach), so 15%.
_SPREAD_TOL = 0.15


def test_a_rulers_spread_through_the_elastica():
  overhang, c, sd = 0.06, 0.025, 0.0015
  reach = overhang * cantilever.tip(overhang / c)[0][0]
  got, got_sd = cantilever.bending_length_sd(overhang, reach, sd, sd)
  assert got == pytest.approx(c, rel=1e-6)
  # the reference: the elastica's reach tabulated finely around the truth
  # once, each draw's ratio read off it (independent of bending_length's
  # bracketing)
  ratios = np.geomspace(0.5 * overhang / c, 2.0 * overhang / c, 400)
  reaches = cantilever.tip(ratios)[0]  # falling
  e = np.random.default_rng(0).normal(0.0, sd, (300, 2))
  o, r = overhang + e[:, 0], reach + e[:, 1]
  draws = o / np.exp(np.interp(-r / o, -reaches, np.log(ratios)))
  assert got_sd == pytest.approx(np.std(draws), rel=_SPREAD_TOL)
  # one reading's sd alone is smaller than both together; none gives none
  assert cantilever.bending_length_sd(overhang, reach, sd)[1] < got_sd
  assert cantilever.bending_length_sd(overhang, reach, 0.0)[1] == 0.0


def test_a_reading_one_sd_from_the_limits_is_refused():
  overhang = 0.05
  reach = overhang * cantilever.tip(cantilever.MIN_RATIO * 1.01)[0][0]  # hardly droops
  with pytest.raises(ValueError, match='cannot bound the bending length'):
    cantilever.bending_length_sd(overhang, reach, 0.001)
  with pytest.raises(ValueError, match='reach_sd'):
    cantilever.bending_length_sd(overhang, 0.03, float('nan'))


def test_the_shape_of_a_short_overhang_is_the_small_deflection_beam():
  # Euler-Bernoulli: a uniformly loaded cantilever's deflection is
  # q x^2 (6 L^2 - 4 L x + x^2) / (24 D); over L, with xi = x / L:
  # (L / c)^3 xi^2 (6 - 4 xi + xi^2) / 24
  ratio = 0.2
  line = cantilever.shape(ratio)
  xi = line[:, 0]
  beam = ratio**3 * xi**2 * (6 - 4 * xi + xi**2) / 24
  np.testing.assert_allclose(line[:, 1], beam, rtol=2e-3, atol=1e-7)


def test_the_shape_runs_from_the_edge_to_the_tip_along_its_length():
  ratios = np.array([0.5, 2.0, 4.0])
  line = cantilever.shape(ratios)
  assert line.shape == (3, cantilever._STEPS + 1, 2)
  np.testing.assert_allclose(line[:, 0], 0.0, atol=1e-15)  # at the edge
  reach, drop = cantilever.tip(ratios)
  np.testing.assert_allclose(line[:, -1, 0], reach, rtol=1e-9)
  np.testing.assert_allclose(line[:, -1, 1], drop, rtol=1e-9)
  # arc length L (the strip does not stretch); it leaves the edge flat
  length = np.linalg.norm(np.diff(line, axis=1), axis=-1).sum(axis=1)
  np.testing.assert_allclose(length, 1.0, rtol=1e-4)
  # clamped flat: the first step's chord slopes about a third of the second's
  step = np.diff(line[:, :3], axis=1)
  slope = step[..., 1] / step[..., 0]
  assert np.all(slope[:, 0] < 0.5 * slope[:, 1]), slope


# The loaded elastica's RK4 steps straddle the load's place and its span's
# end (a jump in shear or curvature): first order there, so the hand-derived
# beam is met to this relative tolerance at 200 steps.
_LOAD_TOL = 2e-3


def test_a_coin_at_the_tip_of_a_short_overhang_is_the_beam_with_an_end_load():
  # Euler-Bernoulli, units of c (D = w g c^3): self-weight and an end load
  # p = m / (w b c) drop the tip r^4 / 8 + p r^3 / 3, over L: r^3 / 8 + p r^2 / 3
  ratio, mass = 0.1, np.array([0.0, 0.5, 3.0])
  reach, droop = cantilever.tip(ratio, cantilever.Load(mass=mass))
  np.testing.assert_allclose(droop, ratio**3 / 8 + mass * ratio**2 / 3, rtol=_LOAD_TOL)
  np.testing.assert_allclose(reach, 1.0, atol=1e-4)


def test_a_coin_inboard_of_the_tip_and_the_span_it_stiffens():
  ratio, mass = 0.1, 2.0
  # the load a from the edge (at = r - a from the tip): its own deflection
  # p a^2 (3 r - a) / 6 at the tip, plus the self-weight's r^4 / 8
  at = 0.03
  a = ratio - at
  _, droop = cantilever.tip(ratio, cantilever.Load(mass=mass, at=at))
  want = (ratio**4 / 8 + mass * a**2 * (3 * ratio - a) / 6) / ratio
  assert droop[0] == pytest.approx(want, rel=_LOAD_TOL)
  # the end load with the last s of the strip rigid: by unit load, the tip
  # drops int_s^r (p u^2 + u^3 / 2) du = p (r^3 - s^3) / 3 + (r^4 - s^4) / 8
  s = 0.04
  _, droop = cantilever.tip(ratio, cantilever.Load(mass=mass, span=s))
  want = (mass * (ratio**3 - s**3) / 3 + (ratio**4 - s**4) / 8) / ratio
  assert droop[0] == pytest.approx(want, rel=_LOAD_TOL)


def test_a_load_broadcasts_and_a_heavier_one_hangs_further_down():
  ratio = np.array([[1.0], [2.0]])
  mass = np.array([0.0, 0.5, 1.5])
  span = np.array([0.0, 0.2, 0.2])  # nothing taped to the first
  line = cantilever.shape(ratio, cantilever.Load(mass=mass, at=0.1, span=span))
  assert line.shape == (2, 3, cantilever._STEPS + 1, 2)
  np.testing.assert_allclose(line[:, 0], cantilever.shape(ratio[:, 0]), atol=1e-12)
  drop = line[..., -1, 1]
  assert np.all(np.diff(drop, axis=1) > 0)
  # the stiffened span is straight: its points on one line
  tail = line[1, 2, -int(0.2 / 2.0 * cantilever._STEPS) :]
  d = np.diff(tail, axis=0)
  cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
  assert np.max(np.abs(cross)) < 1e-9


def test_a_load_out_of_range_is_refused():
  with pytest.raises(ValueError, match='load needs'):
    cantilever.tip(1.0, cantilever.Load(mass=-0.1))
  with pytest.raises(ValueError, match='load needs'):
    cantilever.tip(1.0, cantilever.Load(mass=1.0, span=1.0))
  with pytest.raises(ValueError, match='straight down'):
    cantilever.tip(3.0, cantilever.Load(mass=1e4))
  with pytest.raises(ValueError, match='straight down'):  # the looped root
    cantilever.tip(4.0, cantilever.Load(mass=200.0))


def test_a_strip_leaving_flat_is_the_clamped_one_and_its_root_bends_as_its_moment():
  """``leaving`` at angle 0 is ``shape``; its root curvature times c is the
  moment of the strip's weight about the root over D, by hand from the centre
  line: int_0^L x(s) ds over c^3 (a rectangle rule on its 200 steps); at an
  angle, the line leaves at that angle."""
  line, moment = cantilever.leaving(3.0, 0.0)
  np.testing.assert_allclose(line, cantilever.shape(3.0), atol=1e-12)
  x = line[:, 0] * 3.0  # in units of c
  lever = (x[1:] + x[:-1]) / 2 * (3.0 / 200)  # x ds
  assert float(moment) == pytest.approx(lever.sum(), rel=2e-3)
  tilted, _ = cantilever.leaving(2.0, 0.4)
  d = tilted[1] - tilted[0]
  assert np.arctan2(d[1], d[0]) == pytest.approx(0.4, abs=0.01)
