"""Progress bars whose rate and ETA leave out compile time, on a terminal or in a log.

A batched JAX stage spends its first call compiling (MJX, the renderer, the
network): a bar that folds that into its rate shows an ETA many times too
long. ``Bar`` says "compiling" until the first batch is done, then restarts
its clock, so the rate and ETA come from the batches after it.

On a terminal the bar is tqdm's live one. In a file or a pipe (a job's log)
it is ``model.progress.LogBar``: one plain line at the first batch, every 5%
of the total and at the end, each with the count, the rate and the time left,
and no carriage returns.
"""

from __future__ import annotations

import time

from model import progress as progress_lib

LogBar = progress_lib.LogBar
is_terminal = progress_lib.is_terminal


class Bar:
  """A progress bar over ``total`` items processed in batches.

  Call ``done(n)`` after each batch of ``n`` items and ``skip(n)`` for items
  already there (a resume), which do not count towards the rate. ``file``:
  where it is drawn (default stderr); a terminal gets tqdm's live bar, a file
  or pipe a line every ``every`` of the total.
  """

  def __init__(self, total: int, desc: str, unit: str = 'item', *,
               disable: bool = False, file=None,
               every: float = progress_lib.EVERY):  # fmt: skip
    self._bar = progress_lib.bar(total, desc, unit, disable=disable, file=file,
                                 every=every, smoothing=0, dynamic_ncols=True)  # fmt: skip
    self._log = isinstance(self._bar, LogBar)
    self._t0 = time.perf_counter()
    self._warm = False
    self.compile_seconds = None
    if total:
      self._bar.set_postfix_str('first batch: compiling')

  def skip(self, n: int) -> None:
    """``n`` items found done: counted, not timed."""
    if not n:
      return
    if not self._warm and self._bar.n + n >= (self._bar.total or 0):
      self._bar.set_postfix_str('all found done')  # nothing left to compile
    if self._log:
      self._bar.restart(at=self._bar.n + n)
      self._bar.update(n)
    else:
      self._bar.update(n)
      self._restart()

  def done(self, n: int) -> None:
    """``n`` items just computed."""
    if self._warm:
      self._bar.update(n)
      return
    self._warm = True
    self.compile_seconds = time.perf_counter() - self._t0
    note = f'first batch {self.compile_seconds:.0f} s (compile)'
    if self._log:  # its line: the compile time, no rate yet
      self._bar.set_postfix_str(note)
      self._bar.restart(at=self._bar.n + n)
      self._bar.update(n)
    else:
      self._bar.update(n)
      self._bar.set_postfix_str(note)
      self._restart()

  def _restart(self) -> None:
    """tqdm's rate and ETA from now on: the clock restarts at the current count."""
    self._bar.initial = self._bar.n
    self._bar.start_t = self._bar._time()
    self._bar.refresh()
    # drawn now: else a bar whose later updates all fell within tqdm's
    # mininterval would look never drawn to close(), which then skips the end
    self._bar.last_print_t, self._bar.last_print_n = self._bar.start_t, self._bar.n

  def close(self) -> None:
    self._bar.close()

  def __enter__(self):
    return self

  def __exit__(self, *exc):
    self.close()
