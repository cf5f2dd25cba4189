"""physsim.hem_mass and ``build``'s ``extra_mass``: known masses attached to
a cloth, by hand (where the hem's mass goes, the JAX path's masses equal the
C path's) and in MuJoCo C: a mass attached in proportion to each vertex's
area moves the cloth exactly as the same area weight of its own does (gravity
and inertia alike, in steady wind), and a lighter cloth without it does not
(the negative control)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import physsim

RES = 8
# Two MuJoCo C runs of one problem, its masses summed in two orders, agree to
# float rounding grown over the clip; the negative control moves the cloth by
# centimetres.
_SAME_M = 1e-6
_DIFFERENT_M = 1e-3
_SPACE = physsim.SearchSpace(
  bending_scale=(0.01, 100.0), wind_speed=(0.0, 10.0), area_weight=(0.01, 2.0)
)


def test_the_hem_by_hand():
  mesh = physsim.square(RES, 0.2)
  extra = physsim.hem_mass(mesh, RES, 0.005)
  assert extra.sum() == pytest.approx(0.005, rel=1e-12)
  assert np.all(extra[-RES:] == pytest.approx(0.005 / RES, rel=1e-12))
  assert not extra[:-RES].any()
  model = physsim.build(mesh, 'gray_interlock', extra_mass=extra)
  w = np.array([0.1, 0.2])
  want = w[:, None] * mesh.vertex_areas + extra
  np.testing.assert_allclose(model.vertex_masses(w), want, rtol=1e-12)
  # the JAX path (MJX / MuJoCo Warp) sets the same body masses, in float32
  np.testing.assert_allclose(
    np.asarray(model.body_masses_jax(jax.numpy.asarray(w))),
    model.body_masses(w), rtol=1e-6,
  )  # fmt: skip
  moving = model.vert_qadr >= 0
  assert model.body_masses(w).sum(axis=1) == pytest.approx(
    (w[:, None] * mesh.vertex_areas[moving]).sum(axis=1) + extra[moving].sum()
  )


@pytest.mark.parametrize(
  'extra, rows, mass',
  [(np.ones(3), None, None), (None, 7, 0.01), (None, RES, -0.01), (None, RES, np.nan)],
)
def test_bad_masses_refused(extra, rows, mass):
  mesh = physsim.square(RES, 0.2)
  with pytest.raises(ValueError, match='extra_mass|hem_mass'):
    if extra is not None:
      physsim.build(mesh, 'gray_interlock', extra_mass=extra)
    else:
      physsim.hem_mass(mesh, rows, mass)


def _positions(extra_per_area: float, area_weight: float) -> np.ndarray:
  mesh = physsim.square(RES, 0.2)
  cfg = physsim.config_for_mesh(mesh, 20.0)
  extra = extra_per_area * mesh.vertex_areas
  model = physsim.build(mesh, 'gray_interlock', cfg, extra_mass=extra)
  params = physsim.params.make(1.0, 2.0, area_weight)
  out = physsim.simulate(
    model, params, frames=4, fps=20.0, warmup=0.3, backend='c', space=_SPACE,
    workers=1,
  )  # fmt: skip
  assert np.all(out.valid)
  return out.positions[0]


def test_an_attached_mass_moves_the_cloth_as_its_own_weight_does():
  # extra mass spread as the cloth's own (per vertex area) is area weight:
  # the same gravity, the same inertia against the same wind and bending
  want = _positions(0.0, 0.23)
  np.testing.assert_allclose(_positions(0.05, 0.18), want, atol=_SAME_M)
  # the control: without it the lighter cloth is blown elsewhere
  assert np.abs(_positions(0.0, 0.18) - want).max() > _DIFFERENT_M
