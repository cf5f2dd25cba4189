"""The instruments' readings of a protocol set in the air study: a scale's
area weight and a strip's bending length (shared by the set's recordings),
and each fan setting's anemometer.

The strip's reading follows its law (``StripLaw``): a ruler's cantilever, one
Gaussian sd; or a depth camera's overhang, whose sd varies with the strip's
length and pixels and whose error is a Student's t (``physsim.overhang_depth``).
Its draws come from their own stream, so the other readings are the same
whatever its law.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

import physsim
from experiments.pipeline import measurements
from experiments.studies import calibration_config

# relative sd of the anemometer's wind, the scale's area weight and a ruler's
# bending length
READ = {'wind_speed': 0.02, 'area_weight': 0.01, 'bending_length': 0.03}


@dataclasses.dataclass(frozen=True)
class StripLaw:
  """How a set's strip reading errs: its sd ``sd`` x exp(``spread`` x z), z
  standard normal clipped (``calibration_config.spread_length_sd``); its
  error Gaussian, or a Student's t of ``dof`` degrees of freedom (> 2)
  scaled to that sd (``measurements.unit_error``)."""

  sd: float = READ['bending_length']
  spread: float = 0.0
  dof: float = 0.0

  def range(self) -> tuple[float, float]:
    """The relative sds the readings span."""
    return calibration_config.spread_length_range(self.sd, self.spread)

  def check(self) -> None:
    """Refuses a law no reading has, naming its flag."""
    if not (math.isfinite(self.sd) and 0.0 < self.sd <= 0.3):
      raise ValueError(f'--length_sd={self.sd}: need a relative sd in (0, 0.3]')
    if not (math.isfinite(self.spread) and 0 <= self.spread <= 1):
      raise ValueError(f'--length_sd_spread={self.spread}: need 0 to 1')
    if self.dof and not 2.0 < self.dof <= measurements.MAX_DOF:
      raise ValueError(
        f'--length_dof={self.dof}: need 0 (Gaussian) or more than 2, at most '
        f'{measurements.MAX_DOF:g}'
      )


def readings(seed: int, truth: dict, space, strip: StripLaw = StripLaw()):
  """The scale's and the strip's readings of a set with ``truth`` (shared, a
  dict of ``Measured``'s fields) and each fan's anemometer's (value, sd)."""
  key = int(1e6 * truth['bending_scale'])
  rng = np.random.default_rng([seed, 43, key])
  c = float(physsim.params.bending_length(
    truth['bending_scale'], truth['area_weight'], space.rigidity
  ))  # fmt: skip
  w = truth['area_weight']
  weight = w * (1 + READ['area_weight'] * rng.standard_normal())
  z = rng.standard_normal()
  own = np.random.default_rng([seed, 44, key])  # the strip's own stream
  rel = calibration_config.spread_length_sd(
    strip.sd, strip.spread, own.standard_normal()
  )
  if strip.dof:
    z = measurements.unit_error(own, strip.dof)
  shared = {
    'area_weight': weight, 'area_weight_sd': READ['area_weight'] * w,
    'bending_length': c * (1 + rel * z), 'bending_length_sd': rel * c,
    **({'bending_length_dof': strip.dof} if strip.dof else {}),
  }  # fmt: skip
  winds = [(v * (1 + READ['wind_speed'] * rng.standard_normal()),
            READ['wind_speed'] * v) for v in truth['winds']]  # fmt: skip
  return shared, winds
