"""benchmarks/overhang_check.py: its set-ups cover the envelope and its
corners, a clean one has none of a real table's effects, and flying pixels
lie between the two sides of a jump only."""

from __future__ import annotations

import numpy as np

from benchmarks import overhang_check as check


def test_set_ups_lie_in_the_envelope_and_reach_its_corners():
  rng = np.random.default_rng(0)
  setups = [check.draw(rng, c, False) for c in np.geomspace(0.006, 0.04, 200)]
  for name, (lo, hi) in check.ENVELOPE.items():
    v = np.array([s[name] for s in setups])
    assert ((v >= lo) & (v <= hi)).all(), name
    # each end drawn as such about CORNER / 2 of the time (200 draws: >= 20)
    assert (v == lo).sum() >= 20 and (v == hi).sum() >= 20, name
  for s in setups:  # the user's reading to 5 mm marks, the strip's within 2 mm
    assert abs(s['told'] * 200 - round(s['told'] * 200)) < 1e-9
    assert abs(s['overhang'] - s['told']) <= 2 * check.RULER_SD + 1e-12
  clean = check.draw(rng, 0.02, True)
  assert all(clean[k] == v for k, v in check.CLEAN.items())
  assert clean['overhang'] == clean['told']


def test_flying_pixels_mix_the_two_sides_of_a_jump_only():
  depth = np.full((20, 20), 0.5)
  depth[:, 10:] = 0.8  # a 30 cm jump between columns 9 and 10
  depth[0, 0] = 0.0  # invalid stays invalid
  out = check.flying_pixels(depth, np.random.default_rng(1), share=1.0)
  changed = out != depth
  assert changed[:, 9:11].all() and not changed[:, :9].any()
  assert not changed[:, 11:].any() and out[0, 0] == 0.0
  assert ((out[changed] >= 0.5) & (out[changed] <= 0.8)).all()
