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


def _seen(world, position, pixels: int = 16) -> np.ndarray:
  """A stand-in camera: a (T=2, 4, 4) frame whose cloth share is a fixed
  function of the world and the pose (its first few pixels set)."""
  share = (np.sin(1000.0 * position.sum() + 7.0 * world) + 1.0) / 2.0
  frame = (np.arange(pixels) < round(share * pixels)).astype(np.float32)
  return np.broadcast_to(frame.reshape(4, 4), (2, 4, 4))


def test_cameras_drawn_again_render_only_their_worlds():
  # Against the rule as it was written first (every world rendered at every
  # draw, cameras picked among them): the same poses, frames, draws and
  # coverage, while only the worlds with a poorly framed camera are rendered.
  b, c = 6, 2
  config = dataclasses.replace(SMOKE, cameras=c, min_coverage=0.6, pose_draws=6)
  rng = np.random.default_rng(0)
  drawn = [rng.normal(size=(b, c, 3)) for _ in range(config.pose_draws)]
  rot = np.broadcast_to(np.eye(3), (b, c, 3, 3))

  def draw(attempt):
    return physsim.Pose(rot, drawn[attempt])

  def frames(worlds, poses):
    return np.stack([[_seen(w, poses.position[i, k]) for k in range(c)]
                     for i, w in enumerate(worlds)]), None  # fmt: skip

  valid = np.array([True, True, True, True, False, True])
  first = frames(np.arange(b), draw(0))
  rendered = []

  def some(worlds, poses):
    rendered.append(len(worlds))
    return frames(worlds, poses)

  got = datasets._frame_cameras(
    config, draw, some, draw(0), (first[0].copy(), None), valid
  )
  # the first rule, written out: every world rendered at each draw
  poses, depth = draw(0), first[0].copy()
  cover = datasets._coverage(depth)
  draws = np.ones((b, c), int)
  for attempt in range(1, config.pose_draws):
    low = (cover < config.min_coverage) & valid[:, None]
    if not low.any():
      break
    new = physsim.Pose(rot, np.where(low[..., None], drawn[attempt], poses.position))
    new_depth = frames(np.arange(b), new)[0]
    new_cover = datasets._coverage(new_depth)
    better = low & (new_cover > cover)
    poses = physsim.Pose(rot, np.where(better[..., None], new.position, poses.position))
    depth = np.where(better[..., None, None, None], new_depth, depth)
    cover = np.where(better, new_cover, cover)
    draws += low
  np.testing.assert_array_equal(got[0].position, poses.position)
  np.testing.assert_array_equal(got[1], depth)
  np.testing.assert_array_equal(got[3], draws)
  np.testing.assert_array_equal(got[4], cover)
  assert draws.max() > 2 and 0 < min(rendered) < b  # some worlds, not all
