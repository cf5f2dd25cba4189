"""Where an estimate's configuration goes (issue 75, item 2): the modules of
the project's functions that are handed the whole ``EstimateConfig``, in the
order they are called.

The configuration is resolved once, at the edge (``setup``), and each stage
should be handed its own section only: followed from ``estimation.estimate``,
the whole config should never come back to a module it has left. ``trace``
records, under ``sys.setprofile`` (the calling thread only), every call into
the project's packages that receives the config as an argument (positional,
keyword, ``*args`` or ``**kwargs``), each marked by how:

  'direct': handed an ``EstimateConfig`` itself (or a list or tuple of them:
    several searches' configs);
  'own': so handed, but by the config's own methods (``check``'s
    ``cli.check_numbers``): the config reading itself, no stage;
  'held': handed a value that holds one in a field (a ``Setup``, a ``Job``,
    a ``Problem``): where the whole config still travels inside another
    (the holder's own methods, handed it as ``self``, aside).

(The config's own methods themselves are left out.) ``path`` collapses
consecutive repeats of the chosen kinds into stays; ``returns`` counts the
stays in a module the path had left before.

  calls = trace(estimation.estimate, config, recording, '', workdir)
  stays = path(calls)  # 'direct' only
  print(len(stays), returns(stays))
"""

from __future__ import annotations

import dataclasses
import inspect
import sys
from collections.abc import Callable
from typing import NamedTuple

from experiments.pipeline.config import EstimateConfig

PACKAGES = ('physsim', 'model', 'bo', 'experiments')


class Call(NamedTuple):
  """One call handed the config: its module, function and how (``_how``)."""

  module: str
  function: str
  how: str


def _arguments(frame) -> list:
  """The values a called frame was handed (its parameters but ``self``,
  ``*args``'s items and ``**kwargs``'s values), read at its 'call' event."""
  code = frame.f_code
  n = code.co_argcount + code.co_kwonlyargcount
  names = [name for name in code.co_varnames[:n] if name != 'self']
  star = code.co_varnames[n : n + bool(code.co_flags & inspect.CO_VARARGS)]
  n += len(star)
  stars = code.co_varnames[n : n + bool(code.co_flags & inspect.CO_VARKEYWORDS)]
  values = [frame.f_locals.get(name) for name in names]
  for name in star:
    values.extend(frame.f_locals.get(name) or ())
  for name in stars:
    values.extend((frame.f_locals.get(name) or {}).values())
  return values


def _is_own_method(frame) -> bool:
  """A frame of ``EstimateConfig``'s own methods (``flat``, ``check``,
  ``replace``, its properties, its classmethods)."""
  names = frame.f_code.co_varnames
  return (
    frame.f_globals.get('__name__') == EstimateConfig.__module__
    and bool(names)
    and names[0] in ('self', 'cls')
    and isinstance(frame.f_locals.get(names[0]), EstimateConfig | type)
  )


def _is_config(value) -> bool:
  """An ``EstimateConfig``, or a list or tuple of them."""
  if isinstance(value, list | tuple) and not hasattr(value, '_fields') and value:
    return all(isinstance(v, EstimateConfig) for v in value)
  return isinstance(value, EstimateConfig)


def _holds(value) -> bool:
  """A dataclass or named tuple with an ``EstimateConfig`` field (or a list
  of them: several searches' jobs)."""
  if isinstance(value, list) and value:
    return _holds(value[0])
  if dataclasses.is_dataclass(value) and not isinstance(value, type):
    fields = [getattr(value, f.name, None) for f in dataclasses.fields(value)]
  elif isinstance(value, tuple) and hasattr(value, '_fields'):
    fields = list(value)
  else:
    return False
  return any(isinstance(v, EstimateConfig) for v in fields)


def _how(frame) -> str | None:
  """How a called frame was handed the config ('direct', 'own', 'held'), or
  None: not at all, or it is the config's own method."""
  if _is_own_method(frame):
    return None
  values = _arguments(frame)
  if any(_is_config(v) for v in values):
    return 'own' if frame.f_back and _is_own_method(frame.f_back) else 'direct'
  return 'held' if any(_holds(v) for v in values) else None


def trace(fn: Callable, *args, **kw) -> list[Call]:
  """Calls ``fn(*args, **kw)``; returns, in call order, every call into
  ``PACKAGES`` handed the config (``Call``)."""
  calls = []

  def profile(frame, event, _):
    if event != 'call':
      return
    module = frame.f_globals.get('__name__') or ''
    if module.partition('.')[0] not in PACKAGES:
      return
    how = _how(frame)
    if how:
      calls.append(Call(module, frame.f_code.co_qualname, how))

  previous = sys.getprofile()
  sys.setprofile(profile)
  try:
    fn(*args, **kw)
  finally:
    sys.setprofile(previous)
  return calls


def path(calls: list[Call], kinds: tuple[str, ...] = ('direct',)) -> list[str]:
  """The modules of the ``calls`` of ``kinds``, consecutive repeats
  collapsed: one per stay."""
  out = []
  for call in calls:
    if call.how in kinds and (not out or out[-1] != call.module):
      out.append(call.module)
  return out


def returns(stays: list[str]) -> int:
  """The stays in a module that the path had already left."""
  seen, n = set(), 0
  for module in stays:
    n += module in seen
    seen.add(module)
  return n
