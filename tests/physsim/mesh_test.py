"""Tests for physsim.mesh."""

import numpy as np
import pytest

from physsim import mesh


def test_square_area_and_lumped_areas():
  m = mesh.square(8, size=1.0)
  assert m.vertices.shape == (64, 3) and m.faces.shape == (2 * 49, 3)
  assert m.area == pytest.approx(1.0)
  assert m.vertex_areas.sum() == pytest.approx(1.0)
  # Pinned: the two top corners.
  top = m.vertices[m.pinned]
  np.testing.assert_allclose(top[:, 2], m.vertices[:, 2].max())
  np.testing.assert_allclose(sorted(top[:, 0]), [-0.5, 0.5])


def test_faces_are_consistently_oriented():
  m = mesh.square(6)
  p = m.vertices[m.faces]
  n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
  # One orientation for all (the wind force is orientation-invariant, but the
  # renderer's shading and the bending stencil want a consistent surface).
  assert np.all(n[:, 1] < 0) and np.allclose(n[:, [0, 2]], 0)


@pytest.mark.parametrize('name', mesh.GARMENTS)
def test_garments_are_recognisable_single_panels(name):
  m = mesh.garment(name, spacing=0.05)
  assert len(m.faces) > 100
  assert 0.2 < m.area < 1.0
  x = m.vertices[m.pinned, 0]
  assert x[0] < 0 < x[1]  # one pin each side
  assert len(np.unique(m.faces)) == len(m.vertices)  # no stray vertices


def test_jeans_have_two_legs():
  m = mesh.garment('jeans', spacing=0.04)
  low = m.vertices[m.vertices[:, 2] < m.vertices[:, 2].min() + 0.05]
  assert not np.any(np.abs(low[:, 0]) < 0.03)  # a gap between the legs


def test_bad_inputs():
  with pytest.raises(ValueError, match='resolution'):
    mesh.square(2)
  with pytest.raises(ValueError, match='tshirt'):
    mesh.garment('dress')
  with pytest.raises(ValueError, match='spacing'):
    mesh.garment('shirt', spacing=1.0)
