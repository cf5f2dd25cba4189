"""Benchmarks: each module is a script on the scripts' one config mechanism
(``experiments.pipeline.cli``: a frozen ``Args`` dataclass and its presets).
Run one from the repository root::

  python -m benchmarks.NAME --help

Each prints its table and writes its JSON (by default under ``out/benchmarks``,
outside the source tree).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

OUT = os.path.join('out', 'benchmarks')


def out_path(name: str) -> str:
  """The default JSON path of benchmark ``name``: ``out/benchmarks/NAME.json``."""
  return os.path.join(OUT, f'{name}.json')


def floats(flag: str, values: Sequence[str], *, positive: bool = False) -> list[float]:
  """A list flag's values as floats (finite; > 0 with ``positive``).

  Raises:
    ValueError: naming the flag and its value, when one is not a number,
      not finite or (with ``positive``) not positive, or none is given.
  """
  try:
    out = [float(v) for v in values]
  except ValueError:
    out = []
  if not out or not all(math.isfinite(v) and (v > 0 or not positive) for v in out):
    need = 'positive numbers' if positive else 'numbers'
    raise ValueError(f'--{flag}={",".join(values)}: need {need}, comma-separated')
  return out


def ints(flag: str, values: Sequence[str], *, positive: bool = True) -> list[int]:
  """A list flag's values as integers (> 0 unless ``positive`` is False).

  Raises:
    ValueError: naming the flag and its value.
  """
  try:
    out = [int(v) for v in values]
  except ValueError:
    out = []
  if not out or not all(v > 0 or not positive for v in out):
    need = 'positive integers' if positive else 'integers'
    raise ValueError(f'--{flag}={",".join(values)}: need {need}, comma-separated')
  return out
