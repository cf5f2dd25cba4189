"""Progress bars whose rate and ETA leave out compile time.

A batched JAX stage spends its first call compiling (MJX, the renderer, the
network): a bar that folds that into its rate shows an ETA many times too
long. ``Bar`` says "compiling" until the first batch is done, then restarts
its clock, so the rate and ETA come from the batches after it.
"""

from __future__ import annotations

import time

from tqdm import tqdm


class Bar:
  """A tqdm bar over ``total`` items processed in batches.

  Call ``done(n)`` after each batch of ``n`` items and ``skip(n)`` for items
  already there (a resume), which do not count towards the rate.
  """

  def __init__(self, total: int, desc: str, unit: str = 'item', *,
               disable: bool = False):  # fmt: skip
    self._bar = tqdm(total=total, desc=desc, unit=unit, smoothing=0,
                     disable=disable, dynamic_ncols=True)  # fmt: skip
    self._t0 = time.perf_counter()
    self._warm = False
    self.compile_seconds = None
    if total:
      self._bar.set_postfix_str('first batch: compiling')

  def skip(self, n: int) -> None:
    """``n`` items found done: counted, not timed."""
    if n:
      self._bar.update(n)
      self._restart()

  def done(self, n: int) -> None:
    """``n`` items just computed."""
    self._bar.update(n)
    if not self._warm:
      self._warm = True
      self.compile_seconds = time.perf_counter() - self._t0
      self._bar.set_postfix_str(f'first batch {self.compile_seconds:.0f} s (compile)')
      self._restart()

  def _restart(self) -> None:
    """Rate and ETA from now on: the clock restarts at the current count."""
    self._bar.initial = self._bar.n
    self._bar.start_t = self._bar._time()
    self._bar.refresh()

  def close(self) -> None:
    self._bar.close()

  def __enter__(self):
    return self

  def __exit__(self, *exc):
    self.close()
