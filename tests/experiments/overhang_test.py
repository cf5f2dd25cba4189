"""experiments.overhang: a ruler's overhang reading turned into the flags an
estimate takes, against physsim.cantilever and the bending scale by hand."""

from __future__ import annotations

import dataclasses
import math

import pytest

import physsim
from experiments import overhang
from physsim import cantilever, overhang_depth
from tests.experiments import overhang_fixtures


def test_the_reading_is_the_elastica_and_the_scale_by_hand(capsys):
  c = 0.02
  reach = 0.05 * cantilever.tip(0.05 / c)[0][0]
  args = overhang.Args(
    overhang=(0.05,), reach=(reach,), ruler_sd=0.001, material='gray_interlock',
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
  assert 'dof' not in out  # a ruler's reading is Gaussian
  # without an area weight: the bending length alone
  assert set(overhang.reading(dataclasses.replace(args, area_weight=0.0))) == {
    'bending_length', 'bending_length_sd', 'readings'
  }  # fmt: skip


@pytest.mark.parametrize(
  'change, flag',
  [
    ({'overhang': (0.0,)}, '--overhang=0.0'),
    ({'reach': (0.06,)}, '--reach=0.06'),
    ({'reach': (0.0,)}, '--reach=0.0'),
    ({'reach': (0.03, 0.03)}, 'one reach per overhang'),
    ({'overhang': (), 'reach': ()}, 'at least one'),
    ({'ruler_sd': -0.001}, '--ruler_sd'),
    ({'material': 'tweed'}, '--material'),
    ({'reach': (0.04999,)}, '--overhang=0.05 --reach=0.04999'),
  ],
)
def test_bad_readings_name_their_flag(change, flag):
  args = dataclasses.replace(overhang.Args(overhang=(0.05,), reach=(0.03,)), **change)
  with pytest.raises(ValueError, match=flag):
    overhang.reading(args)


def test_several_readings_are_averaged_with_the_larger_spread():
  # Three readings (the standard takes four: both ends, face up and down):
  # their mean; its sd the larger of the ruler's (the readings' sds in
  # quadrature over n) and the scatter's standard error, by hand from each
  # reading alone.
  reaches = (0.045, 0.043, 0.046)
  args = overhang.Args(overhang=(0.06,) * 3, reach=reaches, ruler_sd=0.001)
  r = overhang.reading(args)
  alone = [cantilever.bending_length_sd(0.06, x, 0.001, 0.001) for x in reaches]
  cs = [c for c, _ in alone]
  assert r['readings'] == pytest.approx(cs, rel=1e-12)
  assert r['bending_length'] == pytest.approx(sum(cs) / 3, rel=1e-12)
  ruler = math.sqrt(sum(sd**2 for _, sd in alone)) / 3
  mean = sum(cs) / 3
  scatter = math.sqrt(sum((c - mean) ** 2 for c in cs) / 2) / math.sqrt(3)
  assert scatter > ruler  # these readings scatter more than the ruler says
  assert r['bending_length_sd'] == pytest.approx(scatter, rel=1e-9)
  # two identical readings: the ruler's alone, a single reading's sd / sqrt(2)
  same = overhang.reading(
    dataclasses.replace(args, overhang=(0.06,) * 2, reach=(0.045,) * 2)
  )
  assert same['bending_length_sd'] == pytest.approx(
    alone[0][1] / math.sqrt(2), rel=1e-9
  )


def test_a_depth_recording_instead_of_a_ruler(tmp_path, capsys):
  frames, cam = overhang_fixtures.write_overhang_recording(str(tmp_path))
  args = overhang.Args(
    overhang=(0.04,), depth=(frames,), camera=cam, material='gray_interlock',
    area_weight=0.2, area_weight_sd=0.004, figure=str(tmp_path / 'fit.png'),
  )  # fmt: skip
  r = overhang.reading(args)
  # mm-rounded frames of a clean render: c within the reader's clean tolerance
  assert r['bending_length'] == pytest.approx(0.02, rel=0.02)
  assert r['bending_length_dof'] == overhang_depth.DOF  # the reader's t law
  # at least its floor and half the ruler's 1 mm share of c over 4 cm
  assert r['bending_length_sd'] >= max(overhang_depth.FLOOR, 0.5 * 0.001 / 0.04) * 0.02
  overhang.main(args)
  out = capsys.readouterr().out
  assert 'strip pixels' in out and '--bending_length=' in out and 'bending scale' in out
  assert 'the edge rounded' in out  # a sharp edge: its radius, read near 0
  # the law goes with the reading to the estimate
  assert f'--bending_length_dof={overhang_depth.DOF:g}' in out
  assert f'"bending_length_dof": {overhang_depth.DOF:g}' in out
  assert (tmp_path / 'fit.png').stat().st_size > 0


@pytest.mark.parametrize(
  'change, flag',
  [
    ({'camera': ''}, 'needs --camera'),
    ({'reach': (0.03,)}, '--depth and --reach'),
    ({'depth': ('a', 'b')}, 'one depth per overhang'),
  ],
)
def test_bad_depth_readings_name_their_flag(change, flag, tmp_path):
  args = dataclasses.replace(
    overhang.Args(overhang=(0.04,), depth=(str(tmp_path / 'none'),), camera='c.json'),
    **change,
  )
  with pytest.raises(ValueError, match=flag):
    overhang.reading(args)


def test_a_rounded_edges_overhang_and_reach_are_from_the_face():
  """On an edge rounded by 2 mm the strip bends from 2 mm behind the face,
  where the overhang and reach are measured from: with ``--edge_radius`` the
  elastica of L + 2 mm whose tip reaches 2 mm further gives c back; taken as
  sharp, c is read short. Its sd adds the radius's by a secant."""
  c, length, radius = 0.015, 0.045, 0.002
  free = length + radius
  reach = free * cantilever.tip(free / c)[0][0] - radius  # from the face
  args = overhang.Args(overhang=(length,), reach=(reach,), edge_radius=radius)
  r = overhang.reading(args)
  assert r['bending_length'] == pytest.approx(c, rel=1e-5)
  sharp = overhang.reading(dataclasses.replace(args, edge_radius=-1.0))
  assert sharp['bending_length'] < 0.98 * c
  wide = overhang.reading(dataclasses.replace(args, edge_radius_sd=0.001))
  up = cantilever.bending_length(length + 0.003, reach + 0.003)
  down = cantilever.bending_length(length + 0.001, reach + 0.001)
  assert wide['bending_length_sd'] == pytest.approx(
    math.hypot(r['bending_length_sd'], (up - down) / 2), rel=1e-6
  )
