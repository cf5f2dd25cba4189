"""Atomic writes for experiment outputs (``physsim.dataset``'s writers, plus figures).

An interrupted script never leaves a half-written JSON, text or PNG under its
final name.
"""

from __future__ import annotations

import os

from model import config_io
from physsim.dataset import write_atomic
from physsim.dataset import write_json_atomic as write_json
from physsim.dataset import write_text_atomic as write_text

__all__ = ['resume', 'savefig', 'write_atomic', 'write_json', 'write_text']


def savefig(fig, path: str, dpi: int = 100) -> None:
  """Saves a matplotlib figure as PNG, atomically."""
  write_atomic(path, lambda p: fig.savefig(p, dpi=dpi, format='png'))


def resume(path: str, config) -> dict:
  """What an earlier run of the same config saved in the JSON at ``path``
  (``{'config': ..., ...}``), or {} when there is none or its config differs
  (JSON turns tuples into lists, so the configs are compared as dataclasses)."""
  if not os.path.exists(path):
    return {}
  data = config_io.read_json(path)
  try:
    same = config_io.from_dict(type(config), data.get('config')) == config
  except (ValueError, TypeError):
    same = False
  return data if same else {}
