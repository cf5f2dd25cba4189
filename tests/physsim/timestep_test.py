"""physsim.stable_timestep: the simulator's step for a mesh's spacing, by hand,
and against MuJoCo C itself (a 20 cm swatch of 25 vertices, bending 10x: the
default 2 ms step blows it up, the rule's step holds it)."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import physsim


@pytest.mark.parametrize(
  'edge, frame_dt, timestep, want',
  [
    (1 / 24, 0.05, 0.002, 0.002),  # the paper's 1 m sheet: unchanged
    (1 / 24, 1 / 24, 1 / 480, 1 / 480),  # the eval preset: unchanged
    (1 / 24, 1 / 30, 0.002, (1 / 30) / 17),  # 30 fps: 17 whole substeps
    # a 20 cm swatch of 25: 2 ms * (8.33 / 12.4)^2 = 0.9 ms, 56 substeps a frame
    (
      0.2 / 24,
      0.05,
      0.002,
      0.05 / math.ceil(0.05 / (0.002 * (0.2 / 24 / 0.0124) ** 2)),
    ),
  ],
)
def test_the_step_by_hand(edge, frame_dt, timestep, want):
  got = physsim.stable_timestep(edge, frame_dt, timestep)
  assert got == pytest.approx(want, rel=1e-12)
  substeps = frame_dt / got
  assert abs(substeps - round(substeps)) < 1e-9


def test_nonpositive_inputs_are_refused_by_name():
  with pytest.raises(ValueError, match=r'need edge, frame_dt and timestep > 0'):
    physsim.stable_timestep(0.0, 0.05)


def test_a_swatch_holds_at_the_rules_step_and_blows_up_at_the_sheets():
  mesh = physsim.square(25, 0.2)
  p = physsim.params.make(bending_scale=10.0, wind_speed=2.0, area_weight=0.15)
  reach = []
  for step in (0.002, physsim.stable_timestep(mesh.shortest_edge, 0.05)):
    config = physsim.SimConfig(timestep=step, edge_solref=max(0.004, 2 * step))
    out = physsim.simulate(
      physsim.build(mesh, 'gray_interlock', config), p, frames=10, fps=20.0,
      warmup=0.5, wind=physsim.Wind(gust_intensity=0.2), key=jax.random.key(0)[None],
      backend='c', workers=1,
    )  # fmt: skip
    x = np.asarray(out.positions, np.float64)
    # how far any vertex got from the top edge's midpoint (0, 0, 1.5)
    reach.append(np.nan_to_num(np.linalg.norm(x - [0, 0, 1.5], axis=-1), nan=1e9).max())
  # the swatch's farthest point is its bottom corner, sqrt(0.1^2 + 0.2^2) m away
  # at rest; the edge constraints let it stretch a few per cent (10% allowed)
  assert reach[0] > 1.0 and reach[1] < 1.1 * math.hypot(0.1, 0.2), reach
