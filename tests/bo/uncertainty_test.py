"""Tests for bo.uncertainty: the posterior distribution of the minimiser."""

import jax
import numpy as np
import pytest

import bo

_BOUNDS = np.array([[0.0, 10.0], [-1.0, 1.0]])
_TRUE = np.array([3.0, 0.2])


def _f(x, flat_second=False):
  # Sharp in x0; in x1 sharp or (flat_second) nearly constant.
  w = 0.01 if flat_second else 4.0
  return (x[:, 0] - _TRUE[0]) ** 2 + w * (x[:, 1] - _TRUE[1]) ** 2


def _design(n, seed=0):
  u = bo.qmc.halton(n, 2, seed=seed)
  return _BOUNDS[:, 0] + u * (_BOUNDS[:, 1] - _BOUNDS[:, 0])


def test_samples_bracket_the_true_minimum():
  X = _design(40)
  s = bo.minimizer_samples(X, _f(X), _BOUNDS, jax.random.key(0), n_samples=256)
  assert s.samples.shape == (256, 2)
  assert np.all(s.quantiles[0] <= _TRUE + 0.05) and np.all(
    _TRUE - 0.05 <= s.quantiles[2]
  )
  assert abs(s.quantiles[1, 0] - _TRUE[0]) < 0.3


def test_flat_direction_is_more_uncertain():
  X = _design(40)
  sharp = bo.minimizer_samples(X, _f(X), _BOUNDS, jax.random.key(1))
  flat = bo.minimizer_samples(X, _f(X, flat_second=True), _BOUNDS, jax.random.key(1))
  # relative to the range: x1 spans 2, x0 spans 10
  assert flat.std[1] / 2 > 3 * sharp.std[1] / 2


def test_more_data_narrows_the_distribution():
  few, many = _design(8), _design(64)
  s_few = bo.minimizer_samples(few, _f(few), _BOUNDS, jax.random.key(2))
  s_many = bo.minimizer_samples(many, _f(many), _BOUNDS, jax.random.key(2))
  assert s_many.std[0] < s_few.std[0]


def test_failures_are_ignored_and_bad_shapes_raise():
  X = _design(20)
  Y = _f(X)
  Y[::3] = np.nan
  s = bo.minimizer_samples(X, Y, _BOUNDS, jax.random.key(3))
  assert np.all(np.isfinite(s.samples))
  with pytest.raises(ValueError, match='at least 2'):
    bo.minimizer_samples(
      X[:3], np.array([np.nan, np.nan, 1.0]), _BOUNDS, jax.random.key(0)
    )
  with pytest.raises(ValueError, match='need X'):
    bo.minimizer_samples(X, Y[:5], _BOUNDS, jax.random.key(0))
