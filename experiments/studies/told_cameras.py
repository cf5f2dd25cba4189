"""Cameras told off by the error an estimate carries, for studies of it.

An estimate of a user's recording carries its intake's alignment error
(``camera_sd_m`` / ``camera_sd_deg``, 1 sd). A study that measures how often
such estimates' intervals hold the truth must tell each recording's estimate
a camera off by an error of that law, and (to cover the range an intake
claims) may draw each recording's error size over a range. These are the
two draws, each from its own explicit seed; the calibration study
(``calibration_config.told_pose``) and the protocol study
(``air_protocol``) use them alike.
"""

from __future__ import annotations

import math

import jax
import numpy as np

import physsim

# One compiled program for every recording's error (hundreds per study).
_misplaced_pose = jax.jit(physsim.shape.misplaced_pose)
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
  moved = _misplaced_pose(key, pose, *sd, pins)
  return physsim.Pose(
    *(np.asarray(m, np.asarray(p).dtype) for m, p in zip(moved, pose, strict=True))
  )
