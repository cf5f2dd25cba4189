"""Tests of physsim.interrupt: a Ctrl-C that arrives while Python runs inside
a callback of compiled code is raised after the callback, never inside it.

The callbacks here are real: a ctypes comparator called by the C library's
``qsort`` (an independent C caller, like Warp's FFI), and MuJoCo C's rollout
behind ``jax.pure_callback`` in a jitted program. The signal is sent from
inside the callback, so nothing depends on timing."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import time

import jax
import numpy as np
import pytest

import physsim
from physsim import interrupt
from physsim import rollout as rollout_lib

_CMP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_int),
                        ctypes.POINTER(ctypes.c_int))  # fmt: skip


def _sort_with_ctrl_c(values: list[int]) -> tuple[list[int], int]:
  """``qsort`` with a comparator that sends SIGINT to this process on its
  first call; returns the sorted values and the comparator's call count."""
  libc = ctypes.CDLL(ctypes.util.find_library('c'))
  calls = [0]

  @_CMP
  def compare(a, b):
    with interrupt.deferred():
      if calls[0] == 0:
        os.kill(os.getpid(), signal.SIGINT)
      calls[0] += 1
      for _ in range(100):  # bytecodes, where Python runs the handler
        pass
      return a[0] - b[0]

  arr = (ctypes.c_int * len(values))(*values)
  libc.qsort(arr, len(values), ctypes.sizeof(ctypes.c_int), compare)
  return list(arr), calls[0]


def test_a_signal_inside_a_callback_is_raised_by_the_caller(deferring_sigint):
  values = list(range(64))[::-1]
  out, calls = _sort_with_ctrl_c(values)
  # The comparator was never interrupted: qsort finished its work.
  assert out == sorted(values)
  assert calls > len(values)
  assert interrupt.pending()
  with pytest.raises(KeyboardInterrupt):
    interrupt.raise_if_pending()
  assert not interrupt.pending()
  interrupt.raise_if_pending()  # raised once only
  time.sleep(interrupt.RESEND_S + 0.2)  # the resend finds nothing pending


def test_unclaimed_it_is_sent_again_outside(deferring_sigint, monkeypatch):
  monkeypatch.setattr(interrupt, 'RESEND_S', 0.05)
  _sort_with_ctrl_c(list(range(16)))
  t0 = time.monotonic()
  with pytest.raises(KeyboardInterrupt):
    while time.monotonic() - t0 < 5.0:  # ordinary Python, no caller checking
      time.sleep(0.01)
  assert time.monotonic() - t0 < 2.0
  assert not interrupt.pending()


def test_outside_a_callback_it_raises_at_once(deferring_sigint):
  with pytest.raises(KeyboardInterrupt):
    signal.raise_signal(signal.SIGINT)
    for _ in range(1000):
      pass
  assert not interrupt.pending()


def test_install_keeps_a_handler_that_is_not_pythons_own():
  own = signal.getsignal(signal.SIGINT)
  try:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a background job's
    interrupt.install()
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    signal.signal(signal.SIGINT, signal.default_int_handler)
    interrupt.install()
    assert signal.getsignal(signal.SIGINT) is interrupt.handler
  finally:
    signal.signal(signal.SIGINT, own)


def test_mujoco_c_behind_a_pure_callback_stops_and_raises_after(
  deferring_sigint, monkeypatch
):
  """A Ctrl-C during MuJoCo C's rollout inside a jitted program: before,
  a ``JaxRuntimeError`` wrapping the interrupt (two logged tracebacks); now
  the program returns, its worlds NaN from the frame the signal came in, and
  ``raise_if_pending`` raises the interrupt."""
  model = physsim.build(physsim.square(6), 'gray_interlock')
  frames, fps = 40, 20.0
  substeps, _ = rollout_lib._frame_plan(model, frames, fps, 0.0)
  fn = jax.jit(rollout_lib.rollout_fn(
    model, frames=frames, fps=fps, warmup=0.0, backend='c', workers=1
  ))  # fmt: skip
  p = physsim.params.make(bending_scale=[1.0, 2.0], wind_speed=[2.0, 3.0],
                          area_weight=[0.2, 0.25])  # fmt: skip
  w = rollout_lib.world_inputs(
    model, *p, rollout_lib._world_keys(jax.random.key(0), 2, physsim.Wind()),
    physsim.Wind(), np.ones(2),
  )  # fmt: skip
  xs, valid = fn(w)  # compiled, run whole
  assert np.all(np.asarray(valid))
  real, calls = rollout_lib._applied_forces_np, [0]

  def forces(*args):
    calls[0] += 1
    if calls[0] == 3 * substeps:  # during the first world's third frame
      os.kill(os.getpid(), signal.SIGINT)
    return real(*args)

  monkeypatch.setattr(rollout_lib, '_applied_forces_np', forces)
  xs, valid = jax.device_get(fn(w))
  assert interrupt.pending()
  assert not np.any(valid)
  assert np.all(np.isfinite(xs[0, :2])) and np.all(np.isnan(xs[0, 3:]))
  assert np.all(np.isnan(xs[1]))  # the second world never ran
  assert calls[0] <= 4 * substeps  # the frame it was in, then stopped
  with pytest.raises(KeyboardInterrupt):
    interrupt.raise_if_pending()


# A child that simulates on MuJoCo Warp and sends itself SIGINT from inside
# the third frame's FFI call (argv[1]: 'handled' installs the module's handler
# as every script does; 'python' keeps Python's own: the abort before, to see
# by hand).
_WARP_CHILD = r"""
import json, os, signal, sys
import jax, numpy as np
import physsim
from physsim import interrupt, warp_frames
if sys.argv[1] == 'handled':
  interrupt.install()
else:  # nothing installs it (physsim.warp_frames would)
  interrupt.install = lambda *args, **kwargs: None
real, calls = warp_frames._Worlds.run, [0]
def run(self):
  calls[0] += 1
  if calls[0] == 3:
    os.kill(os.getpid(), signal.SIGINT)
  real(self)
warp_frames._Worlds.run = run
try:
  physsim.simulate(
    physsim.build(physsim.square(8), 'gray_interlock'),
    physsim.params.make(bending_scale=[1.0], wind_speed=[2.0], area_weight=[0.2]),
    frames=40, fps=20.0, warmup=0.0, backend='warp',
    devices=[d for d in jax.devices() if d.platform == 'gpu'][:1],
  )
  print(json.dumps({'interrupted': False, 'calls': calls[0]}))
except KeyboardInterrupt:
  print(json.dumps({'interrupted': True, 'calls': calls[0]}))
"""


@pytest.mark.gpu
def test_ctrl_c_inside_a_warp_frame_is_raised_after_the_program():
  """On a GPU, a KeyboardInterrupt raised inside Warp's FFI call was dropped
  by ctypes and the process aborted (``free(): invalid size``); with the
  handler the rollout stops after that frame and ``simulate`` raises it."""
  import json  # noqa: PLC0415
  import subprocess  # noqa: PLC0415
  import sys  # noqa: PLC0415

  root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
  out = subprocess.run(
    [sys.executable, '-c', _WARP_CHILD, 'handled'], cwd=root, capture_output=True,
    text=True, timeout=300,
  )  # fmt: skip
  assert out.returncode == 0, out.stderr[-2000:]
  got = json.loads(out.stdout.strip().splitlines()[-1])
  assert got['interrupted'] and got['calls'] == 3  # no frame ran after it
