"""experiments.pipeline.setup: what an estimate is built from, resolved once."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from experiments.pipeline import calibration_tables, embedding, estimation, setup
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
  assert s.calibration == calibration_tables.calibration_note(SHAPE)


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


def _job(config, model_dir='', **kw):
  from experiments.pipeline import recording, search

  rec = recording.Recording(
    depth=np.zeros((4, 24, 32), np.float32), fps=20.0, intrinsics=None, pose=None,
    source='rec', truth=None,
  )  # fmt: skip
  return search.Job(config, rec, model_dir, '/nonexistent/workdir', **kw)


def test_jobs_resolve_once_per_network_folder(monkeypatch):
  # Three jobs of one network folder and one without: the network is restored
  # and its record read once; the shape job compares at the recording's size.
  from experiments.pipeline import searcher

  loads = []
  net = embedding.no_network((32, 32))._replace(materials=('gray_interlock',))
  monkeypatch.setattr(embedding, 'load_embedding', lambda d: loads.append(d) or net)
  monkeypatch.setattr(embedding, 'network_recipe', lambda d: {'training': {}})
  monkeypatch.setattr(embedding, 'network_accuracy', lambda d: 0.8)
  monkeypatch.setattr(embedding, 'network_retrieval', lambda d: None)
  jobs = [_job(SHAPE, 'runs/gray') for _ in range(3)] + [_job(SHAPE)]
  out = searcher.resolve_jobs(jobs)
  assert loads == ['runs/gray']
  assert all(o.setup.network.embedding is net for o in out[:3])
  assert out[3].setup.network.embedding.image_size == (24, 32)
  # A job that has its setup keeps it (nothing read again).
  assert searcher.resolve_jobs(out)[0].setup is out[0].setup and loads == ['runs/gray']
  # Each setup's calibration is the one resolve gives for its settings.
  assert out[3].setup.calibration == setup.resolve(SHAPE, '', image_size=32).calibration


def test_a_job_that_cannot_be_set_up_is_its_error_not_the_batchs(monkeypatch):
  from experiments.pipeline import searcher

  net = embedding.no_network((32, 32))._replace(materials=('black_denim',))
  monkeypatch.setattr(embedding, 'load_embedding', lambda d: net)
  for name in ('network_recipe', 'network_accuracy', 'network_retrieval'):
    monkeypatch.setattr(embedding, name, lambda d: None)
  out = searcher.resolve_jobs([_job(SHAPE, 'runs/denim'), _job(SHAPE)])
  assert isinstance(out[0], ValueError) and 'not gray_interlock' in str(out[0])
  assert out[1].setup is not None


def test_an_estimate_refuses_a_setup_of_other_settings():

  s = setup.resolve(SHAPE, '', image_size=32)
  with pytest.raises(ValueError, match='other settings.*q'):
    estimation.estimate(
      SHAPE.replace(q=4), _job(SHAPE).recording, '', '/nonexistent', setup=s
    )
