"""experiments.overhang: a ruler's overhang reading turned into the flags an
estimate takes, against physsim.cantilever and the bending scale by hand."""

from __future__ import annotations

import dataclasses
import math

import pytest

import physsim
from experiments import overhang
from physsim import cantilever


def test_the_reading_is_the_elastica_and_the_scale_by_hand(capsys):
  c = 0.02
  reach = 0.05 * cantilever.tip(0.05 / c)[0][0]
  args = overhang.Args(
    overhang=0.05, reach=reach, ruler_sd=0.001, material='gray_interlock',
    area_weight=0.2, area_weight_sd=0.004,
  )  # fmt: skip
  r = overhang.reading(args)
  assert r['bending_length'] == pytest.approx(c, rel=1e-6)
  d = 0.2 * physsim.params.GRAVITY * c**3
  assert r['rigidity'] == pytest.approx(d, rel=1e-5)
  rel = math.hypot(3 * r['bending_length_sd'] / c, 0.004 / 0.2)
  assert r['rigidity_sd'] == pytest.approx(d * rel, rel=1e-5)
  d0 = physsim.reference_rigidity('gray_interlock')
  assert r['bending_scale'] == pytest.approx(d / d0, rel=1e-5)
  overhang.main(args)
  out = capsys.readouterr().out
  assert f'--bending_length={c:.4g}' in out and 'bending scale' in out
  # without an area weight: the bending length alone
  assert set(overhang.reading(dataclasses.replace(args, area_weight=0.0))) == {
    'bending_length', 'bending_length_sd'
  }  # fmt: skip


@pytest.mark.parametrize(
  'change, flag',
  [
    ({'overhang': 0.0}, '--overhang'),
    ({'reach': 0.06}, '--reach'),
    ({'reach': 0.0}, '--reach'),
    ({'ruler_sd': -0.001}, '--ruler_sd'),
    ({'material': 'tweed'}, '--material'),
    ({'reach': 0.04999}, '--overhang=0.05 --reach=0.04999'),
  ],
)
def test_bad_readings_name_their_flag(change, flag):
  args = dataclasses.replace(overhang.Args(overhang=0.05, reach=0.03), **change)
  with pytest.raises(ValueError, match=flag):
    overhang.reading(args)
