"""A call that may block (``open()`` on a FIFO) run so that it fails the test
instead of hanging it."""

from __future__ import annotations

import threading


def in_thread(fn, timeout: float = 10.0):
  """fn() in a daemon thread: its value, or what it raised; an assertion
  error if it is still running after ``timeout`` seconds."""
  out = {}

  def target():
    try:
      out['value'] = fn()
    except BaseException as e:  # noqa: BLE001 - handed back to the test
      out['error'] = e

  t = threading.Thread(target=target, daemon=True)
  t.start()
  t.join(timeout)
  assert not t.is_alive(), f'blocked for {timeout} s'
  if 'error' in out:
    raise out['error']
  return out.get('value')
