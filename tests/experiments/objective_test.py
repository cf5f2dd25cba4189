"""experiments.pipeline.objective: the estimate's mesh, pins and per-candidate keys.

The fused objective itself (simulate, render, sense, embed, score) is tested
end to end in estimate_test, estimate_methods_test and joint_test.
"""

from __future__ import annotations

import os
import signal

import jax
import numpy as np
import pytest

import physsim
from experiments.pipeline import embedding
from experiments.pipeline import objective as obj
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  load,
  write_hand_made_model,
  write_recording,
)

SMOKE = obj.PRESETS['smoke']
# One jitted program against the same operations run one at a time (float32).
_SUMMARY_RTOL = 1e-5


def _data(keys):
  return np.asarray(jax.random.key_data(keys))


def test_keys_depend_on_the_evaluation_index_not_the_batch():
  """A candidate's gusts and noise are the same whether it was scored in a
  batch of 4 or resumed alone as evaluation 2: what makes lockstep searches and
  resumes go as a search alone would."""
  gust4, noise4 = obj.candidate_keys(SMOKE.seed, SMOKE.search, first=0, q=4)
  gust1, noise1 = obj.candidate_keys(SMOKE.seed, SMOKE.search, first=2, q=1)
  np.testing.assert_array_equal(_data(gust4)[2:3], _data(gust1))
  np.testing.assert_array_equal(_data(noise4)[2:3], _data(noise1))
  assert len({tuple(k) for k in _data(gust4)}) == 4  # every evaluation its own
  assert not np.array_equal(_data(gust4), _data(noise4))


def test_the_papers_argmin_gives_every_evaluation_one_pair():
  crn = SMOKE.replace(point='argmin')  # common random numbers
  assert crn.common_random_numbers
  gust, noise = obj.candidate_keys(crn.seed, crn.search, first=5, q=3)
  assert len({tuple(k) for k in _data(gust)}) == 1
  assert len({tuple(k) for k in _data(noise)}) == 1


def test_seeds_change_the_keys():
  other = SMOKE.replace(seed=SMOKE.seed + 1)
  assert not np.array_equal(
    _data(obj.candidate_keys(SMOKE.seed, SMOKE.search, 0, 2)[0]),
    _data(obj.candidate_keys(other.seed, other.search, 0, 2)[0]),
  )


def test_presets_are_reachable_from_the_library():
  demo = obj.EstimateConfig.preset('demo', material='black_denim')
  assert demo.simulation.material == 'black_denim'
  assert (
    demo.simulation.cloth_resolution == obj.PRESETS['demo'].simulation.cloth_resolution
  )
  assert obj.EstimateConfig.preset('paper').search.point == 'argmin'
  with pytest.raises(
    ValueError, match=r"no estimate preset 'tiny': one of \['default'"
  ):
    obj.EstimateConfig.preset('tiny')


def test_one_cloth_model_per_mesh_step_and_hem_is_built_once():
  from experiments.pipeline import simulation

  base = simulation.Simulation(cloth_resolution=6)
  model = simulation.cloth(base)
  # what the model does not depend on: the fabric, clip, gusts, cameras
  other = simulation.Simulation(
    material='black_denim', cloth_resolution=6, frames=7, gusts=0.5, cameras=1
  )
  assert simulation.cloth(other) is model
  # what it does: another mesh, size, frame rate (the step) or hem
  for changed in (
    dict(cloth_resolution=7), dict(cloth_size=0.3), dict(fps=40.0),
    dict(hem_mass=0.05),
  ):  # fmt: skip
    got = simulation.cloth(simulation.Simulation(**{'cloth_resolution': 6, **changed}))
    assert got is not model, changed
  assert simulation.cloth(
    simulation.Simulation(cloth_resolution=7)
  ).mesh.vertices.shape == (49, 3)
  assert model.mesh.vertices.shape == (36, 3)


@pytest.mark.parametrize('distance', ['energy', 'shape'])
def test_an_objective_is_built_from_each_section_of_its_config(tmp_path, distance):
  """Objective.__init__ reads the simulation, scoring and hardware sections
  (a wrong name there fails every estimate, and only the slow tier runs
  one): built here without running, from a tiny recording."""
  config = CONFIG.replace(distance=distance, backend='c', workers=1)
  net = embedding.load_embedding(write_hand_made_model(str(tmp_path / 'model')))
  problem = obj.make_problem(config, net, load(write_recording(str(tmp_path), TRUTH)))
  built = obj.Objective(problem)
  n = config.simulation.cloth_resolution
  assert built.mesh.vertices.shape == (n * n, 3)
  assert built.n_frames == problem.n_frames <= config.simulation.frames
  assert built._distance == distance and not built._camera_error


def test_a_problems_arrays_are_made_on_the_host_and_its_shape_in_one_program(
  tmp_path,
):
  """make_problem's small arrays land on the host's CPU (each call places
  them), and the recording's shape summary, computed as one jitted program,
  is ``physsim.shape.summary``'s (tested against its reference in shape_test)
  to float32 rounding."""
  config = CONFIG.replace(distance='shape', backend='c', workers=1)
  rec = load(write_recording(str(tmp_path), TRUTH))
  net = embedding.no_network(rec.depth.shape[1:])
  problem = obj.make_problem(config, net, rec)
  host = {physsim.devices.host()}
  for leaf in (problem.data.lo, problem.data.rec_shape, problem.data.poses.position):
    assert leaf.devices() == host
  want = physsim.shape.summary(
    rec.depth, problem.intr, jax.tree.map(lambda a: a[0], problem.data.poses)
  )
  np.testing.assert_allclose(problem.data.rec_shape, want, rtol=_SUMMARY_RTOL)


def test_a_network_problem_made_beside_an_accelerator_enters_its_program(tmp_path):
  """With an accelerator the default device (here the second CPU device stands
  in for it), a problem's small arrays are made on the host and the network's
  parameters and the recording's embedding on the accelerator; stacked for a
  call and placed where the program runs, every leaf lands on that device
  (no leaf mixes devices)."""
  accelerator = jax.local_devices()[1]
  assert accelerator != physsim.devices.host()
  config = CONFIG.replace(distance='energy', backend='c', workers=1)
  with jax.default_device(accelerator):
    net = embedding.load_embedding(write_hand_made_model(str(tmp_path / 'model')))
    net = net._replace(params=jax.device_put(net.params, accelerator))
    rec = load(write_recording(str(tmp_path), TRUTH))
    problem = obj.make_problem(config, net, rec)
    assert problem.data.lo.devices() == {physsim.devices.host()}
    assert problem.data.rec_points.devices() == {accelerator}
    data = obj.stack([problem.data, problem.data])
    mesh = physsim.devices.world_mesh([accelerator])
    placed = physsim.devices.place(data, mesh)
  for leaf in jax.tree.leaves(placed):
    assert leaf.devices() == {accelerator}
  np.testing.assert_array_equal(placed.rec_shape[0], problem.data.rec_shape)


def test_ctrl_c_during_the_simulators_callback_is_an_interrupt_not_scores(
  tmp_path, monkeypatch, deferring_sigint
):
  """A Ctrl-C while MuJoCo C runs inside the fused program (a host callback):
  the call raises ``KeyboardInterrupt`` once the program returns, where it
  used to raise a ``JaxRuntimeError`` (a traceback, not the CLI's one line);
  the NaN worlds of the stopped rollout are never returned as scores."""
  config = CONFIG.replace(distance='shape', backend='c', workers=1)
  rec = load(write_recording(str(tmp_path), TRUTH))
  problem = obj.make_problem(config, embedding.no_network(rec.depth.shape[1:]), rec)
  objective = obj.Objective(problem)
  u = np.zeros((1, 1, 3))
  gust, noise = obj.candidate_keys(config.seed, config.search, 0, 1)
  keys = (gust[None], noise[None])
  data = obj.stack([problem.data])
  assert np.all(objective(data, u, *keys).valid)  # compiled, whole
  real, calls = physsim.rollout._applied_forces_np, [0]

  def forces(*args):
    calls[0] += 1
    if calls[0] == 2:
      os.kill(os.getpid(), signal.SIGINT)
    return real(*args)

  monkeypatch.setattr(physsim.rollout, '_applied_forces_np', forces)
  with pytest.raises(KeyboardInterrupt):
    objective(data, u, *keys)
  assert not deferring_sigint.pending()
