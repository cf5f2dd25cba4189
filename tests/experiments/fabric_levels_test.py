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
