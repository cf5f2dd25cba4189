"""Tests for physsim.materials."""

import numpy as np
import pytest

from physsim import materials


def test_seven_fabrics_load_with_measured_tables():
  assert len(materials.FABRICS) == 7
  for name, fab in materials.FABRICS.items():
    m = materials.load_material(name)
    assert m.name == fab.material
    assert m.bending.shape == (3, 5) and m.stretching.shape == (6, 4)
    assert np.all(m.bending >= 0) and 0.05 < m.density < 0.5
    lo, hi = fab.area_weight_range
    assert lo < fab.real_area_weight < hi


def test_gray_interlock_values_match_arcsim_file():
  m = materials.load_material('gray-interlock')
  assert m.density == pytest.approx(0.187)
  assert m.bending[0, 0] == pytest.approx(23.191698e-6)


def test_licence_ships_with_data():
  assert 'Regents of the University of California' in materials.license_text()
  assert len(materials.material_names()) == 10


@pytest.mark.parametrize('bad', ['cotton', 'gray interlock', ''])
def test_unknown_material_names_the_choices(bad):
  with pytest.raises(ValueError, match='gray_interlock'):
    materials.load_material(bad)
