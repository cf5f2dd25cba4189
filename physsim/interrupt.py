"""Ctrl-C while the simulator runs Python inside a device call.

Two backends run Python from inside a compiled program: MuJoCo Warp's frame
(an FFI call, ``warp.jax_callable``, on the thread that runs the program) and
MuJoCo C behind ``jax.pure_callback``. Python raises ``KeyboardInterrupt`` in
the main thread at the next bytecode, so a Ctrl-C (or a launcher's SIGTERM)
during a rollout lands inside one of them. There it cannot unwind: through
Warp's FFI the exception is dropped by ctypes and the process aborts
(``free(): invalid size``, a C stack dump, on an H200); through
``pure_callback`` it comes back as a ``JaxRuntimeError`` with two logged
tracebacks. Neither is the one line and resume command a user is promised.

So the handler installed here defers a signal that arrives inside a callback
(``deferred()`` around our own callback bodies, and any frame of the two
libraries' callback wrappers on the stack): it marks the run interrupted and
returns. Every later frame of the rollout then returns at once, its worlds NaN
(so nothing plausible comes out of an interrupted rollout), the program ends
within a frame's time, and ``raise_if_pending()`` raises the
``KeyboardInterrupt`` where the caller reads the program's result
(``physsim.simulate``, the estimate's objective). Where no caller checks (a
library user's own jit), the signal is sent again after ``RESEND_S``, to land
in ordinary Python. Outside callbacks the handler is Python's own: it raises.
"""

from __future__ import annotations

import contextlib
import inspect
import os
import signal
import threading

# Seconds after a deferred signal at which it is sent again if no caller has
# raised it by then: longer than a frame's skipped callbacks take to unwind.
RESEND_S = 1.0


class _State:
  depth = 0  # our own callback bodies now running (any thread)
  pending: int | None = None  # the deferred signal's number
  resent = False  # the next handled signal is our own resend
  timer: threading.Timer | None = None
  files: set[str] = set()  # callback wrappers' source files


_state = _State()


def _in_callback(frame) -> bool:
  if _state.depth:
    return True
  while frame is not None:
    if frame.f_code.co_filename in _state.files:
      return True
    frame = frame.f_back
  return False


def _resend(signum: int) -> None:
  if _state.pending is not None:
    _state.resent = True
    os.kill(os.getpid(), signum)


def _schedule_resend(signum: int) -> None:
  if _state.timer is None or not _state.timer.is_alive():
    _state.timer = threading.Timer(RESEND_S, _resend, (signum,))
    _state.timer.daemon = True
    _state.timer.start()


def handler(signum, frame) -> None:
  """SIGINT / SIGTERM: ``KeyboardInterrupt``, deferred out of callbacks."""
  resent, _state.resent = _state.resent, False
  if _in_callback(frame):
    if _state.pending is None:
      _state.pending = signum
    _schedule_resend(_state.pending)
    return
  if resent and _state.pending is None:
    return  # raised already, by raise_if_pending
  _state.pending = None
  raise KeyboardInterrupt


def pending() -> bool:
  """Whether a deferred interrupt waits: callbacks skip their work."""
  return _state.pending is not None


def raise_if_pending() -> None:
  """Raises the deferred ``KeyboardInterrupt`` (after a program that ran
  callbacks has returned its result): the result is not to be used."""
  if _state.pending is not None:
    _state.pending = None
    raise KeyboardInterrupt


@contextlib.contextmanager
def deferred():
  """Marks a callback body: a signal meanwhile is deferred (module doc)."""
  _state.depth += 1
  try:
    yield
  finally:
    _state.depth -= 1


def defer_in(*objects) -> None:
  """Treats the source files of ``objects`` (a library's callback wrapper)
  as callback frames."""
  for o in objects:
    path = inspect.getsourcefile(o)
    if path:
      _state.files.add(path)


def install(signals=(signal.SIGINT,)) -> None:
  """Puts ``handler`` in place of Python's default for ``signals``; for
  SIGINT only where it is Python's own (a notebook's or an application's
  handler stays). A no-op off the main thread, where signals cannot be set."""
  if threading.current_thread() is not threading.main_thread():
    return
  for s in signals:
    current = signal.getsignal(s)
    if s == signal.SIGINT and current is not signal.default_int_handler:
      continue
    signal.signal(s, handler)
