"""Tests of an ensemble of embedding networks (``--model=a,b``).

The reference is each member on its own: the fused objective of the ensemble
must score every candidate with the geometric mean of its members' PSDs, each
computed by the single-network program. Networks are the fixtures' untrained
tiny PhySNets (different seeds, so their PSDs differ) and the hand-made one.
"""

from __future__ import annotations

import os

import jax
import numpy as np
import pytest

from experiments.pipeline import embedding, estimation
from experiments.pipeline import objective as obj_lib
from experiments.studies import tables
from tests.experiments.estimate_fixtures import (
  CONFIG,
  TRUTH,
  load,
  write_hand_made_model,
  write_random_model,
  write_recording,
)

pytestmark = pytest.mark.slow  # trains and searches with ensembles

# The ensemble's program against its members' programs: one float32 embedding
# and PSD per member on both paths, combined in float32 (ensemble) or float64.
_MEAN_RTOL = 1e-4


@pytest.fixture(scope='module')
def env(tmp_path_factory):
  root = str(tmp_path_factory.mktemp('ensemble'))
  seq = write_recording(root, TRUTH)
  a = write_random_model(os.path.join(root, 'a'), 'physnet', 'depth', seed=1)
  b = write_random_model(os.path.join(root, 'b'), 'physnet', 'depth', seed=2)
  return dict(root=root, rec=load(seq), a=a, b=b)


def _scores(model_dir: str, rec, u) -> np.ndarray:
  net = embedding.load_embedding(model_dir)
  problem = obj_lib.make_problem(CONFIG, net, rec)
  gust, noise = obj_lib.candidate_keys(CONFIG.seed, CONFIG.search, 0, len(u))
  out = obj_lib.Objective(problem)(
    obj_lib.stack([problem.data]), np.asarray(u)[None], gust[None], noise[None]
  )
  assert out.valid.all()
  return out.psd[0]


def test_ensemble_psd_is_the_members_geometric_mean(env):
  # Away from the truth: there the PSD is ~0 up to float32 cancellation.
  u = np.array([[0.0, 0.0, 0.0], [0.5, -0.6, 0.7], [-0.8, 0.3, -0.4]])
  pa, pb = _scores(env['a'], env['rec'], u), _scores(env['b'], env['rec'], u)
  assert np.all(pa > 0) and np.all(pb > 0)
  assert not np.allclose(pa, pb, rtol=0.1)  # two different networks
  both = _scores(f'{env["a"]},{env["b"]}', env['rec'], u)
  np.testing.assert_allclose(both, np.sqrt(pa * pb), rtol=_MEAN_RTOL)


def test_ensemble_loads_stacked_and_refuses_mismatched_members(env):
  net = embedding.load_embedding(f'{env["a"]}, {env["b"]}')
  one = embedding.load_embedding(env['a'])
  assert net.members == 2 and one.members == 0
  for stacked, single in zip(
    jax.tree.leaves(net.params), jax.tree.leaves(one.params), strict=True
  ):
    assert stacked.shape == (2, *single.shape)
  sdn = write_random_model(os.path.join(env['root'], 'sdn'), 'sdn', 'depth')
  with pytest.raises(ValueError, match='sdn: an ensemble member with'):
    embedding.load_embedding(f'{env["a"]},{sdn}')
  with pytest.raises(ValueError, match='empty run folder'):
    embedding.load_embedding(f'{env["a"]},')


def test_a_run_folder_whose_name_holds_a_comma_is_one_network(env):
  odd = os.path.join(env['root'], 'lr=1e-3,seed=4')
  write_random_model(odd, 'physnet', 'depth', seed=4)
  assert embedding.members(odd) == [odd]
  assert embedding.load_embedding(odd).members == 0
  # a list that names it and another is still an ensemble
  assert embedding.members(f'{env["a"]},{env["b"]}') == [env['a'], env['b']]


def test_ensemble_recipe_differs_from_a_single_network(env):
  pair = embedding.network_recipe(f'{env["a"]},{env["b"]}')
  single = embedding.network_recipe(env['a'])
  # Seeds are not part of a recipe: the members share one.
  assert pair['ensemble'] == {'members': 2, 'differ': []}
  assert embedding.recipe_differences(pair, single) == ['ensemble']
  assert tables._model_dir('r1,r2', 'physnet_depth', 'denim') == ','.join(
    os.path.join(r, 'physnet_depth', 'simulation', 'denim') for r in ('r1', 'r2')
  )


def test_ensemble_of_one_network_twice_estimates_as_that_network(env, tmp_path):
  # The paper's protocol (common random numbers, MuJoCo C): deterministic, so
  # an ensemble of two copies must retrace the single network's search.
  hand = write_hand_made_model(str(tmp_path / 'hand'))
  copy = write_hand_made_model(str(tmp_path / 'copy'))
  config = CONFIG.replace(max_iter=1, min_iter=1)
  one = estimation.estimate(
    config, env['rec'], hand, str(tmp_path / 'one'), progress=False
  )
  two = estimation.estimate(
    config, env['rec'], f'{hand},{copy}', str(tmp_path / 'two'), progress=False
  )
  assert two['evaluations'] == one['evaluations']
  np.testing.assert_allclose(two['psd_best'], one['psd_best'], rtol=_MEAN_RTOL)
  for f in ('bending_scale', 'wind_speed', 'area_weight'):
    np.testing.assert_allclose(two['argmin'][f], one['argmin'][f], rtol=1e-6)
