"""What ``estimate`` tells a person beside the table: settings whose intervals
not to trust as they stand, and what to record or measure next.

Each function returns one line to print, or None where there is nothing to
say. The warnings come before the search (from the settings alone); the
notes after it (from the estimate's load ratio and narrowing).
"""

from __future__ import annotations

import numpy as np

import physsim
from experiments.pipeline import objective as obj_lib
from experiments.pipeline.config import Scoring
from experiments.pipeline.measurements import Measured

# One clip reads the load ratio about twice as poorly above STRONG_LOAD_RATIO as
# below GENTLE_LOAD_RATIO, and a longer clip helps only below (the sheet blown
# nearly flat; benchmarks/gust_floor.py at c465b0e, docs/studies/benchmarks.md).
STRONG_LOAD_RATIO = 10.0
GENTLE_LOAD_RATIO = 8.0
# Below this narrowing (the prior's 90% width over the posterior's) a
# recording has told little about a fabric parameter.
LITTLE_NARROWING = 1.5


def shape_camera_warning(sc: Scoring, aligned: bool) -> str | None:
  """The line ``estimate`` prints when a shape discrepancy (the scoring's
  distance, which reads centimetres in the simulator's world) trusts a camera
  that the intake's alignment placed there (``aligned``) as exact (no
  ``camera_sd``); else None."""
  if (
    sc.distance not in obj_lib.SHAPE_DISTANCES
    or sc.camera_sd_m
    or sc.camera_sd_deg
    or not aligned
  ):
    return None
  return (
    f'warning: --distance={sc.distance} reads where the sheet hangs in the '
    "simulator's world, and the intake placed your camera there by its alignment "
    '(within about 2 cm and 3 degrees on its test); with --camera_sd_m=0 '
    '--camera_sd_deg=0 the posterior trusts that placement exactly. Give its '
    'error, e.g. --camera_sd_m=0.02 --camera_sd_deg=3'
  )


def synthetic_warning(scoring: Scoring) -> str | None:
  """The line ``estimate`` prints for the scoring's 'synthetic' likelihood
  (else None): it takes the recording's scatter to be the simulator's. On
  real-like recordings simulated with another mesh and gust level its
  intervals were too narrow; with their own (``cloth_resolution``,
  ``gusts``) they held (BENCHMARKS.md)."""
  if scoring.likelihood != 'synthetic':
    return None
  return (
    'warning: --likelihood=synthetic trusts the simulator to scatter as your '
    'recording does; on real-like recordings simulated with another mesh and gust '
    'level its 90% intervals held the wind and the load ratio only 50-67% of the '
    "time (the default 'gibbs' 83%), with their own (--cloth_resolution, --gusts) "
    '83-100%: report its intervals only when the simulator matches your set-up'
  )


def fan_setting_note(load_ratios, material: str) -> str | None:
  """The line ``estimate`` prints when every recording's load ratio (posterior
  medians) is above ``STRONG_LOAD_RATIO``: such fan settings read area weight
  hardly better than its range, while three gentler ones (the wind that gives
  ``GENTLE_LOAD_RATIO`` at the fabric's middle area weight), each with an
  anemometer reading, estimated jointly, read it about twice as well as the
  range (BENCHMARKS.md); else None."""
  ratios = np.atleast_1d(np.asarray(load_ratios, np.float64))
  if not np.all(ratios > STRONG_LOAD_RATIO):
    return None
  w = float(physsim.search_space(material).center().area_weight)
  gentle = float(
    np.sqrt(GENTLE_LOAD_RATIO * w * physsim.params.GRAVITY / physsim.params.AIR_DENSITY)
  )
  seen = ', '.join(f'{r:.0f}' for r in ratios)
  return (
    f'note: load ratio rho v^2/(w g) about {seen}: at fan settings this strong the '
    'sheet is blown nearly flat and a clip reads the area weight hardly better than '
    f'its range; to measure it, record three gentler settings (load ratio under '
    f'{GENTLE_LOAD_RATIO:g}: about {gentle:.1f} m/s or less for {material}), each '
    'with an anemometer reading, and estimate them jointly (--recording=a,b,c '
    '--wind_speeds=...; docs/identifiability.md)'
  )


def next_recording_note(shared: dict, measured: Measured, workdir: str) -> str | None:
  """The one line ``estimate`` prints after every estimate whose bending or
  area weight the recordings left near the prior (``shared``: an estimate's
  ``estimate`` entries, or a joint estimate's shared ones) and no reading
  (``measured``) gave: what to record or
  measure next by the protocol study's bound (docs/studies/protocol.md), and the
  command that ranks candidates with the simulator from this posterior."""
  # narrowing is the video's over the prior with the readings: a parameter a
  # reading measured (the strip's bending length, a scale's area weight) is
  # not left at the prior however little the video added
  read = {'bending_scale': measured.bending_length_sd > 0,
          'area_weight': measured.area_weight_sd > 0}  # fmt: skip
  little = [
    name for name in ('bending_scale', 'area_weight')
    if shared.get(name, {}).get('narrowing_90', np.inf) < LITTLE_NARROWING
    and not read[name]
  ]  # fmt: skip
  if not little:
    return None
  steps = []
  if 'area_weight' in little:
    steps.append(
      'weigh the sheet and measure its sides (--area_weight=... --area_weight_sd=...)'
    )
  if 'bending_scale' in little:
    steps.append(
      'lay a strip of it over a table edge and measure its bending length (the '
      'cantilever test: README, How to record; --bending_length=... '
      '--bending_length_sd=...)'
    )
  told = ' and '.join(n.replace('_scale', '').replace('_', ' ') for n in little)
  return (
    f'next: the recording(s) told little about {told}; ' + '; '.join(steps) + '. '
    f'python -m experiments.plan --workdir={workdir} ranks what to record next '
    'with the simulator'
  )
