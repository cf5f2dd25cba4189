"""The protocol study's candidate recordings: what a person could record, by
name, and the mesh the simulator gives it.

A candidate is a piece of the fabric (the 1 m sheet, or a 10-30 cm swatch)
pinned at its two top corners (or one) in front of a fan at one setting (or
none), or the fabric flat on a table with a few centimetres of it over the
edge (an overhang). Its name (``Candidate.name``, read back by ``parse``) is
how the study's flags, its cached slopes and ``experiments.plan`` speak of it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

import physsim


@dataclasses.dataclass(frozen=True)
class Candidate:
  """One recording a person could make.

  Attributes:
    size: the cloth's side, m.
    wind: the fan's mean wind, m/s (0: no fan).
    pins: 2 (the two top corners) or 1 (the top-left corner).
    resolution: vertices a side of the simulated square.
    overhang: the square lies flat on a table and ``size`` of it overhangs the
      edge, in still air, filmed from the side (the textile cantilever test,
      ASTM D1388: the droop is set by the bending length
      (D / (w g))^(1/3) over the overhang); else it hangs from its pins.
    hem: grams of known mass taped evenly along the free bottom edge (coins:
      a US nickel is 5.000 g, a 1-euro coin 7.50 g), 0 for none
      (``physsim.hem_mass``). In a fan the cloth's weight is then measured
      against a known one: the wind's push, whatever the drag law, is the same
      with and without it at one fan setting.
  """

  size: float
  wind: float
  pins: int = 2
  resolution: int = 9
  overhang: bool = False
  hem: float = 0.0

  @property
  def name(self) -> str:
    cm = round(100 * self.size)
    if self.overhang:
      return f'overhang_{cm}cm_r{self.resolution}'
    where = 'sheet' if self.size >= 0.5 else 'swatch'
    fan = f'{self.wind:g}ms' if self.wind > 0 else 'still'
    pin = '' if self.pins == 2 else '_1pin'
    hem = f'_hem{self.hem:g}g' if self.hem > 0 else ''
    return f'{where}_{cm}cm_{fan}{pin}{hem}_r{self.resolution}'


def parse(name: str) -> Candidate:
  """The candidate a ``Candidate.name`` names (e.g. ``'swatch_20cm_2ms_r9'``,
  ``'overhang_15cm_r17'``)."""
  parts = name.split('_')
  try:
    size = float(parts[1].removesuffix('cm')) / 100
    res = int(parts[-1].removeprefix('r'))
    if parts[0] == 'overhang':
      c = Candidate(size, 0.0, 2, res, overhang=True)
    else:
      wind = 0.0 if parts[2] == 'still' else float(parts[2].removesuffix('ms'))
      hems = [p for p in parts[3:-1] if p.startswith('hem')]
      hem = float(hems[0].removeprefix('hem').removesuffix('g')) if hems else 0.0
      c = Candidate(size, wind, 1 if '1pin' in parts else 2, res, hem=hem)
  except (IndexError, ValueError):
    raise ValueError(
      f'candidate {name!r}: need e.g. sheet_100cm_2ms_r9, swatch_20cm_still_r9, '
      'swatch_20cm_2ms_1pin_r9, sheet_100cm_2ms_hem100g_r9, overhang_15cm_r17'
    ) from None
  if c.name != name or not (
    0 < size <= 2 and 0 <= c.wind <= 6 and res >= 3 and 0 <= c.hem <= 1000
  ):
    raise ValueError(f'candidate {name!r} is not a canonical name (or out of range)')
  return c


def timestep(c: Candidate) -> float:
  """The simulator's step for the candidate's mesh spacing h: the bending
  force is explicit, so its stable step shrinks as h^2 (MuJoCo C blew up at
  bending 4.5x on a 6 mm mesh at 2 ms; 12.5 mm held 10x)."""
  h = c.size / (c.resolution - 1)
  return 0.002 if h >= 0.0124 else 0.001 if h >= 0.008 else 0.0005


def mesh(c: Candidate) -> physsim.Mesh:
  """The candidate's square, pinned at its two top corners or the top-left.

  An overhang lies flat, reaching out along +y: its first two rows are held
  (the table clamps the slope too), row 1 on the table's edge at y = 0 and
  row 0 one spacing back on the table, so that ``size`` is the free overhang
  on every mesh (the square's side is ``size`` plus that spacing)."""
  if c.overhang:
    h = c.size / (c.resolution - 2)
    m = physsim.square(c.resolution, c.size + h)
    v = m.vertices
    top = v[:, 2].max()
    flat = np.stack([v[:, 0], top - v[:, 2] - h, np.full(len(v), top)], axis=1)
    return dataclasses.replace(
      m, vertices=flat, pinned=np.arange(2 * c.resolution), name=m.name + '_overhang'
    )
  m = physsim.square(c.resolution, c.size)
  if c.pins == 1:
    m = dataclasses.replace(m, pinned=m.pinned[:1], name=m.name + '_1pin')
  return m
