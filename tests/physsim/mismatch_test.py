"""physsim.mismatch: a world unlike the estimator's simulator reaches the cloth."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import physsim

_MESH = physsim.square(8)


def _mean_position(physics: physsim.Mismatch, speed: float = 3.0) -> np.ndarray:
  """(3,) the sheet's mean vertex position over a short steady-wind clip
  (MuJoCo C, no gusts)."""
  config = physsim.config_for_mesh(_MESH, 20.0, **physics.sim_fields())
  model = physsim.build(_MESH, 'gray_interlock', config)
  out = physsim.simulate(
    model, physsim.params.make([1.0], [speed], [0.15]), frames=4, fps=20.0,
    warmup=0.5, wind=physics.wind(0.0), key=jax.random.key(0), backend='c',
    workers=1,
  )  # fmt: skip
  return np.asarray(out.positions, np.float64)[0].mean(axis=(0, 1))


def test_the_world_recipe_by_hand():
  w = physsim.mismatch.WORLD
  a = np.deg2rad(10.0)
  np.testing.assert_allclose(w.wind(0.3).direction, (np.sin(a), np.cos(a), 0.0))
  assert w.wind(0.3).gust_modes == 16 and w.wind(0.3).gust_intensity == 0.3
  assert w.sim_fields() == dict(edge_solref=0.008, air_drag=0.1, bending_damping=0.002)
  # the estimator's own physics is the simulator's defaults
  own = physsim.mismatch.OWN
  assert own.wind(0.2) == physsim.Wind(gust_intensity=0.2)
  assert physsim.config_for_mesh(_MESH, 20.0, **own.sim_fields()) == (
    physsim.config_for_mesh(_MESH, 20.0)
  )


def test_the_second_world_by_hand():
  w = physsim.mismatch.WORLD_B
  a = np.deg2rad(5.0)
  np.testing.assert_allclose(w.wind(0.3).direction, (np.sin(a), np.cos(a), 0.0))
  assert w.wind(0.3).gust_modes == 32
  assert w.sim_fields() == dict(edge_solref=0.006, air_drag=0.05, bending_damping=0.005)
  assert physsim.MISMATCHES['mismatched_b'] is w


@pytest.mark.parametrize(
  'field, value',
  [('fan_yaw_deg', float('nan')), ('air_drag', -0.1), ('gust_modes', 0),
   ('edge_solref_scale', 0.0), ('bending_damping', float('inf'))],
)  # fmt: skip
def test_bad_settings_are_refused_by_name(field, value):
  with pytest.raises(ValueError, match=field if field != 'gust_modes' else 'gust'):
    physsim.Mismatch(**{field: value})


def test_a_turned_fan_lifts_less_and_drag_carries_the_sheet_along():
  """Pressure goes with the flow's normal component squared, so a fan turned
  30 degrees lifts the sheet less (cos^2 30 = 0.75 of the push); drag on the
  tangential flow (+x here) carries it along x."""
  own = _mean_position(physsim.mismatch.OWN)
  turned = _mean_position(physsim.Mismatch(fan_yaw_deg=30.0))
  dragged = _mean_position(physsim.Mismatch(fan_yaw_deg=30.0, air_drag=0.5))
  assert turned[2] < own[2] - 0.01  # metres lower
  assert dragged[0] > turned[0] + 0.001  # metres along the tangential flow
