"""experiments.pipeline.datasets: the sweep's config checks and parameter draws."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import physsim
from experiments.pipeline import datasets

SMOKE = datasets.PRESETS['smoke']


def test_parameter_draws_lie_in_the_fabrics_range_and_repeat_by_seed():
  a = datasets.material_params(SMOKE, 'black_denim')
  b = datasets.material_params(SMOKE, 'black_denim')
  for x, y in zip(a, b, strict=True):
    np.testing.assert_array_equal(x, y)
  space = physsim.search_space('black_denim')
  lo, hi = space.bounds().T
  values = np.stack([np.asarray(v, np.float64).ravel() for v in a], axis=-1)
  assert values.shape == (SMOKE.sequences, 3)
  assert np.all(values >= lo) and np.all(values <= hi)
  other = datasets.material_params(dataclasses.replace(SMOKE, seed=1), 'black_denim')
  assert not np.allclose(np.asarray(other.wind_speed), np.asarray(a.wind_speed))


def test_materials_draw_from_their_own_streams():
  """Adding a fabric to a sweep does not change another fabric's draws."""
  one = dataclasses.replace(SMOKE, materials=('black_denim',))
  np.testing.assert_array_equal(
    datasets.material_params(one, 'black_denim').wind_speed,
    datasets.material_params(SMOKE, 'black_denim').wind_speed,
  )


@pytest.mark.parametrize(
  'field, value, word',
  [('cloth_resolution', 1, 'cloth_resolution'), ('materials', ('wool',), 'wool')],
)
def test_bad_configs_are_refused_by_name(field, value, word):
  with pytest.raises(ValueError, match=word):
    datasets._check_config(dataclasses.replace(SMOKE, **{field: value}))


def test_a_hem_is_part_of_a_sweeps_identity_and_refused_out_of_range():
  """A sweep with a hem is another dataset (a resume of the plain one into
  its folder is refused); without one, its identity is the one datasets made
  before the setting had (they resume); a hem out of [0, 1] kg, NaN, or on a
  garment is refused by name."""
  plain = datasets.PRESETS['smoke']
  assert 'hem_mass' not in datasets._identity(plain, 'c')
  hemmed = datasets._identity(dataclasses.replace(plain, hem_mass=0.3), 'c')
  assert hemmed['hem_mass'] == 0.3
  for bad in (-0.1, 1.5, float('nan')):
    with pytest.raises(ValueError, match='hem_mass must be in'):
      datasets._check_config(dataclasses.replace(plain, hem_mass=bad))
  with pytest.raises(ValueError, match="on garment 'tshirt'"):
    datasets._check_config(dataclasses.replace(plain, hem_mass=0.1, garment='tshirt'))
