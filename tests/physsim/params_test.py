"""Tests for physsim.params."""

import numpy as np
import pytest

from physsim import params

_TOLERANCE = 1e-12


def test_unit_round_trip():
  space = params.search_space('black_denim')
  u = np.random.default_rng(0).uniform(-1, 1, (50, 3))
  p = params.from_unit(u, space)
  np.testing.assert_allclose(params.to_unit(p, space), u, atol=_TOLERANCE)
  assert np.all((p.area_weight >= 0.30) & (p.area_weight <= 0.37))


def test_bending_is_log10_in_default_range():
  p = params.make([0.1, 1.0, 10.0, 3.0], 3.0, 0.2)
  u = params.to_unit(p)
  np.testing.assert_allclose(u[:, 0], np.log10(p.bending_scale), atol=_TOLERANCE)


def test_center_is_trivial_estimate():
  c = params.search_space('white_tablecloth').center()
  assert float(c.bending_scale) == pytest.approx(1.0)
  assert float(c.wind_speed) == pytest.approx(3.5)
  assert float(c.area_weight) == pytest.approx(0.135)


@pytest.mark.parametrize(
  ('field', 'values'),
  [
    ('bending_scale', (20.0, 3.0, 0.2)),
    ('wind_speed', (1.0, 0.5, 0.2)),
    ('area_weight', (1.0, 3.0, np.nan)),
    ('wind_speed', (1.0, np.inf, 0.2)),
  ],
)
def test_out_of_range_names_field_and_range(field, values):
  with pytest.raises(ValueError, match=field) as err:
    params.validate(params.make(*values))
  assert '[' in str(err.value)  # the allowed range is quoted


def test_from_unit_rejects_outside_box_and_bad_shape():
  with pytest.raises(ValueError, match=r'\[-1, 1\]'):
    params.from_unit([0.0, 1.5, 0.0])
  with pytest.raises(ValueError, match='trailing axis'):
    params.from_unit([0.0, 0.0])


def test_load_ratio_by_hand():
  # rho v^2 / (w g) with rho = 1 kg/m^3: 3 m/s on 0.2 kg/m^2
  np.testing.assert_allclose(
    params.load_ratio(3.0, 0.2), 9.0 / (0.2 * 9.81), rtol=1e-12
  )
  np.testing.assert_allclose(
    params.load_ratio([1.0, 2.0], [0.1, 0.4]), [1 / 0.981, 4 / 3.924], rtol=1e-12
  )
