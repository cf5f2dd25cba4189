"""The errors an estimate carries into its posterior, against those a
calibration's tables were measured with.

An estimate's posterior carries the uncertainty of what it was given: a
reading's (an anemometer's, a scale's, an overhang's bending length) and the
camera's placement in the simulator's world (``camera_sd_m`` /
``camera_sd_deg``: the intake's alignment error). A calibration's tables hold
for estimates whose carried errors are like those its held-out recordings
had: a reading's relative error within a factor of two of the one its
recordings were drawn with (or within the range drawn); a camera's error in
each of its shift and tilt within the range the study drew its recordings'
over (``camera_sd_spread``: each recording its own), or within a factor of
two of the one error they all had; a camera known exactly (0) only where the
study's was too. Outside, the note says which error, and what the tables
were measured at.
"""

from __future__ import annotations

import glob
import math

# The estimate's camera error, as ``EstimateConfig.flat`` names it: a shift
# (metres) and a tilt about the pins (degrees), 1 sd per axis.
CAMERA_FIELDS = ('camera_sd_m', 'camera_sd_deg')
# How far a carried error may be from the calibrated one, as a factor either way.
FACTOR = 2.0


def readings_of(mode: str | None) -> tuple[str, ...]:
  """The readings a calibration mode's estimates were given (their
  uncertainty must be within a factor of two of the calibrated one)."""
  return {
    'known wind': ('wind_speed',),
    'known area weight': ('area_weight',),
    'joint pair, known winds': ('wind_speed',),
    'bending length': ('bending_length',),
    'known wind, bending length': ('wind_speed', 'bending_length'),
    'bending length (ruler)': ('bending_length',),
    'known wind, bending length (ruler)': ('wind_speed', 'bending_length'),
  }.get(mode, ())


def calibrated_range(rec: dict, name: str) -> tuple[float | None, float | None]:
  """The relative errors of reading ``name`` an estimate may have and quote a
  calibration's tables: the range its recordings' readings were drawn over
  (a bending length's ``length_sd_range``), else within a factor of two of
  the one error they all had."""
  if name == 'bending_length' and 'length_sd_range' in rec:
    lo, hi = rec['length_sd_range']
    return float(lo), float(hi)
  sd = rec.get('length_sd' if name == 'bending_length' else 'measured_sd')
  return (None, None) if sd is None else (sd / FACTOR, FACTOR * sd)


def pct_range(rec: dict, name: str) -> str:
  """The simulated readings' relative error as the calibration line prints it."""
  if name == 'bending_length' and 'length_sd_range' in rec:
    lo, hi = rec['length_sd_range']
    return f'{100 * lo:.2g}-{100 * hi:.2g}% (median {100 * rec["length_sd"]:.2g}%)'
  return f'{100 * rec["length_sd" if name == "bending_length" else "measured_sd"]:.2g}%'


def law_words(dof: float) -> str:
  """A reading's error law in words: a t's degrees of freedom, or Gaussian."""
  return f"Student's t, {dof:g} degrees of freedom" if dof else 'Gaussian'


def reading_differences(measured, rec: dict, mode: str | None) -> list[str]:
  """The readings of ``mode`` whose uncertainty (or a bending length's error
  law) lies outside what the tables ``rec`` were drawn with, each in words."""
  differs = []
  for name in readings_of(mode):
    value, sd = getattr(measured, name), getattr(measured, f'{name}_sd')
    lo, hi = calibrated_range(rec, name)
    if lo is None or not lo <= sd / value <= hi:
      differs.append(
        f'{name} reading uncertainty ({100 * sd / value:.1f}%; calibrated: '
        + (f'{pct_range(rec, name)})' if lo is not None else 'none)')
      )
    if name == 'bending_length':  # the reading's error law, as the tables drew it
      dof = measured.bending_length_dof
      theirs = 0.0 if mode.endswith('(ruler)') else rec.get('length_dof', 0.0)
      if dof != theirs:
        differs.append(
          f'bending length error law ({law_words(dof)}; calibrated: {law_words(theirs)})'
        )
  return differs


def covers(calibrated: float, mine: float, spread: float = 0.0) -> bool:
  """Whether tables measured with one camera error component (a shift's or a
  tilt's sd) hold for an estimate carrying ``mine``: within the range their
  recordings' errors were drawn over (``spread`` > 0: ``calibrated`` x
  exp(+-spread)), else within a factor of two of it; a camera known exactly
  (0) is covered only by tables of 0, and tables of 0 cover only it (their
  recordings' cameras were exact)."""
  if calibrated <= 0.0 or mine <= 0.0:
    return math.isclose(calibrated, mine, abs_tol=1e-12)
  lo, hi = spread_range(calibrated, spread)
  return lo * (1 - 1e-9) <= mine <= hi * (1 + 1e-9)


def spread_range(sd: float, spread: float) -> tuple[float, float]:
  """The errors tables measured at ``sd`` hold for: ``sd`` x exp(+-spread)
  where their recordings' errors were drawn over that range, else from half
  to twice ``sd``."""
  f = math.exp(spread) if spread > 0 else FACTOR
  return sd / f, sd * f


def table_of(cal: dict) -> tuple[float, float, float]:
  """(metres, degrees, spread): the camera error a calibration ``cal``'s
  estimates carried (the centre of its range) and how far its recordings'
  were drawn about it (``camera_sd_spread``; 0: all had that one)."""
  config = cal.get('config', {})
  m, deg = camera_of(config.get('estimate', {}))
  return m, deg, float(config.get('camera_sd_spread', 0.0))


def source_of(flat: dict) -> str:
  """Where the camera error of an estimate's flat settings came from
  (``Scoring.camera_sd_from``): 'given' (a user's, or none; files from
  before it was a setting) or 'intake'."""
  return str(flat.get('camera_sd_from', 'given'))


def table_source(cal: dict) -> str:
  """How a calibration ``cal``'s recordings' cameras were displaced: 'given'
  (by the full error each estimate carried) or 'intake' (as the intake
  actually errs against what it claims, ``experiments.calibrate
  --camera_errors``)."""
  return source_of(cal.get('config', {}).get('estimate', {}))


def table_recordings(cal: dict) -> str:
  """Whose recordings a calibration ``cal``'s tables were fitted on: 'rig'
  (a user's rig's, taken in through the intake: ``calibrate --rig_runs``)
  or 'simulated' (the study's own)."""
  return 'rig' if cal.get('config', {}).get('rig_runs') else 'simulated'


def source_holds(table: str, mine: str) -> bool:
  """Whether tables of cameras displaced as ``table`` says hold for an
  estimate whose error came from ``mine``: the full claimed error's for any
  (they displace at least as far as any honest claim); the intake's actual
  errors' only for the intake's own claims (a user's claim is not known to
  err as the intake does)."""
  return table == 'given' or table == mine


def camera_of(flat: dict) -> tuple[float, float]:
  """(metres, degrees): the camera error of an estimate's flat settings
  (``EstimateConfig.flat``, or a calibration's ``config.estimate``); 0 where
  not recorded (files from before it was a setting: exact cameras)."""
  return tuple(float(flat.get(f, 0.0)) for f in CAMERA_FIELDS)


def camera_gap(calibrated: tuple[float, float], mine: tuple[float, float]) -> float:
  """How far a carried camera error is from a calibrated one: the sum of the
  components' absolute log ratios (0 where equal, infinite where only one of
  them is 0): of tables whose recordings all carried one error, how unlike
  this one they were (``recordings_gap``), and of raised claims the nearest."""
  gap = 0.0
  for c, m in zip(calibrated, mine, strict=True):
    if c <= 0.0 or m <= 0.0:
      gap += 0.0 if c == m == 0.0 else math.inf
    else:
      gap += abs(math.log(m / c))
  return gap


def recordings_gap(table: tuple[float, ...], mine: tuple[float, float]) -> float:
  """How far a carried camera error lies, on average, from the errors a
  table's held-out recordings carried: per component the mean absolute log
  ratio to errors drawn log-uniformly over the table's range (``table``:
  metres, degrees, spread; its recordings' errors were the centre times
  exp(spread x u), u uniform in [-1, 1]), or ``camera_gap``'s where they all
  carried one. Of the tables covering an estimate, the one whose recordings
  were most like it is the least: a narrow range wins over a wide one
  centred nearer, whose coverage is averaged over errors far from this one."""
  m, deg, spread = (*table, 0.0)[:3]
  if spread <= 0.0:
    return camera_gap((m, deg), mine)
  gap = 0.0
  for c, x in zip((m, deg), mine, strict=True):
    if c <= 0.0 or x <= 0.0:
      gap += 0.0 if c == x == 0.0 else math.inf
      continue
    d = abs(math.log(x / c))  # E|d - spread u|: (s^2 + d^2) / 2s inside, d past it
    gap += (spread**2 + d**2) / (2 * spread) if d < spread else d
  return gap


def camera_words(sd: tuple[float, float]) -> str:
  """A camera error as the notes print it: '8.5 cm / 3 deg'."""
  return f'{100 * sd[0]:.3g} cm / {sd[1]:.3g} deg'


def table_words(table: tuple[float, ...]) -> str:
  """The camera errors a calibration's tables were measured at, in words:
  'exact cameras', '4 cm / 2.5 deg', or a range drawn per recording,
  '1.3-12 cm / 0.8-7.5 deg'."""
  m, deg, spread = (*table, 0.0)[:3]
  if not (m or deg):
    return 'exact cameras'
  if spread <= 0:
    return camera_words((m, deg))
  (m0, m1), (d0, d1) = spread_range(m, spread), spread_range(deg, spread)
  return f'{100 * m0:.2g}-{100 * m1:.2g} cm / {d0:.2g}-{d1:.2g} deg'


def camera_difference(
  mine: tuple[float, float], levels: list, what: str = 'tables'
) -> str:
  """The note's words for a carried camera error no table covers: the error
  and the camera errors the shipped tables (or ``what`` else was measured)
  were measured at (``levels``: (metres, degrees) or with their spread,
  ``table_of``), e.g. "camera alignment error 8.5 cm / 3 deg, 1 sd (tables
  measured at exact cameras; 2 cm / 2 deg; each holds from half to twice its
  own)"."""
  tables = sorted({(*t, 0.0)[:3] for t in levels})
  have = '; '.join(table_words(t) for t in tables)
  if any((t[0] or t[1]) and not t[2] for t in tables) or not tables:
    have += ('; ' if have else 'none; ') + 'each holds from half to twice its own'
  error = (
    f'alignment error {camera_words(mine)}, 1 sd' if any(mine) else 'known exactly'
  )
  return f'camera {error} ({what} measured at {have})'


def camera_path(
  base: str,
  sd: tuple[float, float],
  spread: float = 0.0,
  source: str = 'given',
  recordings: str = '',
) -> str:
  """Where tables measured with camera error ``sd`` are shipped beside the
  file ``base`` of exact cameras: ``base`` itself for (0, 0), else
  ``<base>_camera_<cm>cm_<deg>deg.json``, or for a range drawn per recording
  (``spread``) ``<base>_camera_<cm>-<cm>cm_<deg>-<deg>deg.json``; with
  ``_camera_intake_`` where the cameras were displaced as the intake errs
  (``source`` 'intake'), ``_camera_intake_rig_`` where the recordings were
  a user's rig's taken in through the intake (``recordings`` 'rig')."""
  if not any(sd):
    return base
  words = table_words((*sd, spread)).replace(' ', '').replace('/', '_')
  kind = 'camera_intake' if source == 'intake' else 'camera'
  kind += '_rig' if recordings == 'rig' else ''
  return f'{base.removesuffix(".json")}_{kind}_{words}.json'


def camera_paths(base: str) -> list[str]:
  """The files of tables measured with a camera error shipped beside
  ``base`` (``camera_path``), in order."""
  return sorted(glob.glob(f'{glob.escape(base.removesuffix(".json"))}_camera_*.json'))
