"""benchmarks/windy_rig.py: its recordings and its summary, without estimating."""

import dataclasses

import numpy as np
import pytest

from benchmarks import windy_rig
from experiments.pipeline import rig


def test_one_recording_per_wind_each_with_its_own_seed():
  args = windy_rig.Args(winds='3.0,4.5', recipe='mismatched')
  recs = windy_rig.recordings(args)
  assert [n for n, _ in recs] == ['rec00', 'rec01']
  assert [r.wind_speed for _, r in recs] == [3.0, 4.5]
  assert [r.seed for _, r in recs] == [rig.MISMATCHED.seed, rig.MISMATCHED.seed + 1]
  # everything else is the named recipe's
  assert dataclasses.replace(recs[1][1], wind_speed=3.52, seed=11) == rig.MISMATCHED


def test_without_winds_the_recipe_itself_in_the_workdir():
  assert windy_rig.recordings(windy_rig.Args()) == [('', rig.Recipe())]


def test_recipe_fields_change_the_recipe_as_numbers_of_its_types():
  args = windy_rig.Args(recipe_fields='gust_intensity=0.2,cloth_resolution=25')
  ((_, r),) = windy_rig.recordings(args)
  assert r.gust_intensity == 0.2 and r.cloth_resolution == 25
  assert isinstance(r.cloth_resolution, int)


def test_recipe_fields_move_the_camera_as_points():
  args = windy_rig.Args(recipe_fields='eye=-0.6:-1.4:1.6,target=0:0.2:1')
  ((_, r),) = windy_rig.recordings(args)
  assert r.eye == (-0.6, -1.4, 1.6) and r.target == (0.0, 0.2, 1.0)
  assert dataclasses.replace(r, eye=rig.Recipe.eye, target=rig.Recipe.target) == (
    rig.Recipe()
  )


def test_recipe_fields_change_the_depth_noise_by_its_own_numbers():
  args = windy_rig.Args(recipe_fields='noise.sigma_a=0.00035,noise.native_width=848')
  ((_, r),) = windy_rig.recordings(args)
  assert r.noise.sigma_a == 0.00035 and r.noise.native_width == 848
  assert r.noise.sigma_b == rig.Recipe().noise.sigma_b  # the rest as the recipe's
  assert dataclasses.replace(r, noise=rig.Recipe().noise) == rig.Recipe()


@pytest.mark.parametrize(
  'fields, named',
  [('gusts=0.2', "'gusts=0.2'"), ('cloth_resolution=2.5', "'2.5' is not a int"),
   ('material=black_denim', "'material=black_denim'"), ('warmup=', "'warmup='"),
   ('eye=1:2', "'1:2' is not three finite"), ('target=0:a:1', "'0:a:1' is not a float"),
   ('wind_speed=nan', "'nan' is not a finite number"),
   ('noise.blur=1', "'noise.blur=1'"), ('noise.native_width=6.5', "'6.5' is not a int"),
   ('noise=0.1', "'noise=0.1'"), ('noise.sigma_a=-1', 'sigma_a must be >= 0')],
)  # fmt: skip
def test_bad_recipe_fields_are_refused_naming_the_item(fields, named):
  with pytest.raises(ValueError, match='--recipe_fields') as e:
    windy_rig.recordings(windy_rig.Args(recipe_fields=fields))
  assert named in str(e.value)


@pytest.mark.parametrize('winds', ['fast', '3,-1', ',', '3,25'])
def test_bad_winds_are_refused(winds):
  with pytest.raises(ValueError, match='--winds'):
    windy_rig.recordings(windy_rig.Args(winds=winds))


def test_the_summary_counts_by_hand():
  rows = [
    {
      'mode': 'world_up',
      'exit': 0,
      'error': 0.05,
      'holds': True,
      'holds_50': True,
      'calibrated': True,
      'median': 3.1,
      'truth': 3.0,
    },
    {
      'mode': 'world_up',
      'exit': 0,
      'error': 0.15,
      'holds': False,
      'holds_50': False,
      'calibrated': True,
      'median': 5.0,
      'truth': 4.0,
    },
    {'mode': 'none', 'exit': 2},
    {
      'mode': 'world_up',
      'exit': 0,
      'error': 0.10,
      'holds': True,
      'median': 2.0,
      'truth': 2.0,
    },
  ]
  s = windy_rig.summary(rows)
  assert s['world_up'] == {
    'recordings': 3, 'refused': 0, 'mean_error': pytest.approx(0.10),
    'max_error': 0.15, 'within_10pct': 2, 'holds_90': 2, 'holds_50': 1,
    'calibrated': 2,
    'median_mean_error': pytest.approx((0.1 / 3 + 0.25 + 0) / 3),
    'median_within_10pct': 2,
  }  # fmt: skip
  assert s['none']['refused'] == 1 and s['none']['mean_error'] is None
  text = windy_rig.summary_table(s)
  assert (
    '| world_up | 3 | 0 | 10.0% | 15.0% | 2/3 | 2/3 | 1/3 | 2/3 | 9.4% | 2/3 |' in text
  )
  assert '| none | 1 | 1 | - | - | 0/0 | 0/0 | 0/0 | 0/0 | - | 0/0 |' in text


def test_fabric_draws_give_each_recording_a_fabric_of_the_prior():
  """By hand: the unit cube's bending is log-uniform over 0.1-10 and its area
  weight uniform over gray interlock's 0.15-0.22 kg/m^2 (the tables' prior)."""
  args = windy_rig.Args(winds='3.0,4.0,2.5', fabric_draws=7, recipe_fields='seed=70')
  recs = [r for _, r in windy_rig.recordings(args)]
  for k, r in enumerate(recs):
    u = np.random.default_rng([7, k]).uniform(-1.0, 1.0, 3)
    assert r.bending_scale == pytest.approx(10.0 ** u[0], rel=1e-9)
    assert r.area_weight == pytest.approx(0.15 + (u[2] + 1) / 2 * 0.07, rel=1e-9)
    assert (r.wind_speed, r.seed) == ((3.0, 4.0, 2.5)[k], 70 + k)
  assert len({r.area_weight for r in recs}) == 3  # each its own fabric
  plain = windy_rig.recordings(dataclasses.replace(args, fabric_draws=-1))
  assert {(r.bending_scale, r.area_weight) for _, r in plain} == {(1.0, 0.185)}
