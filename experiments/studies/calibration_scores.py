"""The calibration study's scores: each recording's posterior formed again
from its saved GP at a likelihood setting, in every mode (the video alone, a
reading, a bending length, a pair's joint posterior), and scored against its
truth: the truth's rank and the posterior's quantile function."""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import numpy as np

import bo
import physsim
from experiments.pipeline import measurements
from experiments.pipeline import posterior as posterior_lib
from experiments.studies.calibration_config import (
  FIELDS,
  MODES,
  Config,
  length_sd_of,
  run_material,
)
from experiments.studies.calibration_runs import saved_gp

# Each recording's posterior is kept as its quantile function on this grid of
# CDF levels, so intervals at any (recalibrated) level come without redrawing.
QGRID = np.linspace(0.0, 1.0, 1001)
LOG_FIELDS = posterior_lib.LOG_SCALED  # compared on a log scale
_LOG_COLUMNS = tuple(f in LOG_FIELDS for f in FIELDS)


def _draws(rng, grid, log_post, n: int) -> np.ndarray:
  """Draws from a grid posterior (numpy; as ``bo.posterior.sample_grid``)."""
  pts = bo.posterior.grid_points(grid)
  p = np.exp(log_post - np.max(log_post))
  idx = rng.choice(len(pts), size=n, p=p / p.sum())
  width = 2.0 / np.asarray(grid, np.float64)
  return np.clip(pts[idx] + (rng.random((n, 3)) - 0.5) * width, -1.0, 1.0)


def _log_lik(z: dict, form: str, sharpness: float, model_error: float) -> np.ndarray:
  return np.asarray(
    bo.posterior.log_likelihood(
      z['gp_mean'], z['gp_var'], z['floor'], z['noise_sd'], form=form,
      sharpness=sharpness, model_error=model_error,
    )
  )  # fmt: skip


def physical_with_ratio(unit, space) -> np.ndarray:
  p = measurements.physical(unit, space)
  return np.concatenate([p, physsim.load_ratio(p[:, 1], p[:, 2])[:, None]], axis=1)


def _truth_row(t: dict) -> np.ndarray:
  return np.array([t[f] for f in posterior_lib.FIELDS]
                  + [physsim.load_ratio(t['wind_speed'], t['area_weight'])])  # fmt: skip


@functools.lru_cache(maxsize=4096)
@functools.lru_cache(maxsize=8192)
def _prior_point(material: str, measured: measurements.Measured) -> np.ndarray:
  """The prior's own least-error points in ``FIELDS`` order (quadrature;
  read-only). Kept per fabric and reading: the analysis asks again for each
  likelihood and sharpness, and for every recording read without a reading."""
  p = posterior_lib.prior_points(physsim.search_space(material), measured, n=1001)
  out = np.array([p[f] for f in FIELDS])
  out.flags.writeable = False
  return out


def _score(draws_phys: np.ndarray, prior_phys: np.ndarray, truth_row: np.ndarray,
           seed: int, prior_point: np.ndarray, box_phys: np.ndarray) -> dict:  # fmt: skip
  """The truth's rank and the quantile function, per field, of the posterior's
  defensive mixture with its prior (``bo.calibration.defensive``, as an
  estimate reads it); intervals at any level are read off it later. With
  the prior's own least-error point (the reading's, for a measured mode), the
  truth's rank under the prior alone, and the width of the posterior's
  intervals over those of the search box's prior ``box_phys`` (the prior the
  truths are drawn from: about 1 where neither video nor reading told the
  posterior anything)."""
  mix = bo.calibration.defensive(draws_phys, prior_phys, seed=seed)
  return {
    'rank': bo.calibration.ranks(mix, truth_row),
    'width_ratio': bo.calibration.width_ratio(mix, box_phys, log=_LOG_COLUMNS),
    # how an interval that knows nothing (the prior's own) fares on this truth
    'prior_rank': bo.calibration.ranks(prior_phys, truth_row),
    'qf': bo.calibration.linear_quantiles(mix, QGRID),  # (len(QGRID), fields)
    'prior_point': prior_point,
  }


def posteriors(config: Config, runs: list[dict], form: str, sharpness: float,
               n: int = 2000, pairs: bool = True,
               model_error: float | None = None) -> dict[str, list[dict]]:  # fmt: skip
  """Every recording's scores under each mode, at one likelihood setting
  (``pairs``: recordings 2k and 2k+1 share bending and area weight, and
  their joint posterior is scored too). ``model_error``: the likelihood's
  discrepancy term (None: the study's estimate's)."""
  if model_error is None:
    model_error = config.estimate.scoring.model_error
  like = functools.partial(
    _log_lik, form=form, sharpness=sharpness, model_error=model_error
  )
  grid = tuple(config.estimate.search.posterior_grid)
  points = bo.posterior.grid_points(grid)
  rng = np.random.default_rng([config.seed, 11, int(sharpness * 1000)])
  out = {m: [] for m in MODES}
  by_seq = {r['seq']: r for r in runs}
  for r in runs:
    material = run_material(config, r)
    ll = like(saved_gp(r))
    alone, scored = _alone(config, r, material, ll, grid, points, rng, n)
    scored += _with_length(
      config, r, material, ll, grid, n, sharpness, alone.prior_draws['video']
    )
    mate = by_seq.get(r['seq'] ^ 1) if pairs else None  # the pair's other recording
    if mate is not None and r['seq'] % 2 == 0:
      scored += _pair(
        config, (r, mate), material, (ll, like(saved_gp(mate))), grid, points,
        rng, n, alone,
      )  # fmt: skip
    for mode, entry in scored:
      out[mode].append(entry)
  return out


class _Alone(NamedTuple):
  """A recording's single-recording modes (``_alone``): per mode, its reading,
  its log prior on the posterior grid and the prior's draws (physical, with
  the load ratio)."""

  measured: dict
  priors: dict
  prior_draws: dict


def _alone(config: Config, r: dict, material: str, ll, grid, points, rng,
           n: int) -> tuple[_Alone, list]:  # fmt: skip
  """Recording ``r``'s scores by the video alone and with a simulated reading
  of its wind or area weight (``rng`` draws the priors', then each mode's
  posterior's draws). Returns its readings and priors, and (mode, score)s."""
  space = physsim.search_space(material)
  t = r['truth']
  row = _truth_row(t)
  sd = config.measured_sd
  measured = {
    'video': measurements.Measured(),
    'known wind': measurements.simulated_reading(
      'wind_speed', t, sd, config.seed, r['seq']
    ),
    'known area weight': measurements.simulated_reading(
      'area_weight', t, sd, config.seed, r['seq']
    ),
  }
  priors = {m: measurements.log_prior(points, space, v) for m, v in measured.items()}
  prior_draws = {
    mode: physical_with_ratio(_draws(rng, grid, lp, n // 4), space)
    for mode, lp in priors.items()
  }
  scored = []
  for mode, lp in priors.items():
    post = bo.posterior.log_normalise(lp + ll)
    draws = physical_with_ratio(_draws(rng, grid, np.asarray(post), n), space)
    point = _prior_point(material, measured[mode])
    score = _score(draws, prior_draws[mode], row, r['seq'], point, prior_draws['video'])
    scored.append(
      (mode, {'seq': r['seq'], 'material': material, 'truth': row, **score})
    )
  return _Alone(measured, priors, prior_draws), scored


def _with_length(config: Config, r: dict, material: str, ll, grid, n: int,
                 sharpness: float, box_draws) -> list:  # fmt: skip
  """Recording ``r``'s (mode, score)s in ``LENGTH_MODES`` (a bending length
  read, alone or with the wind), each posterior's draws placed within their
  cells; ``box_draws``: the search box prior's draws."""
  space = physsim.search_space(material)
  t = r['truth']
  row = _truth_row(t)
  rng_length = np.random.default_rng([config.seed, 19, r['seq'], int(sharpness * 1000)])
  length_priors = _length_priors(
    config, material, r['seq'], tuple(sorted(t.items())), n // 4
  )
  scored = []
  for mode, (m, lp, prior_phys) in length_priors.items():
    post = np.asarray(bo.posterior.log_normalise(lp + ll))
    unit = posterior_lib.refine_draws(
      _draws(rng_length, grid, post, n), grid, space, m, seed=r['seq']
    )
    score = _score(
      physical_with_ratio(unit, space), prior_phys, row, r['seq'],
      _prior_point(material, m), box_draws,
    )  # fmt: skip
    scored.append(
      (mode, {'seq': r['seq'], 'material': material, 'truth': row, **score})
    )
  return scored


def _pair(config: Config, pair: tuple, material: str, lls: tuple, grid, points,
          rng, n: int, alone: _Alone) -> list:  # fmt: skip
  """A pair's (mode, score)s by its joint posterior: by the video alone, and
  with an anemometer reading at each recording (``alone``: the first's
  readings and priors)."""
  space = physsim.search_space(material)
  r, mate = pair
  box_draws = alone.prior_draws['video']
  j = posterior_lib.joint(
    list(lls), grid, alone.priors['video'],
    jax.random.key(int(rng.integers(1 << 30))), n=n,
  )  # fmt: skip
  scored = []
  for k, (rr, samples) in enumerate(zip(pair, j['samples'], strict=True)):
    trow = _truth_row(rr['truth'])
    draws = physical_with_ratio(samples, space)
    point = _prior_point(material, alone.measured['video'])
    score = _score(draws, box_draws, trow, rr['seq'], point, box_draws)
    scored.append(('joint pair', {'seq': rr['seq'], 'material': material,
                                  'pair_member': k, 'truth': trow, **score}))  # fmt: skip
  # The same pair with an anemometer reading at each recording.
  readings = [alone.measured['known wind']] + [
    measurements.simulated_reading(
      'wind_speed', mate['truth'], config.measured_sd, config.seed, mate['seq']
    )
  ]  # fmt: skip
  lps = [
    alone.priors['known wind'],
    measurements.log_prior(points, space, readings[1]),
  ]
  jw = posterior_lib.joint(
    list(lls), grid, lps, jax.random.key(int(rng.integers(1 << 30))), n=n
  )
  for k, (rr, samples) in enumerate(zip(pair, jw['samples'], strict=True)):
    own_prior = physical_with_ratio(_draws(rng, grid, lps[k], n // 4), space)
    score = _score(
      physical_with_ratio(samples, space), own_prior, _truth_row(rr['truth']),
      rr['seq'], _prior_point(material, readings[k]), box_draws,
    )  # fmt: skip
    scored.append(
      (
        'joint pair, known winds',
        {
          'seq': rr['seq'],
          'material': material,
          'pair_member': k,
          'truth': _truth_row(rr['truth']),
          **score,
        },
      )
    )
  return scored


@functools.lru_cache(maxsize=1024)  # about 0.3 MB a recording
def _length_priors(config: Config, material: str, seq: int, truth: tuple,
                   n: int) -> dict:  # fmt: skip
  """For ``LENGTH_MODES``, recording ``seq``'s simulated readings (the
  overhang's bending length to ``length_sd_of`` with its law
  ``length_dof``, a ruler's to the same error (Gaussian), the anemometer's
  wind to
  ``measured_sd``, as the other modes draw it), their log priors on the
  posterior grid (the length's averaged over each cell, as an estimate forms
  it) and ``n`` of the prior's draws placed within their cells
  (``posterior.refine_draws``): ``{mode: (measured, log_prior, draws)}``,
  made once per recording whatever the likelihood setting (``truth``: its
  items, sorted)."""
  truth = dict(truth)
  space = physsim.search_space(material)
  grid = tuple(config.estimate.search.posterior_grid)
  points = bo.posterior.grid_points(grid)
  length = measurements.simulated_reading(
    'bending_length',
    truth,
    length_sd_of(config, seq),
    config.seed,
    seq,
    space,
    dof=config.length_dof,
  )
  wind = measurements.simulated_reading(
    'wind_speed', truth, config.measured_sd, config.seed, seq
  )
  # a ruler's reading: the same error, Gaussian (the same normal draw as
  # length_dof 0 would give)
  ruler = measurements.simulated_reading(
    'bending_length', truth, length_sd_of(config, seq), config.seed, seq, space
  )
  with_wind = lambda m: dataclasses.replace(
    m, wind_speed=wind.wind_speed, wind_speed_sd=wind.wind_speed_sd
  )
  readings = {
    'bending length': length,
    'known wind, bending length': with_wind(length),
    'bending length (ruler)': ruler,
    'known wind, bending length (ruler)': with_wind(ruler),
  }
  rng = np.random.default_rng([config.seed, 23, seq])
  out = {}
  for mode, m in readings.items():
    lp = measurements.log_prior(points, space, m, grid)
    unit = posterior_lib.refine_draws(
      _draws(rng, grid, lp, n), grid, space, m, seed=seq + 1
    )
    out[mode] = (m, lp, physical_with_ratio(unit, space))
  return out
