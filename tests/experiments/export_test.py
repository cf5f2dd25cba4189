"""experiments.export: an estimate's (or a joint's) fabric written as MuJoCo
MJCF, an ArcSim material and posterior draws; a workdir without an estimate
refused in one line, nothing written."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import physsim
from experiments import export as script
from experiments.pipeline import fabric_files
from physsim import export

_POINT = {'bending_scale': 2.5, 'area_weight': 0.19}


def _entry(v):
  return {'value': v, 'median': v, 'interval_90': [0.9 * v, 1.1 * v]}


def _estimate(workdir, joint=False, draws=True, n=50):
  """An estimate's workdir: its JSON (a joint's shared entries at the top)
  and saved unit draws around the point."""
  os.makedirs(workdir, exist_ok=True)
  config = {'cloth_size': 0.5, 'cloth_resolution': 6, 'fps': 20.0}
  shared = {k: _entry(v) for k, v in _POINT.items()}
  body = {'material': 'gray_interlock', 'config': config}
  body.update(shared if joint else {'estimate': shared})
  name = 'joint.json' if joint else 'estimate.json'
  with open(os.path.join(workdir, name), 'w') as f:
    json.dump(body, f)
  if draws:
    space = physsim.search_space('gray_interlock')
    unit = physsim.to_unit(physsim.params.make(_POINT['bending_scale'], 3.0,
                                               _POINT['area_weight']), space)  # fmt: skip
    u = np.repeat(np.asarray(unit, np.float64).reshape(1, 3), n, 0)
    u += np.random.default_rng(0).normal(0, 0.01, u.shape)
    npz = 'joint_posterior.npz' if joint else 'posterior.npz'
    np.savez(os.path.join(workdir, npz), samples=u, bounds=space.bounds())


@pytest.mark.parametrize('joint', [False, True])
def test_the_fabric_of_an_estimate_or_a_joint_is_written(tmp_path, joint):
  _estimate(tmp_path / 'e', joint=joint)
  record = fabric_files.write(str(tmp_path / 'e'), str(tmp_path / 'f'), draws=20)
  assert record['point'] == _POINT
  assert set(record['files']) == {'mujoco', 'arcsim', 'draws'}
  # the sheet of the estimate's own size and mesh, at its point
  m = export.load(open(record['files']['mujoco']).read())
  mesh = physsim.square(6, 0.5)
  free = np.setdiff1d(np.arange(36), mesh.pinned)
  np.testing.assert_allclose(
    np.sort(m.body_mass[1:]), np.sort(0.19 * mesh.vertex_areas[free]), rtol=1e-10
  )
  assert json.load(open(record['files']['arcsim']))['density'] == 0.19
  rows = open(record['files']['draws']).read().splitlines()
  assert rows[0].startswith('bending_scale,') and len(rows) == 21
  table = np.array([[float(v) for v in r.split(',')] for r in rows[1:]])
  np.testing.assert_allclose(np.median(table[:, 0]), 2.5, rtol=0.1)
  np.testing.assert_allclose(np.median(table[:, 3]), 0.19, rtol=0.05)
  # each draw's rigidity and Young's modulus are its scale's
  d0 = physsim.reference_rigidity('gray_interlock')
  np.testing.assert_allclose(table[:, 1], table[:, 0] * d0, rtol=1e-4)
  saved = json.load(open(tmp_path / 'f' / fabric_files.FABRIC_FILE))
  assert saved['files'] == record['files'] and saved['sheet']['resolution'] == 6


def test_the_script_writes_the_sheet_it_is_asked_for(tmp_path, capsys):
  _estimate(tmp_path / 'e', draws=False)  # the paper's argmin keeps no draws
  script.main(script.Args(workdir=str(tmp_path / 'e'), cloth_size=0.3, resolution=5))
  out = capsys.readouterr().out
  assert 'no posterior draws' in out and 'area weight 0.19 kg/m^2' in out
  fabric = tmp_path / 'e' / 'fabric'
  # ArcSim's terms: its licence with every copy of its (modified) data
  assert sorted(os.listdir(fabric)) == [
    'LICENSE_ARCSIM.txt', 'fabric.json', 'fabric.xml', 'fabric_arcsim.json'
  ]  # fmt: skip
  m = export.load((fabric / 'fabric.xml').read_text())
  assert m.nflexvert == 25
  mesh = physsim.square(5, 0.3)  # the pinned corners carry none: fixed
  free = np.setdiff1d(np.arange(25), mesh.pinned)
  assert m.body_mass.sum() == pytest.approx(0.19 * mesh.vertex_areas[free].sum())


@pytest.mark.parametrize(
  'make, message',
  [
    (lambda d: None, 'no estimate.json or joint.json'),
    (lambda d: (d / 'estimate.json').write_text('{"material": "gray_interlock"}'),
     'no bending and area weight estimate'),
    (lambda d: (d / 'estimate.json').write_text('{not json'), 'not valid JSON'),
  ],
)  # fmt: skip
def test_a_workdir_without_an_estimate_is_refused_and_left_as_it_was(
  tmp_path, make, message
):
  (tmp_path / 'e').mkdir()
  make(tmp_path / 'e')
  before = sorted(os.listdir(tmp_path / 'e'))
  with pytest.raises(ValueError, match=message):
    script.main(script.Args(workdir=str(tmp_path / 'e')))
  assert sorted(os.listdir(tmp_path / 'e')) == before


@pytest.mark.parametrize(
  'flag', [{'draws': -1}, {'cloth_size': -0.5}, {'resolution': 2}]
)
def test_bad_flags_are_refused_by_name(tmp_path, flag):
  _estimate(tmp_path / 'e')
  name = next(iter(flag))
  with pytest.raises(ValueError, match=name):
    script.main(script.Args(workdir=str(tmp_path / 'e'), **flag))
  assert not os.path.exists(tmp_path / 'e' / 'fabric')
