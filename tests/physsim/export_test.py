"""physsim.export: the exported MJCF, compiled by MuJoCo C, is the estimator's
cloth (stencil, masses, edge weights, and its motion against the estimator's
own MuJoCo C rollout); the ArcSim material carries the same scale."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

import physsim
from physsim import cloth, export

# Sideways gravity and no air: the sheet swings and bends with nothing but
# MuJoCo's own physics, so the file's model and the estimator's meet exactly.
_GRAVITY = np.array([0.0, 6.0, -8.0])
_FPS = 20.0
_FRAMES = 20
_S, _W = 3.0, 0.25


def _mesh():
  return physsim.square(8, 0.5)


def _config(mesh):
  return dataclasses.replace(physsim.config_for_mesh(mesh, _FPS), air_density=0.0)


def _estimator(s, w):
  """(T, V, 3) the estimator's own MuJoCo C rollout of the sheet."""
  mesh = _mesh()
  model = cloth.build(mesh, 'gray_interlock', _config(mesh))
  model.mj_model.opt.gravity[:] = _GRAVITY
  params = physsim.params.make(s, 1.0, w)  # no air: the wind does nothing
  return physsim.simulate(
    model, params, frames=_FRAMES, fps=_FPS, warmup=0.0, backend='c', workers=1
  ).positions[0]


def _exported(m):
  """(T, V, 3) an exported model stepped by MuJoCo C, at the rollout's frames."""
  m.opt.gravity[:] = _GRAVITY
  d = mujoco.MjData(m)
  steps = round(1.0 / _FPS / m.opt.timestep)
  out = []
  for _ in range(_FRAMES):
    for _ in range(steps):
      mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    out.append(d.flexvert_xpos.copy())
  return np.array(out)


def _distance(a, b):
  return float(np.linalg.norm(a - b, axis=-1).mean())


def test_the_file_compiles_to_the_estimators_stencil_masses_and_edges():
  mesh = _mesh()
  config = _config(mesh)
  own = cloth.build(mesh, 'gray_interlock', config)
  m = export.load(export.mujoco_xml(mesh, 'gray_interlock', _S, _W, config, 'a test'))
  # MuJoCo's own bending, compiled from the exported Young's modulus: the
  # estimator's stencil times the scale
  flap = m.flex_edgeflap.reshape(-1, 2)
  coef = m.flex_bending.reshape(-1, 17)[flap[:, 1] >= 0]
  # tolerance: Young's modulus written to 9 digits (the estimator's MJCF's)
  np.testing.assert_allclose(
    coef[:, :16].reshape(-1, 4, 4), _S * own.hinge_coef, rtol=1e-8, atol=1e-15
  )
  assert not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_SPRING  # bending on
  # each free vertex its area's mass (ArcSim's rule), the pins fixed
  free = own.vert_qadr >= 0
  np.testing.assert_allclose(
    m.body_mass[own.vert_body[free]], _W * mesh.vertex_areas[free], rtol=1e-10
  )
  assert m.nbody - 1 == free.sum() and m.opt.timestep == config.timestep
  np.testing.assert_array_equal(m.flexedge_invweight0, own.mj_model.flexedge_invweight0)


def test_the_file_moves_as_the_estimator_simulates():
  mesh = _mesh()
  xml = export.mujoco_xml(mesh, 'gray_interlock', _S, _W, _config(mesh))
  ours = _estimator(_S, _W)
  # the sheet swings well away from rest, and the parameters show in it
  assert _distance(ours, mesh.vertices) > 0.05
  by_param = min(_distance(ours, _estimator(_S * 1.5, _W)),
                 _distance(ours, _estimator(_S, _W * 1.05)))  # fmt: skip
  assert by_param > 1e-4
  # tolerance: float64 on both sides, the stencil's 9 digits (above) and
  # another order of the same sums, a thousandth of what a parameter moves
  assert _distance(_exported(export.load(xml)), ours) < 1e-3 * by_param
  # compiled without the estimator's edge weights, the edges follow the
  # true masses: another sheet, further off than a parameter change
  plain = mujoco.MjModel.from_xml_string(xml)
  assert _distance(_exported(plain), ours) > by_param


def test_the_arcsim_material_carries_the_scale_and_the_weight():
  base = physsim.load_material('gray_interlock')
  out = export.arcsim_material('gray_interlock', _S, _W)
  assert out['density'] == _W
  np.testing.assert_array_equal(out['stretching'], base.stretching)
  np.testing.assert_allclose(out['bending'], _S * base.bending, rtol=1e-12)
  # the estimator's one rigidity of that table (cloth.reference_rigidity's
  # rule, by hand): the scale times the fabric's own
  b = np.asarray(out['bending'])
  d = 7.0 / 36.0 * (0.5 * (b[:, 0] + b[:, 1])).mean()
  assert d == pytest.approx(_S * cloth.reference_rigidity('gray_interlock'), rel=1e-12)


@pytest.mark.parametrize(
  's, w',
  [(0.0, 0.2), (1.0, -0.1), (np.nan, 0.2), (1.0, np.inf), (1.0, 1e308), (1e300, 0.2)],
)
def test_parameters_out_of_range_are_refused_by_name(s, w):
  with pytest.raises(
    ValueError, match='bending_scale' if not 0 < s <= 1e4 else 'area_weight'
  ):
    export.arcsim_material('gray_interlock', s, w)
  with pytest.raises(ValueError, match='need a finite value > 0 and <='):
    export.mujoco_xml(_mesh(), 'gray_interlock', s, w, _config(_mesh()))


def test_load_takes_a_path_or_the_xml_text(tmp_path):
  mesh = _mesh()
  xml = export.mujoco_xml(mesh, 'gray_interlock', _S, _W, _config(mesh))
  path = tmp_path / 'fabric.xml'
  path.write_text(xml)
  from_path, from_text = export.load(str(path)), export.load('  ' + xml)
  np.testing.assert_array_equal(from_path.body_mass, from_text.body_mass)
  np.testing.assert_array_equal(
    from_path.flexedge_invweight0, from_text.flexedge_invweight0
  )
  with pytest.raises(ValueError, match='nowhere.xml: no such file'):
    export.load(str(tmp_path / 'nowhere.xml'))
