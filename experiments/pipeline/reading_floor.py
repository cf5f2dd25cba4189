"""A reading more precise than any calibration's, carried at their lowest.

A shipped calibration's tables, and a protocol check, hold for estimates whose
readings (an anemometer's wind, a scale's area weight, a bending length) had
a relative error like their simulated recordings' (``carried_errors``,
``protocol_checks``). A careful user's reading can be better than any of
them: a sheet weighed to 1 g of 150 g, a strip's overhang read to half a
millimetre. Its estimate would then print its intervals as indicative,
though a posterior that trusted the reading less would be covered.

So a reading up to ``RAISE`` times more precise than the lowest error a
shipped calibration or check was measured with is carried at that lowest
(its standard deviation raised, its value kept): the posterior a little
wider than the reading allows (wider is acceptable), its coverage the
measured one. The same rule raises an intake's claimed camera error
(``user_recordings.calibrated_camera``). A reading far below every range,
or one the tables would not cover for another reason, is carried as given.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

from experiments.pipeline import calibration_tables, carried_errors, protocol_checks

# At most this factor a reading's relative error is raised (``carried``).
RAISE = 2.0
# The readings an estimate may be given, as ``Measured`` names them.
READINGS = ('wind_speed', 'area_weight', 'bending_length')
# The readings a joint estimate's recordings share (each its own wind).
SHARED = ('area_weight', 'bending_length')


def floors(distance: str) -> dict[str, list[float]]:
  """The lowest relative error of each reading that a shipped calibration's
  tables (for ``distance``) or a shipped protocol check was measured with:
  the lower end of the range it holds (``carried_errors.calibrated_range``,
  ``protocol_checks.reading_range``)."""
  out: dict[str, set[float]] = {name: set() for name in READINGS}
  for path in calibration_tables.shipped_calibrations(distance):
    rec = calibration_tables.read_calibration(path).get('recalibration')
    for name in READINGS if rec else ():
      lo, _ = carried_errors.calibrated_range(rec, name)
      if lo is not None:
        out[name].add(float(lo))
  for check in protocol_checks.checks_of_any():
    for name in set(check['readings']) & set(out):
      out[name].add(float(protocol_checks.reading_range(check, name)[0]))
  return {k: sorted(v) for k, v in out.items()}


def raises(measured, lows: dict[str, list[float]], names=READINGS) -> list[dict]:
  """Every way of raising ``measured``'s readings (those of ``names`` with an
  uncertainty) to one of ``lows`` (relative errors) at most ``RAISE`` times
  their own, as ``{name_sd: new sd}``, the least raised first (by the
  largest factor, then their product); the first is ``{}``, nothing raised."""
  options = []
  for name in names:
    value, sd = getattr(measured, name), getattr(measured, f'{name}_sd')
    if not (value > 0 and sd > 0):
      continue
    rel = sd / value
    up = [lo for lo in lows.get(name, ()) if rel < lo <= RAISE * rel]
    options.append([(name, 1.0, None), *((name, lo / rel, lo * value) for lo in up)])
  ways = []
  for combo in itertools.product(*options):
    factors = [f for _, f, _ in combo]
    key = (max(factors, default=1.0), math.prod(factors))
    ways.append((key, {f'{n}_sd': sd for n, _, sd in combo if sd is not None}))
  return [w for _, w in sorted(ways, key=lambda kw: kw[0])] or [{}]


def carried(
  measured,
  lows: dict[str, list[float]],
  covered: Callable[[dict], bool],
  names=READINGS,
) -> tuple[dict, str | None]:
  """The readings' uncertainties to carry (``{name_sd: sd}``; empty: as
  given) and the line that says so (or None): nothing where ``covered({})``
  (a calibration covers the readings as given) or no raise makes one cover
  them; else the least raise (``raises``) that ``covered`` accepts.
  ``covered(raised)`` says whether a calibration covers the estimate with
  those uncertainties in place of its own."""
  if covered({}):
    return {}, None
  found = next((w for w in raises(measured, lows, names)[1:] if covered(w)), None)
  if not found:
    return {}, None
  words = ', '.join(
    f'{k[:-3].replace("_", " ")} {_pct(getattr(measured, k), getattr(measured, k[:-3]))}'
    f' as {_pct(sd, getattr(measured, k[:-3]))}'
    for k, sd in found.items()
  )
  return found, (
    f'readings carried less precise than given ({words}), the lowest error the '
    "calibration's recordings had, so that its measured coverage applies"
  )


def _pct(sd: float, value: float) -> str:
  return f'{100 * sd / value:.2g}%'
