"""physsim.scaled_edge_solref: edge constraints as stiff in stretch on every
mesh, by hand and in MuJoCo C (a 20 cm swatch hanging at 8 and 16 vertices a
side: at the fixed time constant the finer one stretches ~4x more, at the
scaled one about as much)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import physsim

# The scaled meshes' mean vertical strain may differ by this share: the mesh
# still changes how the load spreads (a fixed time constant differs by > 2x).
_STRAIN_RATIO_TOL = 0.25


@pytest.mark.parametrize(
  'edge, want',
  [
    (0.04, 0.004),  # the reference itself: the garments' grid
    (0.04 - 1e-16, 0.004),  # ... as a garment's mesh measures it
    (1 / 24, 0.004),  # the estimate's 1 m sheet of 25: coarser, unchanged
    (1 / 8, 0.004),  # coarser: unchanged
    (1 / 40, 0.004 * 0.025 / 0.04),  # the 1 m sheet of 41
    (0.2 / 24, 0.004 * (0.2 / 24) / 0.04),  # a 20 cm swatch of 25
  ],
)
def test_the_time_constant_by_hand(edge, want):
  assert physsim.scaled_edge_solref(edge) == pytest.approx(want, rel=1e-12)


def test_scaled_edges_bring_the_step_down_to_half_the_time_constant():
  mesh = physsim.square(41, 0.2)  # spacing 5 mm: tau 0.48 ms
  cfg = physsim.config_for_mesh(mesh, 20.0)  # scaled: the default
  assert cfg == physsim.config_for_mesh(mesh, 20.0, scaled_edges=True)
  assert cfg.edge_solref == pytest.approx(0.004 * 0.005 / 0.04, rel=1e-12)
  assert cfg.edge_solref >= 2 * cfg.timestep > 0.9 * cfg.edge_solref
  # The estimate's sheet and the garments: nothing changes.
  for coarse in (physsim.square(25), physsim.garment('tshirt', 0.04)):
    assert physsim.config_for_mesh(coarse, 20.0, scaled_edges=False) == (
      physsim.config_for_mesh(coarse, 20.0)
    )
  with pytest.raises(ValueError, match='need edge and edge_solref > 0'):
    physsim.scaled_edge_solref(0.0)


def _hanging_strain(n: int, scaled: bool) -> float:
  """Mean strain of the vertical edges of a 20 cm swatch of n x n after 0.6 s
  hanging in a 1 m/s breeze without gusts (MuJoCo C)."""
  mesh = physsim.square(n, 0.2)
  model = physsim.build(
    mesh, 'gray_interlock', physsim.config_for_mesh(mesh, 20.0, scaled_edges=scaled)
  )
  out = physsim.simulate(
    model, physsim.params.make(bending_scale=1.0, wind_speed=1.0, area_weight=0.2),
    frames=2, fps=20.0, warmup=0.6, wind=physsim.Wind(gust_intensity=0.0),
    key=jax.random.key(0)[None], backend='c', workers=1,
  )  # fmt: skip
  p, v = np.asarray(out.positions)[0, -1], np.asarray(mesh.vertices)
  i = np.arange(n * (n - 1))  # vertex i and the one below it
  return float(
    np.mean(np.linalg.norm(p[i + n] - p[i], axis=1) / (v[1, 0] - v[0, 0]) - 1)
  )


def test_a_finer_mesh_stretches_as_much_only_with_scaled_edges():
  fixed = _hanging_strain(16, False) / _hanging_strain(8, False)
  scaled = _hanging_strain(16, True) / _hanging_strain(8, True)
  assert fixed > 2.0  # the fixed time constant softens the finer cloth
  assert abs(scaled - 1) < _STRAIN_RATIO_TOL
