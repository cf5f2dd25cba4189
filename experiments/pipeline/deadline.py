"""A wall-clock budget for a long job: stop cleanly between steps, resume later.

A batch system (SLURM's ``--time``) or a lent machine kills a job at a fixed
time, usually in the middle of a step whose work is then lost. A script run
with ``--time_limit=S`` (``cli.run`` sets it, counting from the process's
start) instead stops *before* a step that would not finish in time: the
lockstep estimate (``estimation.estimate_many``) checks before each step, with the
last step's duration as the forecast (its compile and set-up, ``physsim.one_off``,
paid again only for a new program; the rest scaled by its candidates over its
simulations where searches shared worlds: ``objective.distinct_worlds``), a
dataset sweep before each batch, and
a network's training before each epoch (``model.fit``'s ``after_epoch``).
Everything finished so far is on disk (each search saves its state every
step), so the same command resumes where it stopped. The script ends with one
line and exit status ``EXIT_STATUS`` (75, ``EX_TEMPFAIL``: try again).
"""

from __future__ import annotations

import time

# sysexits.h EX_TEMPFAIL: a temporary failure, the user is invited to retry.
EXIT_STATUS = 75

_deadline: float | None = None
# When this process started, near enough: cli imports this module first thing.
STARTED = time.monotonic()


class Reached(Exception):
  """The budget would run out during the next step; nothing of it started."""


def set_limit(seconds: float, start: float | None = None) -> None:
  """Stops later steps ``seconds`` after ``start`` (``time.monotonic()``
  seconds, default now); 0 clears the limit.

  Raises:
    ValueError: a negative or non-finite ``seconds``.
  """
  global _deadline
  if not (seconds >= 0 and seconds < float('inf')):
    raise ValueError(f'--time_limit={seconds}: need a finite number of seconds >= 0')
  _deadline = (
    None if seconds == 0 else (time.monotonic() if start is None else start) + seconds
  )


def remaining() -> float | None:
  """Seconds left, or None without a limit."""
  return None if _deadline is None else _deadline - time.monotonic()


def check(forecast_s: float, what: str) -> None:
  """Raises ``Reached`` when ``what`` (e.g. 'step 3'), forecast to take
  ``forecast_s`` seconds, would end after the deadline."""
  left = remaining()
  if left is not None and forecast_s > left:
    raise Reached(
      f'stopped before {what} (forecast {forecast_s:.0f} s, {max(left, 0.0):.0f} s of '
      f'--time_limit left)'
    )
