"""experiments.pipeline.setup: what an estimate is built from, resolved once."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from experiments.pipeline import embedding, report, setup
from experiments.pipeline import objective as obj

SHAPE = obj.PRESETS['smoke'].replace(distance='shape')


def test_the_shape_distance_resolves_without_a_network():
  s = setup.resolve(SHAPE, '', image_size=32)
  assert s.network.model_dir == '' and s.network.embedding.network is None
  assert s.network.embedding.image_size == (32, 32)
  assert s.network.recipe is None and s.network.accuracy is None
  assert len(s.mesh.vertices) == SHAPE.simulation.cloth_resolution**2
  np.testing.assert_allclose(s.pin_centre, obj.pin_centre(SHAPE.simulation), atol=1e-12)
  assert s.space == physsim.search_space(SHAPE.simulation.material)
  # The note the report would compute for these settings, read once here.
  assert s.calibration == report.calibration_note(SHAPE)


def test_a_distance_that_embeds_needs_a_network():
  with pytest.raises(ValueError, match='missing --model: --distance=energy'):
    setup.resolve(SHAPE.replace(distance='energy'), '')


def test_settings_are_checked_before_anything_is_read():
  bad = SHAPE.replace(sharpness=float('nan'))
  with pytest.raises(ValueError, match='sharpness'):
    setup.resolve(bad, '/no/such/network')


def test_a_network_of_another_fabric_is_refused_naming_both(monkeypatch):
  net = embedding.no_network((32, 32))._replace(materials=('black_denim',))
  monkeypatch.setattr(embedding, 'for_distance', lambda *a: net)
  monkeypatch.setattr(embedding, 'network_recipe', lambda d: {'training': {}})
  monkeypatch.setattr(embedding, 'network_accuracy', lambda d: 0.8)
  monkeypatch.setattr(embedding, 'network_retrieval', lambda d: None)
  config = SHAPE.replace(material='gray_interlock')
  with pytest.raises(ValueError, match=r"\['black_denim'\], not gray_interlock"):
    setup.resolve(config, 'runs/denim')
  s = setup.resolve(config, 'runs/denim', allow_other_material=True)
  assert s.network.accuracy == 0.8 and s.network.recipe == {'training': {}}
