"""Cameras told off by the error an estimate carries, for studies of it.

An estimate of a user's recording carries its intake's alignment error
(``camera_sd_m`` / ``camera_sd_deg``, 1 sd). A study that measures how often
such estimates' intervals hold the truth must tell each recording's estimate
a camera off by an error of that law, and (to cover the range an intake
claims) may draw each recording's error size over a range. These are the
two draws, each from its own explicit seed; the calibration study
(``calibration_config.told_pose``) and the protocol study
(``air_protocol``) use them alike.

Drawn so, a told camera is off by the full error the estimate carries. The
intake's own claim overstates its actual error (``benchmarks.
alignment_error``), so tables measured so are honest for its estimates but
too wide at 50%. The calibration study can instead tell each recording's
estimate a camera off as the intake actually erred: a measured intake's
claim (its error carried) and its actual error (put on the recording's own
camera, in that camera's frame) drawn together (``IntakeError``,
``intake_draw``, ``intake_pose``); such tables hold for the intake's claims
alone (``Scoring.camera_sd_from``).
"""

from __future__ import annotations

import dataclasses
import json
import math

import jax
import numpy as np

import physsim

# One compiled program for every recording's error (hundreds per study).
_misplaced_pose = jax.jit(physsim.shape.misplaced_pose)
_displaced_pose = jax.jit(physsim.shape.displaced_pose)
# The streams of a study's seed its recordings' camera errors are drawn from:
# their sizes (``spread_sd``), then the moves (``moved_pose``).
SD_STREAM, POSE_STREAM = 47, 43
# The most camera error an estimate may carry (``EstimateConfig.check``).
MAX_SD = (0.2, 20.0)


def check_spread(sd: tuple[float, float], spread: float) -> None:
  """Refuses a camera error below 0, a spread of it out of [0, 2], one
  without an error to spread, or one whose range leaves what an estimate
  may carry (``MAX_SD``), naming the flags."""
  if min(sd) < 0:
    raise ValueError(
      f'--camera_sd_m={sd[0]} --camera_sd_deg={sd[1]}: camera errors are >= 0'
    )
  if not 0.0 <= spread <= 2.0:
    raise ValueError(
      f'--camera_sd_spread={spread}: a spread of log camera errors in [0, 2]'
    )
  if spread and not any(sd):
    raise ValueError(
      f'--camera_sd_spread={spread}: the estimates carry no camera error to '
      'spread; give --camera_sd_m and --camera_sd_deg'
    )
  f = math.exp(spread)
  if sd[0] * f > MAX_SD[0] or sd[1] * f > MAX_SD[1]:
    raise ValueError(
      f'--camera_sd_spread={spread}: the range reaches {100 * sd[0] * f:.3g} cm / '
      f'{sd[1] * f:.3g} deg, past what an estimate may carry (20 cm / 20 deg)'
    )


def spread_sd(
  sd: tuple[float, float], spread: float, seed: list[int]
) -> tuple[float, float]:
  """(metres, degrees): ``sd``, each component times exp(``spread`` x u), u
  uniform in [-1, 1], drawn independently from ``seed`` (a NumPy seed
  sequence); ``sd`` itself for no spread."""
  if not spread:
    return tuple(sd)
  u = np.random.default_rng(seed).uniform(-1, 1, 2)
  f = np.exp(spread * u)
  return round(float(sd[0] * f[0]), 6), round(float(sd[1] * f[1]), 5)


def moved_pose(
  key: jax.Array, pose: physsim.Pose, sd: tuple[float, float], pins
) -> physsim.Pose:
  """The camera ``pose`` moved by a rigid error of ``sd`` (a tilt of sd[1]
  degrees per axis about ``pins``, then a shift of sd[0] metres per axis;
  ``physsim.shape.misplaced_pose``, as the estimate draws its own), drawn
  from ``key``; its arrays in ``pose``'s dtypes. ``pose`` itself where both
  are 0. The true camera then lies off the moved one by an error of the same
  law (the inverse of a tilt R about the pins and a shift t is the tilt R^T
  and the shift -R^T t, isotropic Gaussian again): the error the estimate
  models."""
  if not any(sd):
    return pose
  return _like(_misplaced_pose(key, pose, *sd, pins), pose)


def _like(moved: physsim.Pose, pose: physsim.Pose) -> physsim.Pose:
  """``moved`` as NumPy arrays in ``pose``'s dtypes."""
  return physsim.Pose(
    *(np.asarray(m, np.asarray(p).dtype) for m, p in zip(moved, pose, strict=True))
  )


# The fewest measured intake errors tables may be drawn from.
MIN_INTAKE_ERRORS = 8


@dataclasses.dataclass(frozen=True)
class IntakeError:
  """One intake's placement of a camera whose true pose was known
  (``benchmarks.alignment_error``'s row).

  Attributes:
    claim: (metres, degrees) the error the intake claimed, 1 sd per axis (what
      its estimate carries).
    shift: (3,) its actual shift, metres, in the true camera's frame (x right,
      y down, z forward), after its rotation.
    rotation: (3,) its actual rotation about the pins, an axis-angle vector
      (radians) in that frame.
  """

  claim: tuple[float, float]
  shift: tuple[float, float, float]
  rotation: tuple[float, float, float]


def read_intake_errors(paths: tuple[str, ...]) -> tuple[IntakeError, ...]:
  """The placed (not refused) rows of ``benchmarks.alignment_error``'s JSON
  files ``paths``, in order.

  Raises:
    ValueError: a file that cannot be read, one without the error vectors
      (written before they were recorded: rerun it), a row with a claim <= 0
      or a non-finite value, or fewer than ``MIN_INTAKE_ERRORS`` rows in all;
      naming the file.
  """
  errors = []
  for path in paths:
    try:
      with open(path) as f:
        rows = json.load(f)['rows']
    except (OSError, ValueError, KeyError, TypeError) as e:
      raise ValueError(f'--camera_errors: {path}: no alignment errors ({e})') from e
    for r in rows:
      if 'refused' in r:
        continue
      if 'shift_camera_m' not in r:
        raise ValueError(
          f'--camera_errors: {path}: a row without the error vectors (written '
          'before benchmarks.alignment_error recorded them); run it again'
        )
      claim = (float(r['sd_m']), float(r['sd_deg']))
      e = IntakeError(claim, tuple(map(float, r['shift_camera_m'])),
                      tuple(map(float, r['rotation_camera_rad'])))  # fmt: skip
      values = [*e.claim, *e.shift, *e.rotation]
      if min(claim) <= 0 or len(values) != 8 or not np.all(np.isfinite(values)):
        raise ValueError(f'--camera_errors: {path}: a row out of range: {r}')
      errors.append(e)
  if len(errors) < MIN_INTAKE_ERRORS:
    raise ValueError(
      f'--camera_errors: {len(errors)} placed intakes in {", ".join(paths)}; '
      f'tables need at least {MIN_INTAKE_ERRORS}'
    )
  return tuple(errors)


def intake_draw(
  errors: tuple[IntakeError, ...], jitter: float, seed: list[int]
) -> tuple[IntakeError, tuple[float, float]]:
  """One of ``errors`` drawn uniformly from ``seed`` (a NumPy seed sequence),
  and the claim its estimate carries: the intake's own, each component times
  exp(``jitter`` x u), u uniform in [-1, 1] (claims between the measured
  ones; the actual error stays as measured, which hardly follows the claim)."""
  rng = np.random.default_rng(seed)
  e = errors[int(rng.integers(len(errors)))]
  f = np.exp(jitter * rng.uniform(-1, 1, 2))
  return e, (round(float(e.claim[0] * f[0]), 6), round(float(e.claim[1] * f[1]), 5))


def intake_range(
  errors: tuple[IntakeError, ...], jitter: float
) -> tuple[float, float, float]:
  """(metres, degrees, spread): the claims tables drawn with ``intake_draw``
  hold for, as ``carried_errors.table_of`` reads a table's: each component's
  geometric centre, and the smaller half-width (in log) of the two ranges
  drawn, so that both lie inside what was drawn."""
  return claims_box([e.claim for e in errors], jitter)


def claims_box(claims, jitter: float = 0.0, widest: bool = False):
  """(metres, degrees, spread) of claims (n, 2), each widened by
  exp(+-``jitter``): each component's geometric centre of its smallest and
  largest, and the smaller half-width in log of the two ranges (both lie
  inside), or with ``widest`` the larger (the wider range's ends are its)."""
  claims = np.asarray(claims, np.float64)
  lo, hi = claims.min(0) * math.exp(-jitter), claims.max(0) * math.exp(jitter)
  half = np.log(hi / lo) / 2
  spread = float(np.max(half) if widest else np.min(half))
  centre = np.sqrt(lo * hi)
  return round(float(centre[0]), 6), round(float(centre[1]), 5), round(spread, 4)


def intake_pose(pose: physsim.Pose, error: IntakeError, pins) -> physsim.Pose:
  """The camera ``pose`` moved as the intake erred in ``error``: its rotation
  about ``pins`` and its shift, each turned from the true camera's frame into
  the world by ``pose``'s own rotation; its arrays in ``pose``'s dtypes."""
  r = np.asarray(pose.rotation, np.float64)
  moved = _displaced_pose(pose, r @ np.asarray(error.rotation),
                          r @ np.asarray(error.shift), np.asarray(pins))  # fmt: skip
  return _like(moved, pose)
