"""Tests for physsim/one_off.py: a step's compile and set-up seconds."""

import threading

import jax
import jax.numpy as jnp
import pytest

from physsim import one_off


def test_a_compile_on_this_thread_counts_and_a_cached_call_does_not():
  meter = one_off.Meter()
  f = jax.jit(lambda x: jnp.sin(x) * 3.0 + jnp.cos(x) ** 2)
  f(jnp.arange(7.0)).block_until_ready()
  first = meter.seconds()
  assert first > 0.0
  x = (jnp.arange(7.0) + 1).block_until_ready()
  meter.mark()
  f(x).block_until_ready()  # the same shape: no compile
  assert meter.seconds() == 0.0


def test_another_threads_compile_is_not_counted():
  meter = one_off.Meter()

  def background():
    jax.jit(lambda x: jnp.tanh(x) - 1.5)(jnp.ones(11)).block_until_ready()

  t = threading.Thread(target=background)
  t.start()
  t.join()
  assert meter.seconds() == 0.0


def test_set_ups_count_the_longest_device_since_the_mark():
  one_off.add_setup('dev-a', 5.0)  # before the mark: not counted
  meter = one_off.Meter()
  one_off.add_setup('dev-a', 2.0)
  one_off.add_setup('dev-b', 3.0)  # devices set up at once: the longest
  assert meter.seconds() == pytest.approx(3.0)
  assert meter.parts() == pytest.approx((0.0, 3.0))  # (compile, set-up)
  meter.mark()
  assert meter.seconds() == 0.0
