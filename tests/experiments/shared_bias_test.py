"""benchmarks/shared_bias.py: a joint_pairs workdir packed and recombined;
groups whose recordings share a shifted area weight need a shared
discrepancy for their intervals to hold it."""

from __future__ import annotations

import json
import os

import numpy as np

import physsim
from benchmarks import shared_bias

GRID = (2, 4, 60)


def _workdir(root, shift: float, groups: int = 6) -> str:
  """A joint_pairs workdir of ``groups`` groups of three recordings, each
  recording's evidence a narrow Gaussian in area weight at the truth times
  (1 + shift): the error they share."""
  space = physsim.search_space('gray_interlock')
  lo, hi = space.area_weight
  w = lo + (np.arange(GRID[2]) + 0.5) / GRID[2] * (hi - lo)
  rng = np.random.default_rng(0)
  rows = []
  for g in range(groups):
    truth = float(rng.uniform(lo + 0.02, hi - 0.02))
    for k in range(3):
      seq = 3 * g + k
      ll = -0.5 * ((w - truth * (1 + shift)) / (0.01 * truth)) ** 2
      ll = np.broadcast_to(ll, GRID).ravel()
      d = os.path.join(root, f'pair_{g:02d}', f'recording_{k}')
      os.makedirs(d)
      np.savez(os.path.join(d, 'posterior.npz'), log_lik=ll,
               log_prior=np.zeros(ll.size), grid=np.array(GRID))  # fmt: skip
      rows.append({'seq': seq, 'truth': {'area_weight': truth}})
  with open(os.path.join(root, 'joint_pairs.json'), 'w') as f:
    json.dump({'flags': {'group': 3, 'material': 'gray_interlock'}, 'rows': rows}, f)
  return root


def test_a_shared_shift_needs_a_shared_discrepancy(tmp_path, capsys):
  root = _workdir(str(tmp_path / 'run'), shift=0.05)
  fields = str(tmp_path / 'fields.npz')
  shared_bias.main(shared_bias.Args(pack=root, out=fields))
  with np.load(fields) as z:
    assert sorted(z['seq']) == list(range(18)) and z['log_lik'].shape == (18, 480)
  out = str(tmp_path / 'sb.json')
  shared_bias.main(shared_bias.Args(
    runs=(os.path.join(root, 'joint_pairs.json'),), fields=(fields,),
    sds=(0.0, 0.05, 0.1), draws=2000, out=out,
  ))  # fmt: skip
  result = json.load(open(out))
  # 1% evidence three times, 5% off: at 0 no interval holds; at 0.1 all do
  assert result['table']['0.0']['calibration']['held_90'] == 0.0
  assert result['table']['0.1']['calibration']['held_90'] == 1.0
  assert result['chosen'] in (0.05, 0.1)
  assert 'chosen' in capsys.readouterr().out
