"""benchmarks.coin_bound: the hanging strip's catenary arcs against their
force balance and limits by hand, and the information of a profile against
a displacement derived by hand."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import coin_bound


def test_the_hanging_strip_has_its_length_and_hangs_from_both_pins():
  line = coin_bound.hanging_curve(np.array([0.0, 0.4, 3.0]), 0.8)
  np.testing.assert_allclose(line[:, 0], 0.0, atol=1e-12)
  np.testing.assert_allclose(line[:, -1], [[0.8, 0.0]] * 3, atol=1e-9)
  length = np.linalg.norm(np.diff(line, axis=1), axis=-1).sum(-1)
  np.testing.assert_allclose(length, 1.0, rtol=1e-5)  # chords of a smooth curve
  # symmetric about the middle, which hangs lowest, lower under a heavier coin
  np.testing.assert_allclose(line[:, ::-1, 1], line[:, :, 1], atol=1e-12)
  middle = line[:, line.shape[1] // 2, 1]
  assert np.all(np.diff(middle) < 0)


def test_the_pins_carry_the_strip_and_the_coin():
  # vertical balance: each pin holds half of strip and coin, the coin's side
  # of the middle half the coin, under one horizontal tension; so the slope
  # at a pin over the slope beside the coin is (1 + a) / a
  a = 0.5
  line = coin_bound.hanging_curve(a, 0.8, samples=4001)
  mid = line.shape[0] // 2
  d_pin, d_mid = line[1] - line[0], line[mid] - line[mid - 1]
  ratio = (d_pin[1] / d_pin[0]) / (d_mid[1] / d_mid[0])
  assert ratio == pytest.approx((1 + a) / a, rel=2e-3)


def test_a_heavy_coin_pulls_the_strip_into_a_v():
  span = 0.6
  line = coin_bound.hanging_curve(1e4, span)
  depth = -line[line.shape[0] // 2, 1]
  assert depth == pytest.approx(np.sqrt(0.25 - span**2 / 4), rel=1e-3)


def test_a_profile_moved_along_its_normal_carries_its_length_of_information():
  # a straight profile of length 0.2 m whose parameter moves it 3 m per unit
  # along its normal: information 0.2 * 3^2, none from a move along itself
  x = np.linspace(0.0, 0.2, 101)
  base = np.stack([x, np.zeros_like(x)], -1)
  eps = 1e-3
  normal = np.array([0.0, -1.0])  # the convention: the tangent turned clockwise
  along = np.array([1.0, 0.0])
  curves = np.stack([base, base + 3 * eps * normal, base - 3 * eps * normal,
                     base + 5 * eps * along, base - 5 * eps * along])  # fmt: skip
  info = coin_bound.information(curves, np.full(2, eps), 0.2)
  np.testing.assert_allclose(info, [[0.2 * 9, 0.0], [0.0, 0.0]], atol=1e-9)
