"""The protocol set's joint estimate: a sheet's recording in a fan (a
calibration check's packed run: its saved GP on the posterior grid), an
anemometer's wind to ``WIND_SD`` and an overhang's bending length, against
the truth. Each set is read with the sheet and anemometer alone and with the
overhang too, at the nominal levels ('raw') and as an estimate prints it,
with a calibration file's tables ('printed').
"""

from __future__ import annotations

import dataclasses
import glob
import json
import math
import os

import numpy as np

import bo
import physsim
from experiments.pipeline import measurements
from experiments.pipeline import posterior as posterior_lib

WIND_SD = 0.02  # relative: the anemometer's


def packed_runs(folder: str) -> list[dict]:
  """Sheet recordings of a calibration check's packed runs: truth, fabric and
  the saved GP on the posterior grid."""
  out = []
  for path in sorted(glob.glob(os.path.join(folder, 'runs-*.npz'))):
    with np.load(path) as z:
      for j, seq in enumerate(z['seq']):
        out.append({
          'seq': int(seq), 'material': str(z['material'][j]),
          'truth': json.loads(str(z['truth'][j])),
          **{k: np.asarray(z[k][j], np.float64)
             for k in ('gp_mean', 'gp_var', 'floor', 'noise_sd')},
        })  # fmt: skip
  if not out:
    raise ValueError(f'--packed={folder}: no runs-*.npz there')
  return out


# The calibration mode of each of the benchmark's protocol sets
# (``experiments.studies.calibration.MODES``).
MODE_OF_SET = {'sheet, anemometer': 'known wind',
               'sheet, anemometer, overhang': 'known wind, bending length'}  # fmt: skip


def shipped_tables(path: str) -> dict:
  """``{set: (levels, weights)}`` of a calibration file's tables for the
  benchmark's protocol sets (a set its file has no table for is left out)."""
  cal = physsim.dataset.read_json(path)
  rec = cal.get('recalibration') or {}
  out = {}
  for name, mode in MODE_OF_SET.items():
    if mode in rec.get('modes', {}):
      levels = np.asarray(rec['modes'][mode])
      out[name] = (
        {f: levels[:, i] for i, f in enumerate(rec['fields'])},
        rec.get('weights', {}).get(mode, {}),
      )
  return out


def _grid_draws(rng, pts, grid, log_p, space, measured, seed: int, n: int = 4000):
  """Unit draws from a grid density, placed within their cells by a bending
  length's reading (as an estimate draws them)."""
  p = np.exp(log_p - log_p.max())
  idx = rng.choice(len(pts), n, p=p / p.sum())
  x = pts[idx] + (rng.random((n, 3)) - 0.5) * 2.0 / np.array(grid)
  return posterior_lib.refine_draws(x, grid, space, measured, seed=seed)


def _measurements(truth: dict, reading: dict, rng) -> dict:
  """Each protocol set's measurements (``measurements.Measured``): the
  anemometer's wind, drawn to ``WIND_SD`` of the truth, and with it the
  overhang's bending length where the reader read one (not a refusal)."""
  wind = truth['wind_speed'] * (1 + WIND_SD * rng.standard_normal())
  modes = {
    'sheet, anemometer': measurements.Measured(
      wind_speed=wind, wind_speed_sd=WIND_SD * truth['wind_speed']
    ),
  }
  if 'c_hat' in reading:
    modes['sheet, anemometer, overhang'] = dataclasses.replace(
      modes['sheet, anemometer'], bending_length=reading['c_hat'],
      bending_length_sd=reading['sd'], bending_length_dof=reading['dof'],
    )  # fmt: skip
  return modes


def _scored(summ: dict, truth: dict, box: dict, how: str) -> dict:
  """Per field of a posterior's summary against ``truth``: the point (the
  median 'raw', else the Bayes point), the 90% interval, the error (a factor
  for the bending, relative for the rest), which intervals held, and how
  many times narrower the 90% interval is than ``box``'s (the prior's)."""
  row = {}
  for f in posterior_lib.FIELDS:
    s, t = summ[f], truth[f]
    point = s['median'] if how == 'raw' else s['bayes']
    (lo90, hi90), (lo50, hi50) = s['interval_90'], s['interval_50']
    log = f == 'bending_scale'
    width = math.log(hi90 / lo90) if log else hi90 - lo90
    pl, ph = box[f]['interval_90']
    prior_width = math.log(ph / pl) if log else ph - pl
    row[f] = {
      'point': point, 'interval_90': [lo90, hi90],
      'error': (math.exp(abs(math.log(point / t))) if log else abs(point / t - 1)),
      'held_90': bool(lo90 <= t <= hi90), 'held_50': bool(lo50 <= t <= hi50),
      'narrowing_90': prior_width / max(width, 1e-12),
    }  # fmt: skip
  return row


def joint_estimate(run: dict, reading: dict, args, seed: int,
                   tables: dict | None = None) -> dict:  # fmt: skip
  """The protocol set's posterior: the sheet's likelihood with the wind read
  to 2% and the overhang's bending length; per field the point, intervals
  and errors, read at the nominal levels ('raw') and, where ``tables`` (see
  ``shipped_tables``) has the set's mode, as an estimate prints them: at the
  calibration's levels, its point the weighted Bayes point ('printed').
  ``args``: the posterior's ``grid``, ``likelihood`` and ``sharpness`` (the
  benchmark's ``Args``)."""
  space = physsim.search_space(run['material'])
  truth = run['truth']
  grid = tuple(args.grid)
  pts = np.asarray(bo.posterior.grid_points(grid))
  rng = np.random.default_rng([seed, run['seq']])
  modes = _measurements(truth, reading, rng)
  ll = np.asarray(
    bo.posterior.log_likelihood(
      run['gp_mean'], run['gp_var'], run['floor'], run['noise_sd'],
      form=args.likelihood, sharpness=args.sharpness,
    )
  )  # fmt: skip
  box = posterior_lib.summarise(rng.uniform(-1, 1, (4000, 3)), space,
                                rng.uniform(-1, 1, (4000, 3)))  # fmt: skip
  out = {}
  for mode, m in modes.items():
    lp = measurements.log_prior(pts, space, m, grid)
    post = np.asarray(bo.posterior.log_normalise(lp + ll))
    draws = _grid_draws(rng, pts, grid, post, space, m, run['seq'])
    prior = _grid_draws(rng, pts, grid, lp, space, m, run['seq'] + 1)
    readings = {'raw': posterior_lib.summarise(draws, space, prior, measured=m)}
    if tables and mode in tables:
      levels, weights = tables[mode]
      readings['printed'] = posterior_lib.summarise(
        draws, space, prior, levels, weights, m
      )
    out[mode] = {how: _scored(summ, truth, box, how) for how, summ in readings.items()}
  return out
