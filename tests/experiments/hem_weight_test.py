"""benchmarks.hem_weight: the smoke preset end to end (MuJoCo C, seconds) and
its flag check."""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest

import physsim
from benchmarks import hem_weight


@pytest.mark.slow  # two small studies end to end: ~20 s of MuJoCo C
def test_smoke_preset_end_to_end(tmp_path, capsys):
  args = hem_weight.PRESETS['smoke']
  figure = tmp_path / 'fig' / 'hem.png'
  hem_weight.main(
    type(args)(workdir=str(tmp_path / 'w'), figure=str(figure), study=args.study)
  )
  with open(tmp_path / 'w' / hem_weight.RESULT_FILE) as f:
    out = json.load(f)
  rows = out['rows']
  assert len(rows) == 2 * 2 * 2  # sets x drag laws x modes
  assert all(r['area_weight'] >= 1 - 1e-9 for r in rows)  # never wider than the prior
  assert all(np.isfinite(r['world_bias_pct']) for r in rows)  # another physics' bias
  cell = {(r['set'], r['drag_sd'], r['mode']): r['area_weight'] for r in rows}
  # the reading weighs the plain sheet only as far as the drag law is trusted
  assert cell[('sheet', 0.2, 'anemometer')] < cell[('sheet', 0.0, 'anemometer')]
  assert os.path.getsize(tmp_path / 'w' / hem_weight.FIGURE_FILE) > 1000
  assert figure.exists()
  assert '| sheet + hem |' in capsys.readouterr().out
  # another world, the same slopes (cached): its own residuals, its own bias
  hem_weight.main(
    type(args)(workdir=str(tmp_path / 'w'), world=('edge_solref_scale=2',),
               study=args.study)
  )  # fmt: skip
  with open(tmp_path / 'w' / hem_weight.RESULT_FILE) as f:
    edges = json.load(f)
  assert edges['world'] == dataclasses.asdict(physsim.Mismatch(edge_solref_scale=2.0))
  assert [r['area_weight'] for r in edges['rows']] == [r['area_weight'] for r in rows]
  assert [r['world_bias_pct'] for r in edges['rows']] != [
    r['world_bias_pct'] for r in rows
  ]


@pytest.mark.parametrize('bad', [('-0.1',), ('x',), ()])
def test_bad_drag_sds_refused(bad):
  with pytest.raises(ValueError, match='--drag_sds'):
    hem_weight.drag_values(bad)


def test_the_other_physics_from_the_flag():
  assert hem_weight.world_of(()) == physsim.mismatch.WORLD
  one = hem_weight.world_of(('edge_solref_scale=2',))
  assert one == physsim.Mismatch(edge_solref_scale=2.0)
  for bad in (
    ('edges=2',),
    ('air_drag=-1',),
    ('air_drag=x',),
    ('air_drag=1', 'air_drag=2'),
  ):
    with pytest.raises(ValueError, match='--world'):
      hem_weight.world_of(bad)
