"""experiments.studies.air_protocol's sets and summary (its runs are GPU-sized:
BENCHMARKS.md): the truths stay in their ranges, one fan setting a third, and
the summary's measures are the rows' own, by hand."""

from __future__ import annotations

import numpy as np
import pytest

from experiments.studies import air_protocol


def test_each_set_has_its_own_air_and_a_fan_setting_per_third():
  study = air_protocol.Study(sets=50, seed=3)
  sets = air_protocol.truths(study)
  c = np.array([t['air_coefficient'] for t in sets])
  assert c.min() >= 0.4 and c.max() <= 1.25 and len(set(c)) == 50
  third = (4.0 - 1.5) / 3
  for t in sets:
    for k, v in enumerate(t['winds']):
      assert 1.5 + k * third < v < 1.5 + (k + 1) * third
  assert air_protocol.truths(study) == sets  # seeded


def test_the_summary_is_the_rows_own_by_hand():
  row = lambda c, air, held, flagged, mode='free': {  # noqa: E731
    'mode': mode, 'c': c, 'air': air, 'air_pct': 100 * abs(air / c - 1),
    'air_in_90': held, 'air_in_50': False, 'bending_factor': 1.1,
    'area_weight_pct': 1.0, 'wind_pct': [1.0, 2.0, 3.0], 'flagged': flagged,
  }  # fmt: skip
  rows = [row(0.5, 0.55, True, True), row(1.0, 0.9, False, False),
          row(0.6, 0.6, True, True, 'fixed'), row(1.05, 1.0, True, True, 'fixed')]  # fmt: skip
  s = air_protocol.summarise(rows)
  assert s['free']['air_pct_mean'] == pytest.approx(10.0)
  assert s['free']['air_held_90'] == 0.5 and s['free']['wind_pct_mean'] == 2.0
  assert s['free']['flagged_c_below_0.7'] == [1, 1]
  assert s['fixed']['flagged_c_below_0.7'] == [1, 1]
  assert s['fixed']['flagged_c_0.9_1.1'] == [1, 1]
