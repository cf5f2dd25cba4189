"""Tests for bo.minimize and bo.Minimizer: convergence, failures, batches,
stopping, resume, ask/tell."""

import os
import tempfile

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from absl.testing import absltest

import bo
from bo import propose

# Small proposal settings keep the CPU tests quick.
_FAST = dict(fit_restarts=2, fit_maxiter=30, acq_restarts=4, raw_samples=128)
_BOUNDS = np.array([[-2.0, 3.0], [0.0, 4.0]])
_X_STAR = np.array([0.7, 1.3])
_QUADRATIC_TOLERANCE = 1e-2


def quadratic(x):
  return np.sum((x - _X_STAR) ** 2 * np.array([1.0, 3.0]), axis=-1)


class MinimizeTest(absltest.TestCase):
  def test_quadratic_minimum_in_few_evaluations(self):
    res = bo.minimize(
      quadratic, _BOUNDS, n_init=4, n_iter=12, seed=0, config_overrides=_FAST
    )
    self.assertEqual(res.n_evals, 16)
    self.assertEqual(res.X.shape, (16, 2))
    self.assertLess(res.y_best, _QUADRATIC_TOLERANCE)
    np.testing.assert_allclose(res.x_best, _X_STAR, atol=0.1)

  def test_x0_first_and_jax_outputs(self):
    seen = []

    def f(x):
      seen.append(np.array(x))
      return jax.numpy.asarray(quadratic(x))

    x0 = np.array([1.0, 1.0])
    res = bo.minimize(
      f, _BOUNDS, n_init=3, n_iter=2, x0=x0, seed=1, config_overrides=_FAST
    )
    np.testing.assert_array_equal(res.X[0], x0)
    self.assertEqual(seen[0].shape, (3, 2))  # The initial design in one call.
    self.assertTrue(np.all(res.X >= _BOUNDS[:, 0]) and np.all(res.X <= _BOUNDS[:, 1]))

  def test_nan_values_are_failures(self):
    def f(x):
      y = quadratic(x)
      return np.where(x[:, 0] > 1.5, np.nan, np.where(x[:, 1] > 3.5, np.inf, y))

    res = bo.minimize(f, _BOUNDS, n_init=5, n_iter=6, seed=2, config_overrides=_FAST)
    self.assertEqual(res.n_evals, 11)
    self.assertTrue(np.isfinite(res.y_best))
    bad = (res.X[:, 0] > 1.5) | (res.X[:, 1] > 3.5)
    self.assertTrue(np.all(np.isnan(res.Y[bad])))

  def test_all_failures_fall_back_to_quasi_random(self):
    res = bo.minimize(
      lambda x: np.full(x.shape[0], np.nan), _BOUNDS, n_init=2, n_iter=3, q=2
    )
    self.assertEqual(res.n_evals, 8)
    self.assertEqual(res.y_best, float('inf'))
    self.assertEqual(len(np.unique(res.X, axis=0)), 8)

  def test_batch_and_callback(self):
    infos = []
    res = bo.minimize(
      quadratic, _BOUNDS, n_init=4, n_iter=3, q=3, seed=3,
      acquisition='ucb', config_overrides=_FAST, callback=infos.append,
    )  # fmt: skip
    self.assertEqual(res.n_evals, 13)
    self.assertLen(infos, 3)
    self.assertEqual(infos[0].X_new.shape, (3, 2))
    # Kriging believer spreads the batch out.
    self.assertGreater(np.min(np.ptp(infos[-1].X_new, axis=0)), 0.0)

  def test_objective_runs_in_default_precision(self):
    # The GP works in float64; a JAX objective (an MJX simulation) must not
    # be traced in that mode (it failed with int32/int64 mixes on the GPU).
    seen = []

    def fun(x):
      seen.append(jnp.zeros(1).dtype)
      return quadratic(x)

    bo.minimize(fun, _BOUNDS, n_init=3, n_iter=2, seed=0, config_overrides=_FAST)
    self.assertEqual(set(seen), {jnp.zeros(1).dtype})
    self.assertEqual(len(seen), 3)

  def test_callback_stops(self):
    res = bo.minimize(
      quadratic, _BOUNDS, n_init=3, n_iter=10, config_overrides=_FAST,
      callback=lambda info: info.iteration == 1,
    )  # fmt: skip
    self.assertEqual(res.n_evals, 5)
    self.assertTrue(res.stopped_early)

  def test_stopping_rule(self):
    res = bo.minimize(
      quadratic, _BOUNDS, n_init=4, n_iter=20, seed=0, config_overrides=_FAST,
      stop_rel_change=0.1, stop_window=3,
    )  # fmt: skip
    self.assertTrue(res.stopped_early)
    self.assertLess(res.n_iter, 20)
    later = bo.minimize(
      quadratic, _BOUNDS, n_init=4, n_iter=20, seed=0, config_overrides=_FAST,
      stop_rel_change=0.1, stop_window=3, stop_min_iter=res.n_iter + 2,
    )  # fmt: skip
    self.assertGreaterEqual(later.n_iter, res.n_iter + 2)

  def test_resume_matches_uninterrupted(self):
    kw = dict(n_init=4, n_iter=6, seed=5, config_overrides=_FAST)
    full = bo.minimize(quadratic, _BOUNDS, **kw)
    calls = {'n': 0}

    def crashing(x):
      calls['n'] += 1
      if calls['n'] == 4:  # Initial design + 2 iterations, then a crash.
        raise RuntimeError('simulator died')
      return quadratic(x)

    with tempfile.TemporaryDirectory() as tmp:
      path = os.path.join(tmp, 'state.npz')
      with self.assertRaises(RuntimeError):
        bo.minimize(crashing, _BOUNDS, state_path=path, **kw)
      self.assertTrue(os.path.exists(path))
      resumed = bo.minimize(quadratic, _BOUNDS, state_path=path, **kw)
      with self.assertRaises(ValueError):  # Other settings: refuse to resume.
        bo.minimize(quadratic, _BOUNDS, state_path=path, n_init=4, n_iter=6, seed=6)
    np.testing.assert_allclose(resumed.X, full.X, atol=1e-9)
    np.testing.assert_allclose(resumed.Y, full.Y, atol=1e-9)
    self.assertEqual(resumed.y_best, full.y_best)

  def test_no_recompile_as_data_grows(self):
    step = propose.cached_propose(propose.ProposeConfig(d=2, **_FAST))
    before = step._cache_size()
    bo.minimize(quadratic, _BOUNDS, n_init=4, n_iter=8, config_overrides=_FAST)
    # 4 + 8 points with one point of headroom fit a 16-slot buffer: one program.
    self.assertLessEqual(step._cache_size() - before, 1)

  @pytest.mark.slow  # two whole searches
  def test_interleaved_ask_tell_equals_minimize(self):
    # Two searches stepped in lockstep (as experiments.estimate_many drives
    # them) each go exactly as minimize runs them alone.
    other = lambda x: np.sum(np.abs(x - 1.0), axis=-1)
    kw = dict(n_init=3, n_iter=4, q=2, seed=2, config_overrides=_FAST)
    alone = [bo.minimize(f, _BOUNDS, **kw) for f in (quadratic, other)]
    opts = [bo.Minimizer(_BOUNDS, device=jax.devices('cpu')[0], **kw) for _ in alone]
    states = [o.start() for o in opts]
    while not all(o.done(s) for o, s in zip(opts, states, strict=True)):
      for i, f in enumerate((quadratic, other)):
        if not opts[i].done(states[i]):
          x, states[i] = opts[i].ask(states[i])
          states[i] = opts[i].tell(states[i], x, f(x))
    for o, s, ref in zip(opts, states, alone, strict=True):
      res = o.result(s)
      np.testing.assert_allclose(res.X, ref.X, atol=1e-12)
      np.testing.assert_allclose(res.Y, ref.Y, atol=1e-12)
      self.assertEqual(res.n_iter, ref.n_iter)

  def test_ask_after_done_and_wrong_tell(self):
    opt = bo.Minimizer(_BOUNDS, n_init=2, n_iter=0)
    s = opt.start()
    x, s = opt.ask(s)
    with self.assertRaises(ValueError):
      opt.tell(s, x, np.zeros(3))  # 3 values for 2 points
    s = opt.tell(s, x, quadratic(x))
    self.assertTrue(opt.done(s))
    with self.assertRaises(ValueError):
      opt.ask(s)

  def test_bad_bounds(self):
    with self.assertRaises(ValueError):
      bo.minimize(quadratic, [[1.0, 0.0]], n_init=2, n_iter=1)


if __name__ == '__main__':
  absltest.main()
