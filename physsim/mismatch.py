"""A world unlike the estimator's simulator, for recordings that test it.

The estimator simulates a fan blowing along the cloth's normal with an
8-mode frozen-turbulence gust field, no drag along the cloth, undamped
bending and edges of ``SimConfig.edge_solref``. A real rig differs in all of
these, so intervals that held the truth on recordings the estimator's own
simulator made say little about a real recording (issue 39, item 6). A
``Mismatch`` names such differences; recordings made with one (a dataset
sweep's ``physics``, ``experiments.pipeline.rig``'s recipes) are the
held-out data on which coverage is measured and a model-discrepancy term is
fitted.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from physsim import cloth, rollout


@dataclasses.dataclass(frozen=True)
class Mismatch:
  """How a recording's physics differs from the estimator's.

  Attributes:
    fan_yaw_deg: the fan's axis turned about the vertical from the cloth's
      normal, degrees (the estimator assumes 0).
    gust_modes: frozen-turbulence modes of the gusts (the estimator's: 8).
    air_drag: drag on the flow along the cloth (the estimator's: 0).
    bending_damping: Rayleigh damping of bending, seconds (the estimator's: 0).
    edge_solref_scale: the edges' constraint time constant over the
      estimator's (longer: a stretchier cloth).
  """

  fan_yaw_deg: float = 0.0
  gust_modes: int = 8
  air_drag: float = 0.0
  bending_damping: float = 0.0
  edge_solref_scale: float = 1.0

  def __post_init__(self):
    bad = [
      f'{k}={v}'
      for k, v in dataclasses.asdict(self).items()
      if not np.isfinite(v) or v < 0
    ]
    if bad or self.gust_modes < 1 or self.edge_solref_scale <= 0:
      raise ValueError(
        f'a mismatch needs finite settings >= 0, gust_modes >= 1 and '
        f'edge_solref_scale > 0, got {", ".join(bad) or dataclasses.asdict(self)}'
      )

  def wind(self, gust_intensity: float) -> rollout.Wind:
    """The fan: its axis turned by ``fan_yaw_deg`` from the cloth's normal (+y)
    towards +x, and its gust spectrum."""
    yaw = np.deg2rad(self.fan_yaw_deg)
    return rollout.Wind(
      direction=(float(np.sin(yaw)), float(np.cos(yaw)), 0.0),
      gust_intensity=gust_intensity,
      gust_modes=self.gust_modes,
    )

  def sim_fields(self) -> dict:
    """``physsim.config_for_mesh`` arguments: the edges' time constant (at
    the reference spacing) and the drag and damping."""
    return dict(
      edge_solref=cloth.SimConfig.edge_solref * self.edge_solref_scale,
      air_drag=self.air_drag,
      bending_damping=self.bending_damping,
    )


# The estimator's own physics, and a world unlike it the way a real rig is: a
# fan 10 degrees off the cloth's normal, another gust spectrum, drag along the
# cloth, damped bending, stretchier edges.
OWN = Mismatch()
WORLD = Mismatch(
  fan_yaw_deg=10.0, gust_modes=16, air_drag=0.1, bending_damping=0.002,
  edge_solref_scale=2.0,
)  # fmt: skip
# A second such world, each setting other than WORLD's: recordings of it check
# what was fitted on WORLD (tables, a discrepancy term) held out in the
# physics too, not only in the recordings.
WORLD_B = Mismatch(
  fan_yaw_deg=5.0, gust_modes=32, air_drag=0.05, bending_damping=0.005,
  edge_solref_scale=1.5,
)  # fmt: skip
MISMATCHES = {'own': OWN, 'mismatched': WORLD, 'mismatched_b': WORLD_B}
