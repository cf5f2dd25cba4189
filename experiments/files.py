"""Atomic writes for experiment outputs (``physsim.dataset``'s writers, plus figures).

An interrupted script never leaves a half-written JSON, text or PNG under its
final name.
"""

from __future__ import annotations

from physsim.dataset import write_atomic
from physsim.dataset import write_json_atomic as write_json
from physsim.dataset import write_text_atomic as write_text

__all__ = ['savefig', 'write_atomic', 'write_json', 'write_text']


def savefig(fig, path: str, dpi: int = 100) -> None:
  """Saves a matplotlib figure as PNG, atomically."""
  write_atomic(path, lambda p: fig.savefig(p, dpi=dpi, format='png'))
