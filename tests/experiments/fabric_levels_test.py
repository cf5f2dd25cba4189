"""benchmarks.fabric_levels: a fabric's own levels joined to the shipped ones
never narrow an interval, and leave the median and other quantities alone."""

from __future__ import annotations

import numpy as np

from benchmarks import fabric_levels


def test_joined_levels_only_widen_the_chosen_quantities():
  # PROBS (0.05, 0.25, 0.5, 0.75, 0.95) x two quantities
  shipped = np.array([[0.04, 0.03], [0.2, 0.2], [0.5, 0.5], [0.8, 0.8], [0.96, 0.97]])
  own = np.array([[0.01, 0.01], [0.3, 0.1], [0.6, 0.4], [0.7, 0.9], [0.99, 0.99]])
  out = fabric_levels.joined(shipped, own, [0])
  np.testing.assert_array_equal(out[:, 0], [0.01, 0.2, 0.5, 0.8, 0.99])
  np.testing.assert_array_equal(out[:, 1], shipped[:, 1])  # not chosen
  both = fabric_levels.joined(shipped, own, [0, 1])
  assert np.all(both[:2] <= shipped[:2]) and np.all(both[3:] >= shipped[3:])
  np.testing.assert_array_equal(both[2], shipped[2])


def _scores(n: int, wind_rank, material: str = 'white_tablecloth') -> list[dict]:
  """Recordings whose posteriors are uniform on [1, 2] in every quantity, the
  truth at rank ``wind_rank(i)`` in the wind and at the median elsewhere."""
  from experiments.studies import calibration as cal_lib

  qgrid = np.linspace(0.0, 1.0, 1001)
  qf = np.repeat((1.0 + qgrid)[:, None], len(cal_lib.FIELDS), axis=1)
  out = []
  for i in range(n):
    rank = np.full(len(cal_lib.FIELDS), 0.5)
    rank[fabric_levels.WIND] = wind_rank(i)
    out.append({'rank': rank, 'truth': 1.0 + rank, 'qf': qf, 'material': material,
                'width_ratio': np.full(len(cal_lib.FIELDS), 0.3)})  # fmt: skip
  return out


def test_a_quantity_is_short_only_when_its_intervals_miss_beyond_chance():
  from bo import calibration

  nominal = np.repeat(calibration.nominal_levels()[:, None], 4, axis=1)
  # half the truths at the posteriors' extreme: 50% held, short beyond chance
  half = _scores(24, lambda i: 0.999 if i % 2 else 0.5)
  assert fabric_levels.short_columns(half, nominal) == [fabric_levels.WIND]
  # two in 24 outside: 92% held, within chance of 90%
  few = _scores(24, lambda i: 0.999 if i < 2 else 0.5)
  assert fabric_levels.short_columns(few, nominal) == []


def test_held_out_seeds_read_a_short_fabric_wider_and_a_sound_one_as_shipped():
  from bo import calibration

  nominal = np.repeat(calibration.nominal_levels()[:, None], 4, axis=1)
  short = lambda i: 0.999 if i % 2 else 0.5  # noqa: E731
  by_seed = {
    s: _scores(12, short) + _scores(12, lambda i: 0.5, material='gray_interlock')
    for s in (1, 2, 3)
  }
  rows = fabric_levels.held_out(by_seed, nominal)
  assert len(rows['shipped']) == 72
  for rule in ('short fabrics', 'every fabric'):  # the wind's upper level raised
    mine = [x for x in rows[rule] if x['material'] == 'white_tablecloth']
    top = np.array([x['levels'][-1, fabric_levels.WIND] for x in mine])
    assert np.all(top > nominal[-1, 0])
  sound = [x for x in rows['short fabrics'] if x['material'] == 'gray_interlock']
  for x in sound:  # nothing flagged there: the shipped levels
    np.testing.assert_array_equal(x['levels'], nominal)
