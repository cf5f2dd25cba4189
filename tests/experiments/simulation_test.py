"""experiments.pipeline.simulation: the cloth an estimate simulates, by hand,
and the intake's use of it without the objective."""

from __future__ import annotations

import ast
import inspect

import numpy as np
import pytest

import physsim
from experiments.pipeline import intake, objective, simulation


def test_the_mesh_and_its_pin_centre():
  sim = simulation.Simulation(cloth_resolution=9)
  m = simulation.mesh(sim)
  assert len(m.vertices) == 81
  # the 1 m sheet hangs from its top edge at 1.5 m, centred on x = 0
  np.testing.assert_allclose(simulation.pin_centre(sim), [0.0, 0.0, 1.5], atol=1e-12)
  np.testing.assert_allclose(simulation.pin_centre(sim), m.vertices[m.pinned].mean(0))
  swatch = simulation.mesh(simulation.Simulation(cloth_resolution=9, cloth_size=0.2))
  assert np.ptp(swatch.vertices[:, 0]) == pytest.approx(0.2, rel=1e-12)


def test_a_garment_is_its_own_mesh():
  sim = simulation.Simulation(garment=physsim.GARMENTS[0])
  want = physsim.garment(physsim.GARMENTS[0], sim.garment_spacing)
  np.testing.assert_array_equal(simulation.mesh(sim).vertices, want.vertices)


def test_the_step_and_edges_are_the_ones_the_mesh_needs():
  # A 20 cm swatch of 25 (8.3 mm): edges scaled to 4 ms x 8.3 / 40, the step
  # at most half of that (below the bending's stable step) and a whole number
  # of steps a frame.
  sim = simulation.Simulation(cloth_resolution=25, cloth_size=0.2)
  edge = simulation.mesh(sim).shortest_edge
  cfg = simulation.sim_config(sim)
  assert cfg.edge_solref == pytest.approx(0.004 * edge / 0.04, rel=1e-12)
  assert cfg.timestep == physsim.stable_timestep(edge, 1 / sim.fps, cfg.edge_solref / 2)
  assert cfg.timestep < physsim.stable_timestep(edge, 1 / sim.fps)
  # the estimate's 1 m sheet: 2 ms steps and 4 ms edges, as always
  sheet = simulation.sim_config(simulation.Simulation())
  assert sheet.timestep == pytest.approx(0.002) and sheet.edge_solref == 0.004


def test_the_objective_re_exports_it_and_the_intake_needs_no_objective():
  assert objective.Simulation is simulation.Simulation
  assert objective.EstimateConfig().simulation == simulation.Simulation()
  imported = {
    a.name
    for node in ast.walk(ast.parse(inspect.getsource(intake)))
    if isinstance(node, ast.ImportFrom)
    for a in node.names
  }
  assert 'simulation' in imported and 'objective' not in imported
