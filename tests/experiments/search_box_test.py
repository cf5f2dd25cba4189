"""The search box follows the measurements (issue 76): a reading whose 99.9%
range leaves the fabric's box widens it, says so, and is never pinned at its
edge; the widening has limits; a joint's recordings share one box."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from experiments.pipeline import joint, measurements, objective, setup

SMOKE = objective.PRESETS['smoke']


def test_a_stiff_strips_bending_length_widens_the_bending_box():
  # experiments.overhang's own example read bending 15.5 of gray interlock,
  # beyond the box's 10: the estimate's bending was pinned at 9.6
  space = physsim.search_space('gray_interlock')
  w = 0.2
  c = float(physsim.params.bending_length(15.5, w, space.rigidity))
  config = SMOKE.replace(bending_length=c, bending_length_sd=0.03 * c)
  st = setup.resolve(config, '', image_size=32)
  # by hand: the reading's 99.9% high end, at the box's heaviest area weight
  w_hi = space.area_weight[1]
  b_hi = (c * (1 + 3.29 * 0.03)) ** 3 * w_hi * 9.81 / space.rigidity
  assert st.space.bending_scale == (0.1, pytest.approx(b_hi, rel=1e-9))
  assert st.space.bending_scale[1] > 15.5 * w_hi / w  # the truth fits, at any w
  assert st.space.wind_speed == space.wind_speed  # the rest as the fabric's
  (line,) = st.widened
  assert 'bending box 0.1-10 widened to' in line and 'bending length' in line
  assert "a search box other than the fabric's" in st.calibration['differs']


def test_a_reading_inside_the_box_leaves_it_as_the_fabrics():
  config = SMOKE.replace(wind_speed=3.0, wind_speed_sd=0.06)
  st = setup.resolve(config, '', image_size=32)
  assert st.space == physsim.search_space('gray_interlock') and st.widened == ()


def test_the_box_widens_only_as_far_as_its_limits():
  box, said = measurements.search_box(
    'gray_interlock', measurements.Measured(wind_speed=7.0, wind_speed_sd=0.14)
  )
  assert box.wind_speed == (1.0, pytest.approx(7.0 + 3.29 * 0.14))
  assert said == ['wind box 1-6 widened to 1-7.46 to hold the wind reading']
  too_fast = SMOKE.replace(wind_speed=20.0, wind_speed_sd=0.4)
  with pytest.raises(ValueError, match=r'--wind_speed=20.0 \+- 0.4 lies outside'):
    too_fast.check()


def test_a_joints_recordings_share_the_widest_box():
  configs = [SMOKE.replace(wind_speed=v, wind_speed_sd=0.02 * v) for v in (3.0, 7.0)]
  shared = joint._one_box(configs)
  boxes = [measurements.search_box('gray_interlock', c.measured, c.search.box)[0]
           for c in shared]  # fmt: skip
  assert boxes[0] == boxes[1]
  assert boxes[0].wind_speed == (1.0, pytest.approx(7.0 * (1 + 3.29 * 0.02)))
  same = [SMOKE.replace(wind_speed=3.0, wind_speed_sd=0.06)] * 2
  assert joint._one_box(same) == same  # nothing to share: as given


@pytest.mark.parametrize(
  'box, message',
  [
    ((0.1, 10, 1, 6, 0.1), 'six numbers'),
    ((0.1, 10, 6, 1, 0.1, 0.3), 'wind_speed 6-1'),
    ((0.1, 1e3, 1, 6, 0.1, 0.3), 'bending_scale'),
    ((0.1, 10, 1, np.nan, 0.1, 0.3), 'must be finite'),
  ],
)
def test_a_bad_box_is_refused_naming_the_flag(box, message):
  with pytest.raises(ValueError, match=message) as e:
    SMOKE.replace(box=box).check()
  assert str(e.value).startswith('--box')
