"""An estimate's numbers: each quantity's summary of samples, its errors
against a known truth and whether its intervals held it.

What ``results`` records in ``estimate.json`` and what the studies and
benchmarks average over recordings; the tables (``report``) print them.
"""

from __future__ import annotations

import numpy as np

import physsim
from experiments.pipeline import measurements


def stats(value, samples: np.ndarray) -> dict:
  """A value with the median, 90% interval and spread of ``samples``."""
  return {
    'value': float(np.asarray(value).ravel()[0]),
    'posterior_median': float(np.median(samples)),
    'interval_90': [
      float(np.quantile(samples, 0.05)),
      float(np.quantile(samples, 0.95)),
    ],
    'std': float(samples.std()),
  }


def summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  """Per parameter, ``stats`` of the best point and of (S, 3) physical samples."""
  return {n: stats(best[i], samples_phys[:, i]) for i, n in enumerate(best._fields)}


def load_ratio_summary(samples_phys: np.ndarray, best: physsim.Params) -> dict:
  """rho v^2 / (w g) of the best candidate and of the samples: the
  combination of wind and area weight a sheet's shape constrains best."""
  i, j = (
    physsim.Params._fields.index('wind_speed'),
    physsim.Params._fields.index('area_weight'),
  )
  ratio = physsim.load_ratio(samples_phys[:, i], samples_phys[:, j])
  return stats(physsim.load_ratio(best.wind_speed, best.area_weight), ratio)


def point_of(stats: dict) -> float:
  """A quantity's summary as one number: the posterior median where there is a
  posterior, else the reported value (the paper's argmin protocol)."""
  return float(stats['median'] if 'median' in stats else stats['value'])


def errors(best: physsim.Params, truth: dict, space: physsim.SearchSpace,
           air: float | None = None) -> dict:  # fmt: skip
  """Percent errors of wind and area weight, the bending factor, the percent
  error of the load ratio c rho v^2 / (w g) (what a sheet's shape constrains
  best; c the air coefficient, 1 where not estimated), and the same for the
  trivial estimate (the centre of the search range). With ``air`` (the
  estimate's c) and a truth that knows its own, c's factor too."""
  centre = space.center()
  true_ratio = with_load_ratio(truth)['load_ratio']

  def one(p, c):
    b = float(np.asarray(p.bending_scale).ravel()[0])
    ratio = c * float(physsim.load_ratio(p.wind_speed, p.area_weight))
    pct = lambda k: 100 * abs(float(getattr(p, k)) - truth[k]) / truth[k]
    out = {
      'wind_speed_pct': pct('wind_speed'),
      'area_weight_pct': pct('area_weight'),
      'bending_factor': float(np.exp(abs(np.log(b / truth['bending_scale'])))),  # >= 1
      'load_ratio_pct': 100 * abs(ratio - true_ratio) / true_ratio,
    }
    if air is not None and 'air_coefficient' in truth:
      out['air_factor'] = float(np.exp(abs(np.log(c / truth['air_coefficient']))))
    return out

  mid = float(np.sqrt(np.prod(measurements.AIR_RANGE)))  # the prior's centre
  return {
    'estimate': one(best, 1.0 if air is None else air),
    'range_centre': one(centre, 1.0 if air is None else mid),
  }


def mean_error(values, name: str) -> float:
  """The mean of one ``errors`` measure over recordings: geometric for the
  bending factor (a factor), arithmetic for the percent errors."""
  if name == 'bending_factor':
    return float(np.exp(np.mean(np.log(values))))
  return float(np.mean(values))


def with_load_ratio(truth: dict) -> dict:
  """A truth (wind speed, area weight, ...) with its load ratio beside it:
  the load the sheet feels, c rho v^2 / (w g), c its air coefficient where the
  truth knows it (else ArcSim's 1)."""
  ratio = physsim.load_ratio(truth['wind_speed'], truth['area_weight'])
  return {**truth, 'load_ratio': float(truth.get('air_coefficient', 1.0) * ratio)}


def covered(result: dict, truth: dict) -> dict:
  """Per parameter and the load ratio: does each credible interval hold the truth?"""
  out = {}
  rows = dict(result['estimate'], load_ratio=result.get('load_ratio', {}))
  true = with_load_ratio(truth)
  for name, e in rows.items():
    if name not in true:  # an air coefficient the truth does not know
      continue
    out[name] = {
      k: bool(e[k][0] <= true[name] <= e[k][1]) for k in e if k.startswith('interval_')
    }
  return out
