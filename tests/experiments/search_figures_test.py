"""experiments.pipeline.search_figures: trace.png reads in the table's units."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from experiments.pipeline import files, posterior_figure, search_figures, units

FIELDS = physsim.Params._fields


def _trace(units_=None, truth=None):
  """A small trace (12 evaluations, one blown up) of gray_interlock's box."""
  space = physsim.search_space('gray_interlock')
  rng = np.random.default_rng(3)
  X = rng.uniform(-1, 1, (12, 3))
  Y = rng.uniform(0.1, 2.0, 12)
  Y[5] = np.nan
  it = search_figures.iterations_of(12, n_init=4, q=2)
  fig = search_figures.trace_figure(X, Y, it, space, truth, units=units_)
  return fig, np.asarray(physsim.from_unit(X, space)), space.bounds()


def test_the_trace_reads_in_the_tables_units():
  """Given the table's units (``units.in_units``), each parameter's panel is
  labelled with the table's name (bending rigidity in uN m, area weight in
  g/m^2) and its values, limits and truth are the search's times the factor."""
  names, k = units.in_units('gray_interlock')
  truth = {'bending_scale': 1.2, 'wind_speed': 3.0, 'area_weight': 0.2}
  fig, X, bounds = _trace((names, k), truth)
  panels = fig.axes[1:4]
  assert [ax.get_ylabel() for ax in panels] == [
    'bending rigidity (uN m)', 'wind (m/s)', 'area weight (g/m^2)'
  ]  # fmt: skip
  for i, (ax, name) in enumerate(zip(panels, FIELDS, strict=True)):
    (points,) = ax.collections
    np.testing.assert_allclose(points.get_offsets()[:, 1], k[name] * X[i], rtol=1e-12)
    np.testing.assert_allclose(ax.get_ylim(), k[name] * bounds[i], rtol=1e-12)
    (line,) = ax.get_lines()
    assert line.get_ydata()[0] == pytest.approx(k[name] * truth[name], rel=1e-12)
  assert k['bending_scale'] > 1e-3 and k['area_weight'] == 1e3  # not the scales
  files.pyplot().close(fig)


def test_without_units_the_trace_keeps_the_searchs_scales():
  fig, X, bounds = _trace()
  panels = fig.axes[1:4]
  assert [ax.get_ylabel() for ax in panels] == [
    posterior_figure.LABELS[f] for f in FIELDS
  ]
  for i, ax in enumerate(panels):
    np.testing.assert_array_equal(ax.collections[0].get_offsets()[:, 1], X[i])
    np.testing.assert_array_equal(ax.get_ylim(), bounds[i])
    assert len(ax.get_lines()) == 0  # no truth
  files.pyplot().close(fig)
