"""experiments.pipeline.embedding: the network an estimate compares frames through."""

from __future__ import annotations

import numpy as np
import pytest

from experiments.pipeline import embedding


def test_the_shape_distance_needs_no_network():
  net = embedding.for_distance('', 'shape', 32)
  assert net.network is None and net.params == {}
  assert net.image_size == (32, 32)
  assert net.modality == 'depth' and net.members == 0


def test_a_distance_that_embeds_without_a_network_is_refused():
  with pytest.raises(ValueError, match='missing --model: --distance=energy'):
    embedding.for_distance('', 'energy', 32)


@pytest.mark.parametrize('size', [8, 2048])
def test_frame_sizes_outside_the_range_are_refused(size):
  with pytest.raises(ValueError, match=f'--image_size={size}'):
    embedding.for_distance('', 'shape', size)


def test_a_folder_that_is_no_trained_run_is_refused(tmp_path):
  with pytest.raises(ValueError, match='not a trained run'):
    embedding.network_recipe(str(tmp_path))


def test_recipe_differences_names_the_fields():
  mine = {
    'training': {'lr': 1e-3, 'epochs': 5},
    'inputs': {'modality': 'depth'},
    'data': None,
  }
  theirs = {
    'training': {'lr': 1e-3, 'epochs': 6},
    'inputs': {'modality': 'rgb'},
    'data': {},
  }
  assert embedding.recipe_differences(mine, theirs) == [
    'data', 'inputs.modality', 'training.epochs'
  ]  # fmt: skip
  assert embedding.recipe_differences(mine, mine) == []


def test_resize_rgb_keeps_colours_and_takes_nearest_pixels():
  rgb = np.zeros((4, 6, 3), np.float32)
  rgb[:2, :3] = (1.0, 0.5, 0.25)  # the top-left quarter
  small = embedding.resize_rgb(rgb, (2, 3))
  assert small.shape == (2, 3, 3)
  np.testing.assert_array_equal(small[0, 0], (1.0, 0.5, 0.25))
  np.testing.assert_array_equal(small[1, 2], (0.0, 0.0, 0.0))
