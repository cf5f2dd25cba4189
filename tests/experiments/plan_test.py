"""experiments.plan: a known answer on a synthetic posterior, and the command
end to end with the simulator at a tiny size."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import physsim
from experiments import plan as script
from experiments.pipeline import layout
from experiments.studies import protocol_plan


def _posterior(workdir, bending_u, area_u, n=400, seed=0):
  """A posterior.npz of draws uniform over bending_u x area_u (unit cube),
  wind over its whole range, and the estimate.json naming the fabric."""
  rng = np.random.default_rng(seed)
  u = np.stack(
    [rng.uniform(*bending_u, n), rng.uniform(-1, 1, n), rng.uniform(*area_u, n)], 1
  )
  os.makedirs(workdir, exist_ok=True)
  space = physsim.search_space('gray_interlock')
  np.savez(os.path.join(workdir, 'posterior.npz'), samples=u, bounds=space.bounds())
  with open(os.path.join(workdir, 'estimate.json'), 'w') as f:
    json.dump({'material': 'gray_interlock'}, f)


def test_the_candidate_that_sees_the_widest_parameter_wins_by_hand(tmp_path):
  # bending wide (the whole box), area weight narrow: a recording that sees
  # only bending beats one that sees only area weight at the same noise
  _posterior(tmp_path, (-1, 1), (-0.1, 0.1))
  material, draws, weights = layout.read_draws(str(tmp_path))
  assert material == 'gray_interlock' and draws.shape == (400, 2)
  sigma = 0.3
  sees = lambda i: {
    'wind': 0.0,
    'slopes': [[1.0 * (i == 0), 1.0 * (i == 1)]],
    'noise_cov': [[sigma**2]],
  }
  nodes = protocol_plan.node_values(draws, 1)
  ranked = protocol_plan.rank_candidates(
    draws,
    weights,
    {'bending': [sees(0)], 'area weight': [sees(1)]},
    nodes,
    0.0,
    material,
  )
  assert [r['candidate'] for r in ranked] == ['bending', 'area weight']
  var = np.cov(draws, rowvar=False)
  for r, i in zip(ranked, (0, 1), strict=True):
    # by hand: one look at parameter i, det(I + S F) = 1 + S_ii / sigma^2
    assert r['eig_nats'] == pytest.approx(
      0.5 * np.log(1 + var[i, i] / sigma**2), rel=1e-9
    )
    # and its own width after: 1 / sqrt(1 / S_ii + 1 / sigma^2)
    field = ('sd_log_bending', 'sd_log_area_weight')[i]
    assert r[field][1] == pytest.approx(
      1 / np.sqrt(1 / var[i, i] + 1 / sigma**2), rel=1e-9
    )


@pytest.mark.slow  # ~20 s of MuJoCo C
def test_plan_end_to_end_with_the_simulator(tmp_path, capsys):
  # area weight wide, an anemometer on the new recording: the sheet in wind
  # measures the load ratio, hence area weight; a still swatch hangs flat and
  # tells nothing (the known answer: its gain is 0)
  _posterior(tmp_path, (-0.2, 0.2), (-1, 1))
  args = script.PRESETS['smoke']
  script.main(
    type(args)(**{**args.__dict__, 'workdir': str(tmp_path), 'reading': 0.02})
  )
  with open(tmp_path / protocol_plan.PLAN_FILE) as f:
    result = json.load(f)
  ranked = {r['candidate']: r for r in result['ranked']}
  assert result['ranked'][0]['candidate'] == 'sheet_100cm_2ms_r5'
  assert ranked['swatch_20cm_still_r5']['eig_nats'] < 0.01
  assert ranked['sheet_100cm_2ms_r5']['eig_nats'] > 0.1
  out = capsys.readouterr().out
  assert 'Next recording: a 100 cm square' in out


def test_an_overhang_is_described_as_the_depth_reader_wants_it_filmed():
  words = protocol_plan.describe('overhang_3cm_r9', 2.0)
  assert '3 cm of it over the edge' in words and 'in front of the edge' in words
  assert 'experiments.overhang --depth' in words
