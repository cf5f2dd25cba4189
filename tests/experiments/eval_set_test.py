"""experiments.pipeline.eval_set: the real-like evaluation set's recipe."""

from __future__ import annotations

from experiments.pipeline import datasets, eval_set


def test_garments_use_their_fabric_and_every_part_has_colour():
  parts = eval_set.configs()
  assert set(parts) == {'fabrics', *eval_set.GARMENT_FABRICS}
  for garment, fabric in eval_set.GARMENT_FABRICS.items():
    assert parts[garment].materials == (fabric,)
    assert parts[garment].garment == garment
  assert all(c.rgb for c in parts.values())


def test_the_set_differs_from_training_as_documented():
  """Finer mesh and sensor noise against the training preset: what makes the
  set 'real-like' (the module docstring's list)."""
  train, ev = datasets.PRESETS['paper'], eval_set.configs()['fabrics']
  assert ev.cloth_resolution > train.cloth_resolution
  assert ev.noise and not train.noise
  assert ev.gust_intensity > train.gust_intensity
  assert ev.poses == 'evaluation' and train.poses == 'train'
  assert ev.seed != train.seed


def test_overrides_apply_to_every_part_and_zero_means_the_presets():
  parts = eval_set.configs(smoke=True, sequences=3, frames=0)
  assert {c.sequences for c in parts.values()} == {3}
  assert {c.frames for c in parts.values()} == {12}  # the smoke preset's
  assert parts['fabrics'].materials == ('gray_interlock', 'black_denim')
  assert set(parts) == {'fabrics', 'tshirt'}


def test_a_set_of_another_physics_for_every_part():
  parts = eval_set.configs(smoke=True, physics='mismatched')
  assert {c.physics for c in parts.values()} == {'mismatched'}
  assert {c.physics for c in eval_set.configs(smoke=True).values()} == {'own'}
