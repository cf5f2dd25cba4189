"""The protocol study's settings: its config and presets, and its list flags
read (truths' bending scales, candidate sets sharing a fan setting or not)."""

from __future__ import annotations

import dataclasses

import numpy as np

import physsim
from experiments.studies import protocol_candidates

# The study's search box: a recording may be windless.
SPACE = physsim.SearchSpace(wind_speed=(0.0, 6.0))


@dataclasses.dataclass(frozen=True)
class Config:
  """The protocol study.

  Attributes:
    material: the fabric.
    bendings: truths' bending scales (comma-separated).
    area_weight: the truths' area weight, kg/m^2 (0: the middle of the range).
    candidates: candidate recordings (``protocol_candidates.Candidate.name``s,
      comma-separated).
    convergence: candidates simulated at a finer mesh too, at the first truth
      (names, comma-separated; same size and wind, another resolution).
    sets: candidate sets ``label=name+name+...`` (semicolon-separated); the
      ``rNN`` suffix may be left off (the candidate's own resolution).
    gusts: RMS relative gust intensity of the noise replicates.
    draws: gust histories per candidate with wind (>= 3).
    clip: seconds summarised per recording.
    warmup: seconds simulated before the clip.
    fps: frames per second summarised.
    camera_fps: the depth camera's frame rate (its noise averages over it).
    step_bending: half-step of the central differences in log bending.
    step_area_weight: half-step of the central differences in log area weight.
    step_wind: half-step of the central differences in log wind speed.
    setup_mm: set-up repeatability added to every position statistic, mm.
    curvature_floor: floor of the curvature statistic's noise (size / m).
    shrink: weight of the gust covariance's diagonal (``bo.design.shrink``).
    reading: relative standard error of an anemometer's or scale's reading.
    drag_sd: prior standard deviation of the log of the wind force's
      coefficient, shared by a set's recordings in the fan: how far the
      simulator's drag law may be from the world's
      (``protocol_bound.set_narrowing``; 0: trusted, as the first studies did).
    workers: MuJoCo C processes.
    seed: gust histories.
    scaled_edges: the edges' time constant shrinks with the spacing
      (``physsim.config_for_mesh``: the same stretch stiffness on every mesh
      and cloth size; the default); off: the fixed one of the first study.
    stats: the statistics the bound reads (names of
      ``protocol_camera.STATS``, comma-separated; empty: all six). The estimate's shape distance reads
      the sheet's mean position alone (``centroid_out,centroid_up``); the
      slopes are simulated for all of them either way (one cache).
  """

  material: str = 'gray_interlock'
  bendings: tuple[str, ...] = ('0.3', '1', '3')
  area_weight: float = 0.0
  candidates: tuple[str, ...] = (
    'sheet_100cm_2ms_r9', 'sheet_100cm_3.5ms_r9', 'sheet_100cm_5ms_r9',
    'sheet_100cm_still_r9', 'overhang_3cm_r9', 'overhang_5cm_r9',
    'overhang_10cm_r9', 'swatch_20cm_2ms_r17',
  )  # fmt: skip
  convergence: tuple[str, ...] = (
    'overhang_5cm_r13', 'overhang_5cm_r17', 'swatch_20cm_2ms_r9',
  )  # fmt: skip
  sets: str = (
    'sheet 2 m/s=sheet_100cm_2ms;'
    'sheet 3.5 m/s=sheet_100cm_3.5ms;'
    'sheet 5 m/s=sheet_100cm_5ms;'
    'sheet still=sheet_100cm_still;'
    'swatch 20 2 m/s=swatch_20cm_2ms;'
    'overhang 3=overhang_3cm;'
    'overhang 5=overhang_5cm;'
    'overhang 10=overhang_10cm;'
    'overhang 3+5=overhang_3cm+overhang_5cm;'
    'sheet x3=sheet_100cm_2ms+sheet_100cm_3.5ms+sheet_100cm_5ms;'
    'sheet 2 + swatch 20=sheet_100cm_2ms+swatch_20cm_2ms;'
    'sheet 2 + overhang 5=sheet_100cm_2ms+overhang_5cm;'
    'sheet x3 + overhang 5=sheet_100cm_2ms+sheet_100cm_3.5ms+sheet_100cm_5ms+overhang_5cm;'
    'sheet x3 + overhangs 3+5=sheet_100cm_2ms+sheet_100cm_3.5ms+sheet_100cm_5ms'
    '+overhang_3cm+overhang_5cm'
  )
  gusts: float = 0.3
  draws: int = 6
  clip: float = 1.5
  warmup: float = 1.0
  fps: float = 20.0
  camera_fps: float = 30.0
  step_bending: float = 0.2
  step_area_weight: float = 0.05
  step_wind: float = 0.05
  setup_mm: float = 2.0
  curvature_floor: float = 0.05
  shrink: float = 0.5
  reading: float = 0.02
  drag_sd: float = 0.0
  workers: int = 1
  seed: int = 0
  scaled_edges: bool = True
  stats: tuple[str, ...] = ()


PRESETS = {
  # about 25 minutes on 16 cores (MuJoCo C, --workers=16): the overhangs' 3 cm
  # 1.5 min, the 20 cm swatch in wind 1.8 min a truth
  'default': Config(),
  # every candidate of the first study (10-30 cm swatches, still, one pin) as
  # well: about 40 minutes more on 16 cores
  'full': Config(
    candidates=Config.candidates
    + (
      'swatch_10cm_still_r9',
      'swatch_20cm_still_r9',
      'swatch_30cm_still_r9',
      'swatch_10cm_2ms_r13',
      'swatch_30cm_2ms_r17',
      'swatch_20cm_2ms_1pin_r17',
    ),
    convergence=Config.convergence
    + (
      'swatch_20cm_2ms_r25',
      'swatch_20cm_2ms_1pin_r9',
      'sheet_100cm_5ms_r17',
    ),
    sets=Config.sets
    + (
      ';swatch 10 2 m/s=swatch_10cm_2ms;swatch 30 2 m/s=swatch_30cm_2ms;'
      'swatch 20 still=swatch_20cm_still;swatch 20 1 pin=swatch_20cm_2ms_1pin;'
      'swatches 10+20+30 2 m/s=swatch_10cm_2ms+swatch_20cm_2ms+swatch_30cm_2ms'
    ),
  ),
  # the end-to-end path on a CPU in well under a minute: one truth, two tiny
  # candidates, short clips
  'smoke': Config(
    bendings=('1',),
    candidates=('swatch_20cm_still_r5', 'sheet_100cm_2ms_r5'),
    convergence=('swatch_20cm_still_r7',),
    sets='sheet=sheet_100cm_2ms;swatch=swatch_20cm_still;both=sheet_100cm_2ms+swatch_20cm_still',
    draws=3,
    clip=0.5,
    warmup=0.25,
  ),
}


def floats(name: str, values) -> list[float]:
  """A list flag's values as positive numbers; a ValueError naming the flag."""
  try:
    out = [float(v) for v in values]
  except ValueError:
    out = []
  if not out or not all(np.isfinite(v) and v > 0 for v in out):
    raise ValueError(f'--{name}={",".join(values)}: need positive numbers')
  return out


def _wind(name: str) -> float:
  """The fan's wind of the candidate ``name``, m/s."""
  return protocol_candidates.parse(name).wind


def parse_sets(text: str, names: list[str]) -> dict[str, list[str]]:
  """``label=a+b;...`` as {label: [candidate names]}, each resolved against
  ``names`` (a name without its ``_rNN`` suffix means the one listed). A
  member joined by ``&`` instead of ``+`` was recorded at the same fan
  setting as the one before it, the fan untouched (one wind for both): its
  name keeps a leading ``&`` (``shares_wind``)."""
  out = {}
  for item in filter(None, (s.strip() for s in text.split(';'))):
    label, _, members = item.partition('=')
    resolved = []
    for part in filter(None, members.split('+')):
      for j, m in enumerate(part.split('&')):
        hits = [n for n in names if n == m or n.rsplit('_r', 1)[0] == m]
        if len(hits) != 1:
          raise ValueError(f'--sets: {m!r} in {label!r} is not one of --candidates')
        if j and not (0 < _wind(hits[0]) == _wind(resolved[-1])):
          raise ValueError(
            f'--sets: {m!r} in {label!r} shares the wind (&) of a recording at '
            'another fan setting, or of one without a fan'
          )
        resolved.append(('&' if j else '') + hits[0])
    if not label or not resolved:
      raise ValueError(f'--sets: {item!r} is not label=candidate+candidate')
    out[label.strip()] = resolved
  return out


def shares_wind(member: str) -> tuple[str, bool]:
  """A ``parse_sets`` member: its candidate's name, and whether it shares the
  wind of the member before it."""
  return member.removeprefix('&'), member.startswith('&')
