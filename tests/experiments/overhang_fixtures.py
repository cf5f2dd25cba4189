"""A depth recording of a strip over a table's edge as a depth camera's tools
write it (``physsim.tabletop.write_recording``: 16-bit PNG frames in mm from
the project's ray-caster and the camera's OpenCV-style JSON)."""

from __future__ import annotations

from physsim import tabletop


def write_overhang_recording(root: str, bending_length: float = 0.02,
                             overhang: float = 0.04) -> tuple[str, str]:  # fmt: skip
  """(the frames' folder, the camera file) under ``root``."""
  return tabletop.write_recording(root, tabletop.Strip(overhang, bending_length))
