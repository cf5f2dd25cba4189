"""Progress that reads well on a terminal and in a log file.

On a terminal (the stream is a tty) ``bar`` is tqdm's live bar. In a file or
a pipe a live bar's redraws (carriage returns) pile up into one line of
thousands of updates; there ``bar`` is a ``LogBar``, which writes one plain
line at the first update, every ``every`` of the total (5%) and at the end,
each with the count, the elapsed time, the rate and the time left::

  fit: 50/1000 (5%) in 0:04, 12.3 it/s, 1:17 left; loss=0.4210

Scripts' batched stages use ``experiments.pipeline.progress.Bar``, which builds
on this and leaves compile time out of the rate.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

EVERY = 0.05  # a log line every 5% of the total
INTERVAL_S = 60.0  # without a total: a log line at most this often


def is_terminal(file) -> bool:
  """Whether ``file`` is a terminal (a closed or odd stream is not)."""
  try:
    return bool(file.isatty())
  except (AttributeError, ValueError):
    return False


def _duration(seconds: float) -> str:
  return tqdm.format_interval(max(0.0, seconds))


def _rate(per_s: float, unit: str) -> str:
  if per_s >= 100:
    return f'{per_s:,.0f} {unit}/s'
  if per_s >= 1:
    return f'{per_s:.3g} {unit}/s'
  return f'{1 / per_s:.3g} s/{unit}'


class LogBar:
  """The part of tqdm's interface that the bars here use, as plain lines.

  ``restart(at)`` starts the rate's clock again, at count ``at`` (default the
  current one): items counted up to there do not count towards the rate (a
  batch that compiled, items found already done). Until an item is counted
  after that, a line gives no rate or time left.
  """

  def __init__(
    self,
    total: int | None = None,
    desc: str = '',
    unit: str = 'it',
    initial: int = 0,
    disable: bool = False,
    file=None,
    every: float = EVERY,
    interval: float = INTERVAL_S,
  ):
    self.total = total
    self.desc = desc
    self.unit = unit
    self.n = initial
    self.disable = disable
    self.file = sys.stderr if file is None else file
    self.every = every
    self.interval = interval
    self.postfix = ''
    self._t0 = time.perf_counter()
    self._start_n, self._start_t = initial, self._t0
    self._written_n: int | None = None  # the count of the last line
    self._written_t = self._t0
    self._closed = False

  def _step(self, n: int) -> int:
    """The 5%-step that count ``n`` is in."""
    return int(n // max(1.0, self.every * self.total))

  def _due(self) -> bool:
    if self._written_n is None:
      return True  # the first update
    if self.total:
      return self.n >= self.total or self._step(self.n) > self._step(self._written_n)
    return time.perf_counter() - self._written_t >= self.interval

  def line(self) -> str:
    """What a line says now."""
    now = time.perf_counter()
    head = f'{self.desc}: ' if self.desc else ''
    if self.total:
      count = f'{self.n}/{self.total} ({100 * self.n / self.total:.0f}%)'
    else:
      count = f'{self.n} {self.unit}'
    parts = [f'{head}{count} in {_duration(now - self._t0)}']
    timed, span = self.n - self._start_n, now - self._start_t
    if timed > 0 and span > 0:
      per_s = timed / span
      parts.append(_rate(per_s, self.unit))
      if self.total:
        parts.append(f'{_duration(max(0, self.total - self.n) / per_s)} left')
    text = ', '.join(parts)
    return f'{text}; {self.postfix}' if self.postfix else text

  def _write(self) -> None:
    self.file.write(self.line() + '\n')
    self.file.flush()
    self._written_n, self._written_t = self.n, time.perf_counter()

  def update(self, n: int = 1) -> None:
    """``n`` more items done: a line when one is due."""
    self.n += n
    if not self.disable and not self._closed and self._due():
      self._write()

  def restart(self, at: int | None = None) -> None:
    """The rate's clock starts again now, at count ``at`` (default: the current)."""
    self._start_n = self.n if at is None else at
    self._start_t = time.perf_counter()

  def set_postfix_str(self, s: str = '', refresh: bool = True) -> None:
    """Text at the end of the next lines (no line of its own)."""
    del refresh
    self.postfix = str(s)

  def set_postfix(self, ordered_dict=None, refresh: bool = True, **kwargs) -> None:
    """``key=value`` pairs at the end of the next lines, as tqdm's."""
    del refresh
    items = {**(ordered_dict or {}), **kwargs}
    self.postfix = ', '.join(f'{k}={v}' for k, v in items.items())

  def set_description(self, desc: str | None = None, refresh: bool = True) -> None:
    del refresh
    self.desc = desc or ''

  def refresh(self) -> None:
    """Nothing: lines are written only as the count moves."""

  def close(self) -> None:
    """The last line, unless the count has not moved since the last one."""
    if self._closed:
      return
    self._closed = True
    if not self.disable and self._written_n is not None and self.n != self._written_n:
      self._write()

  def __enter__(self):
    return self

  def __exit__(self, *exc):
    self.close()


def bar(
  total: int | None = None,
  desc: str = '',
  unit: str = 'it',
  *,
  initial: int = 0,
  disable: bool = False,
  file=None,
  every: float = EVERY,
  **tqdm_kwargs,
):
  """A progress bar on ``file`` (default stderr): tqdm's live bar (with
  ``tqdm_kwargs``) on a terminal, else a ``LogBar`` of plain lines."""
  file = sys.stderr if file is None else file
  if is_terminal(file):
    return tqdm(total=total, desc=desc, unit=unit, initial=initial, disable=disable,
                file=file, **tqdm_kwargs)  # fmt: skip
  return LogBar(total, desc, unit, initial, disable, file, every)
