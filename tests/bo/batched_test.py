"""Tests of bo.batched: searches asked together propose what each proposes
alone (the single ask is the batch of one), whatever their iteration, with
finished, fresh and failed searches and other settings in the same call."""

from __future__ import annotations

import threading

import jax
import numpy as np
import pytest

import bo
from bo import batched

# A search's rows never mix with another's, so a batch changes its arithmetic
# only by the reassociation of batched linear algebra: candidates (grid cells
# and key-drawn jitter, or L-BFGS-B optima) agree to the last bits, the
# posterior grid to round-off of its normalisation.
_REASSOCIATION_TOLERANCE = 1e-9

# Small settings keep the compiles short; one capacity (n_init + q * n_iter
# <= 16) keeps each setting to one program per batch size.
CONFIG = bo.PosteriorConfig(
  d=2, grid=(12, 12), q=3, samples=64, fit_restarts=2, fit_maxiter=20
)
_FAST = dict(fit_restarts=2, fit_maxiter=20, acq_restarts=2, acq_maxiter=20,
             raw_samples=64)  # fmt: skip
TARGETS = np.array([[0.3, -0.2], [-0.5, 0.5], [0.1, 0.7]])


def discrepancy(i, x, iteration):
  """Search ``i``'s noisy discrepancy (its own noise, fixed per iteration)."""
  rng = np.random.default_rng(100 * i + iteration)
  return np.sum((x - TARGETS[i]) ** 2, 1) * np.exp(0.1 * rng.normal(size=len(x)))


def posterior_search(i):
  return bo.PosteriorSearch(CONFIG, n_init=4, n_iter=3, seed=i)


def cpus():
  return jax.local_devices(backend='cpu')  # conftest: two host devices


def minimizer(i):
  return bo.Minimizer(
    np.array([[-1.0, 1.0]] * 2), n_init=4, n_iter=2, q=2, seed=i,
    config_overrides=_FAST,
  )  # fmt: skip


def run_together(opts, ids, **kw):
  """Runs searches in lockstep through ``ask_many``; per search, its asks."""
  states = [o.start() for o in opts]
  asked = [[] for _ in opts]
  t = 0
  while live := [k for k, o in enumerate(opts) if not o.done(states[k])]:
    got = batched.ask_many([opts[k] for k in live], [states[k] for k in live], **kw)
    for k, (x, state) in zip(live, got, strict=True):
      asked[k].append(x)
      states[k] = opts[k].tell(state, x, discrepancy(ids[k], x, t))
    t += 1
  return asked, states


def run_alone(opt, i, **kw):
  """The same search through its own ``ask`` (with ``kw``: ``ask_many``'s)."""
  state, asked, t = opt.start(), [], 0
  while not opt.done(state):
    x, state = batched.ask_many([opt], [state], **kw)[0] if kw else opt.ask(state)
    asked.append(x)
    state = opt.tell(state, x, discrepancy(i, x, t))
    t += 1
  return asked, state


def assert_same_asks(a, b):
  assert len(a) == len(b)
  for xa, xb in zip(a, b, strict=True):
    np.testing.assert_allclose(xa, xb, rtol=0, atol=_REASSOCIATION_TOLERANCE)


@pytest.mark.parametrize(
  'mode', ['map', pytest.param('vmap', marks=pytest.mark.slow)]
)  # vmap: slow on CPUs
def test_three_posterior_searches_together_ask_as_each_alone(mode):
  ids = [0, 1, 2]
  opts = [posterior_search(i) for i in ids]
  # three rows padded to four, two on each CPU device
  together, states = run_together(opts, ids, mode=mode, devices=cpus())
  results = batched.result_many(opts, states, mode=mode, devices=cpus())
  for i in ids:
    opt = posterior_search(i)
    if mode == 'map':  # the default on CPUs: the plain ask and result
      alone, state = run_alone(opt, i)
      result = opt.result(state)
    else:
      (alone,), (state,) = run_together([opt], [i], mode=mode, devices=cpus())
      (result,) = batched.result_many([opt], [state], mode=mode)
    assert_same_asks(alone, together[i])
    assert len(alone) == 4  # the initial design and three iterations
    np.testing.assert_allclose(
      results[i].log_post, result.log_post, atol=_REASSOCIATION_TOLERANCE
    )
    np.testing.assert_allclose(results[i].samples, result.samples,
                               atol=_REASSOCIATION_TOLERANCE)  # fmt: skip
    np.testing.assert_array_equal(states[i].history.shape, state.history.shape)
  # each search was told its own discrepancies
  assert not np.allclose(results[0].log_post, results[1].log_post)


@pytest.mark.slow  # several searches over several iterations
def test_mixed_batch_fresh_failed_finished_other_settings_and_iterations():
  """One ask_many call with a search at its initial design, one at iteration
  2, one whose every simulation failed, and two Minimizers (another setting,
  so another program): each answers as alone; a finished search is refused."""
  a, b, c = posterior_search(0), posterior_search(1), posterior_search(2)
  m0, m1 = minimizer(0), minimizer(1)
  sa = a.start()  # fresh: the initial design, no GP
  sb = b.start()
  for t in range(3):  # two GP iterations in
    x, sb = b.ask(sb)
    sb = b.tell(sb, x, discrepancy(1, x, t))
  sc = c.start()
  x, sc = c.ask(sc)
  sc = c.tell(sc, x, np.full(len(x), np.nan))  # every simulation failed
  sm0 = m0.start()
  x, sm0 = m0.ask(sm0)
  sm0 = m0.tell(sm0, x, discrepancy(0, x, 0))
  sm1 = m1.start()
  for t in range(2):
    x, sm1 = m1.ask(sm1)
    sm1 = m1.tell(sm1, x, discrepancy(1, x, t))
  opts, states = [a, m0, b, c, m1], [sa, sm0, sb, sc, sm1]
  together = batched.ask_many(opts, states)
  for opt, state, (x, new) in zip(opts, states, together, strict=True):
    x_alone, new_alone = opt.ask(state)
    np.testing.assert_allclose(x, x_alone, rtol=0, atol=_REASSOCIATION_TOLERANCE)
    if new_alone.params is not None:
      np.testing.assert_allclose(new.params, new_alone.params, rtol=1e-7)
  assert together[0][0].shape == (4, 2)  # the initial design
  assert together[3][0].shape == (CONFIG.q, 2)  # quasi-random after failures
  # a finished search is not asked
  done = b.stop(sb)
  with pytest.raises(ValueError, match='finished'):
    batched.ask_many([a, b], [sa, done])


@pytest.mark.slow  # three L-BFGS-B searches, alone and together
def test_minimizers_together_ask_as_each_alone():
  """L-BFGS-B optima carry any change of rounding into the next iterations:
  over the same devices (one mesh, one program) alone and together agree."""
  ids = [0, 1, 2]
  together, _ = run_together([minimizer(i) for i in ids], ids, devices=cpus())
  for i in ids:
    alone, _ = run_alone(minimizer(i), i, devices=cpus())
    assert_same_asks(alone, together[i])


def test_padding_rows_are_skipped_and_change_nothing():
  """Two searches in a batch padded to 8 rows (6 skipped), over two CPU
  devices, ask what each asks alone."""
  opts = [posterior_search(i) for i in (0, 1)]
  states = []
  for i, o in enumerate(opts):
    s = o.start()
    x, s = o.ask(s)
    states.append(o.tell(s, x, discrepancy(i, x, 0)))
  padded = batched.ask_many(opts, states, devices=cpus(), min_rows=8)
  for o, s, (y, _) in zip(opts, states, padded, strict=True):
    x, _ = o.ask(s)
    np.testing.assert_allclose(x, y, rtol=0, atol=_REASSOCIATION_TOLERANCE)


def test_bad_mode():
  opt = posterior_search(0)
  s = opt.start()
  x, s = opt.ask(s)
  s = opt.tell(s, x, discrepancy(0, x, 0))
  with pytest.raises(ValueError, match='mode'):
    batched.ask_many([opt], [s], mode='pmap')


def test_a_warm_up_on_placeholders_compiles_the_next_step_and_changes_nothing(
  tmp_path,
):
  """``warm_ask`` in a thread (as the estimate runs it beside the design's
  simulations) runs the program that the next ``ask`` runs, so none compiles
  there; it writes no state, and the search asks what it asks without it."""

  def search(path=None):
    return bo.PosteriorSearch(CONFIG, n_init=4, n_iter=3, seed=7, state_path=path)

  opt = search(str(tmp_path / 'state.npz'))
  ((x, state),) = batched.ask_many([opt], [opt.start()], devices=cpus())
  batched._program.cache_clear()
  t = threading.Thread(
    target=batched.warm_ask, args=([opt], [state], [x]), kwargs=dict(devices=cpus())
  )
  t.start()
  t.join()
  assert not list(tmp_path.iterdir())  # nothing told, nothing saved
  assert batched._program.cache_info().misses == 1
  ((after, _),) = batched.ask_many(
    [opt], [opt.tell(state, x, discrepancy(0, x, 0))], devices=cpus()
  )
  assert batched._program.cache_info().misses == 1  # the program was ready
  ref = search()
  ((y, ref_state),) = batched.ask_many([ref], [ref.start()], devices=cpus())
  ((ref_after, _),) = batched.ask_many(
    [ref], [ref.tell(ref_state, y, discrepancy(0, y, 0))], devices=cpus()
  )
  np.testing.assert_allclose(after, ref_after, rtol=0, atol=_REASSOCIATION_TOLERANCE)
