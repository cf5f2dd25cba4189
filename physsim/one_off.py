"""Seconds a step spends once per program shape: compiles and simulator set-up.

A batched step's time has a part that grows with its worlds (simulating,
rendering, scoring) and a part paid once per program shape: JAX's trace,
lowering and compile (or its persistent cache's read), and, on MuJoCo Warp,
each batch size's model and data buffers, kernels built and loaded, and the
frame's graph captured on its first call (``physsim.warp_frames``). A forecast
of a step's time from an earlier one (``--time_limit``:
``experiments.pipeline.search.step_forecast``) scales only the first part;
this module measures the second.

``Meter`` counts JAX's compile events of the thread that made it (a warm-up
compiled in a background thread overlaps the work and is not counted) and the
set-up seconds each device reported through ``add_setup`` (the longest device,
since devices set up at once). An estimate, not a profile: work that
overlaps a compile is counted as compile.
"""

from __future__ import annotations

import collections
import threading

import jax

# JAX's duration events of one compile (jax._src.dispatch): tracing to a
# jaxpr, lowering to MLIR, and the backend compile or the persistent cache's
# read. Consecutive phases, not nested.
COMPILE_EVENTS = (
  '/jax/core/compile/jaxpr_trace_duration',
  '/jax/core/compile/jaxpr_to_mlir_module_duration',
  '/jax/core/compile/backend_compile_duration',
)

_lock = threading.Lock()
_compile: collections.Counter = collections.Counter()  # thread id -> seconds
_setup: collections.Counter = collections.Counter()  # device -> seconds
_listening = False


def _on_event(event: str, seconds: float, **_) -> None:
  if event in COMPILE_EVENTS:
    with _lock:
      _compile[threading.get_ident()] += seconds


def _listen() -> None:
  """Registers the JAX listener once per process (listeners cannot be removed
  through JAX's public API; one that only adds is harmless)."""
  global _listening
  with _lock:
    if _listening:
      return
    _listening = True
  jax.monitoring.register_event_duration_secs_listener(_on_event)


def add_setup(device: str, seconds: float) -> None:
  """Records ``seconds`` of a simulator's one-off set-up on ``device``."""
  with _lock:
    _setup[device] += seconds


class Meter:
  """One-off seconds since ``mark()``: compiles on this thread plus the
  longest device's set-up."""

  def __init__(self):
    _listen()
    self._thread = threading.get_ident()
    self.mark()

  def _now(self) -> tuple[float, dict]:
    with _lock:
      return _compile[self._thread], dict(_setup)

  def mark(self) -> None:
    """Starts counting from now."""
    self._compile0, self._setup0 = self._now()

  def parts(self) -> tuple[float, float]:
    """(compile, set-up) seconds since the last ``mark()``."""
    compile_s, setup = self._now()
    grown = [s - self._setup0.get(d, 0.0) for d, s in setup.items()]
    return compile_s - self._compile0, max(grown, default=0.0)

  def seconds(self) -> float:
    """One-off seconds since the last ``mark()``."""
    return sum(self.parts())
