"""The calibration study's analysis: per likelihood, the sharpness and the
recalibration tables an estimate ships with (chosen on every recording), and
the coverage, errors and interval scores that procedure has on recordings it
never saw (cross-fitted by pairs)."""

from __future__ import annotations

import functools
import math

import numpy as np

import bo
import physsim
from experiments.pipeline import posterior as posterior_lib
from experiments.studies.calibration_config import (
  FIELDS,
  LEVELS,
  MODES,
  Config,
  camera_sd_of,
  fold_of,
  study_configs,
  study_materials,
)
from experiments.studies.calibration_scores import LOG_FIELDS, QGRID, posteriors

# The error each point is judged by, and the loss a posterior's own point
# minimises: the estimate's (``posterior.ERROR_LOSS``, ``POINT_LOSS``).
_LOSS = posterior_lib.ERROR_LOSS
_POINT_LOSS = posterior_lib.POINT_LOSS
# A wind estimate this far off (percent) whose 90% interval misses the truth is
# confidently wrong: issue 40's target is none on held-out recordings. The
# tables count such points for every quantity (bending: a factor of 1.25).
CONFIDENT_MISS_PCT = 25.0
_CONFIDENT = {'relative': (1 / (1 + CONFIDENT_MISS_PCT / 100), 1 / (1 - CONFIDENT_MISS_PCT / 100)),
              'factor': (1 / 1.25, 1.25)}  # fmt: skip


def confident_misses(scores, levels, i: int, point, lo, hi, loss: str):
  """Field ``i``'s confident misses: how many truths lie outside their 90%
  interval ``[lo, hi]`` with the point that far off (``_CONFIDENT``: the truth
  below ``point * a`` or above ``point * b``), and how many the recalibrated
  posteriors themselves expect (each one's mass there, summed). Calibrated
  posteriors expect some: a count of none is not a calibrated tool's target."""
  a, b = _CONFIDENT[loss]
  t = np.stack([s['truth'][i] for s in scores])
  below, above = np.minimum(lo, point * a), np.maximum(hi, point * b)
  seen = int(np.sum((t < below) | (t > above)))
  expected = 0.0
  for k, s in enumerate(scores):  # the recalibrated CDF at both cuts
    raw = np.interp([below[k], above[k]], s['qf'][:, i], QGRID)
    at_lo, at_hi = bo.calibration.unwarp(raw, levels[k])
    expected += float(at_lo + 1.0 - at_hi)
  return seen, expected


def _at(qf: np.ndarray, cdf_levels: np.ndarray) -> np.ndarray:
  """Values of quantile functions ``qf (len(QGRID), k)`` at per-field CDF
  levels ``(m, k)``: (m, k)."""
  return np.stack(
    [np.interp(cdf_levels[:, j], QGRID, qf[:, j]) for j in range(qf.shape[1])], axis=1
  )


def _scale(space: physsim.SearchSpace) -> dict:
  """Per field, the prior's extent on its comparison scale (log for bending
  and the load ratio): interval scores are in units of it."""
  (b0, b1), (v0, v1), (w0, w1) = space.bounds()
  r_lo = physsim.load_ratio(v0, w1)
  r_hi = physsim.load_ratio(v1, w0)
  return {
    'bending_scale': np.log(b1 / b0), 'wind_speed': v1 - v0, 'area_weight': w1 - w0,
    'load_ratio': float(np.log(r_hi / r_lo)),
  }  # fmt: skip


def _box(space: physsim.SearchSpace) -> tuple[np.ndarray, np.ndarray]:
  """(centre, scale) of a search box in ``FIELDS`` order: the range centre
  (the load ratio at the centre's wind and area weight) and ``_scale``."""
  c = space.center()
  scale = _scale(space)
  centre = [*map(float, c), float(physsim.load_ratio(c.wind_speed, c.area_weight))]
  return np.array(centre), np.array([scale[f] for f in FIELDS])


@functools.lru_cache(maxsize=64)
def _fabric_box(material: str) -> tuple[np.ndarray, np.ndarray]:
  return _box(physsim.search_space(material))


def recalibration(scores: list[dict], centred: bool = False) -> np.ndarray:
  """(len(PROBS), fields) CDF levels from these recordings' ranks
  (``bo.calibration.levels``; ``centred``: about the median, widths only); a
  field the video does not inform (its intervals as wide as the prior's)
  keeps the nominal levels."""
  widths = [s.get('width_ratio') for s in scores]
  return bo.calibration.levels(
    np.stack([s['rank'] for s in scores]),
    width_ratios=None if any(w is None for w in widths) else np.stack(widths),
    centred=centred,
  )


def summarise(
  scores: list[dict], space: physsim.SearchSpace, cdf_levels=None, bayes: bool = True
) -> dict:
  """Coverage, rank uniformity, point errors and interval scores over
  recordings, per field, with intervals and point read at ``cdf_levels``
  (``(len(PROBS), fields)``; a score's own ``'levels'`` wins; default the
  nominal levels: uncalibrated). With ``bayes``, also the error of the point
  that minimises each posterior's expected error (``bo.calibration.bayes_point``
  on the recalibrated distribution)."""
  if not scores:
    return {}
  probs = bo.calibration.PROBS
  nominal = np.repeat(bo.calibration.nominal_levels()[:, None], len(FIELDS), axis=1)
  default = nominal if cdf_levels is None else np.asarray(cdf_levels)
  truth = np.stack([s['truth'] for s in scores])
  vals = np.stack([_at(s['qf'], s.get('levels', default)) for s in scores])
  median = vals[:, probs.index(0.5)]  # (n, fields)
  # each recording against its own fabric's box (``space``: the fabric of a
  # score that names none)
  own = _box(space) if space is not None else None
  boxes = [_fabric_box(s['material']) if s.get('material') else own for s in scores]
  centre = np.stack([b[0] for b in boxes])  # (n, fields)
  scale = np.stack([b[1] for b in boxes])
  out = {'n': len(scores)}
  for i, f in enumerate(FIELDS):
    t = truth[:, i]
    cell = _intervals(scores, vals[:, :, i], t, scale[:, i], i, f)
    cell.update(_errors(median[:, i], centre[:, i], t, f))
    if bayes:
      levels = [s.get('levels', default)[:, i] for s in scores]
      cell.update(_point_errors(scores, vals[:, :, i], levels, t, i, f))
    out[f] = cell
  return out


def _intervals(scores: list[dict], vals, t, scale, i: int, f: str) -> dict:
  """Field ``i`` (``f``)'s interval coverage and scores (``vals``: (n,
  len(PROBS)) its quantiles per recording, ``scale``: (n,) its prior
  extent), the prior's own intervals' coverage, the 50% interval's median
  half-width over its median, the width over the prior's and the ranks'
  histogram and chi^2."""
  probs = bo.calibration.PROBS
  cell = {}
  tr = np.log if f in LOG_FIELDS else (lambda a: a)
  for lvl in LEVELS:
    a = lvl / 100
    lo = vals[:, probs.index(round((1 - a) / 2, 2))]
    hi = vals[:, probs.index(round((1 + a) / 2, 2))]
    cell[f'interval_{lvl}'] = float(np.mean((lo <= t) & (t <= hi)))
    cell[f'interval_score_{lvl}'] = float(
      np.mean(bo.calibration.interval_score(tr(lo), tr(hi), tr(t), a) / scale)
    )
  if all('prior_rank' in s for s in scores):
    pr = np.array([s['prior_rank'][i] for s in scores])
    for lvl in LEVELS:
      a = lvl / 100
      cell[f'prior_interval_{lvl}'] = float(
        np.mean((pr >= (1 - a) / 2) & (pr <= (1 + a) / 2))
      )
  # How wide the 50% interval is beside its point, to set a user path's
  # estimates beside the tables' recordings at the same error
  # (``benchmarks.windy_rig --pool``): half its width over the median, or for
  # a log-scaled field half its log width (the factor's log).
  lo50, hi50 = vals[:, probs.index(0.25)], vals[:, probs.index(0.75)]
  if f in LOG_FIELDS:
    half = (np.log(hi50) - np.log(lo50)) / 2
  else:
    half = (hi50 - lo50) / (2 * np.maximum(np.abs(vals[:, probs.index(0.5)]), 1e-300))
  cell['half_width_50'] = float(np.median(half))
  if all('width_ratio' in s for s in scores):  # ~1: the prior's own width
    cell['width_ratio'] = float(np.median([s['width_ratio'][i] for s in scores]))
  rank = np.array([s['rank'][i] for s in scores])
  hist = np.histogram(rank, bins=10, range=(0, 1))[0]
  expected = len(scores) / 10
  cell['rank_histogram'] = hist.tolist()
  cell['rank_chi2'] = float(np.sum((hist - expected) ** 2 / expected))  # 9 dof
  return cell


def _errors(median, centre, t, f: str) -> dict:
  """The mean error of the median and of the range centre: bending a factor
  (>= 1), the rest percent."""
  if f == 'bending_scale':
    return {
      'median_error_factor': float(np.mean(np.exp(np.abs(np.log(median / t))))),
      'centre_error_factor': float(np.mean(np.exp(np.abs(np.log(centre / t))))),
    }
  return {
    'median_error_pct': float(np.mean(100 * np.abs(median - t) / t)),
    'centre_error_pct': float(np.mean(100 * np.abs(centre - t) / t)),
  }


def _point_errors(scores: list[dict], vals, levels: list, t, i: int,
                  f: str) -> dict:  # fmt: skip
  """The errors of field ``i``'s least-error point, of that point moved
  towards the prior's by the weight and of the prior's own, and the
  confident misses (``levels``: each recording's CDF levels of the field)."""
  probs = bo.calibration.PROBS
  loss = _LOSS[f]
  bp = np.array(
    [_bayes(s, lv, i, _POINT_LOSS[f]) for s, lv in zip(scores, levels, strict=True)]
  )
  pp = np.array([s['prior_point'][i] for s in scores])
  w = np.array([s.get('weights', {}).get(f, 1.0) for s in scores])
  pt = bo.calibration.shrink(bp, pp, w, loss)
  key = 'factor' if loss == 'factor' else 'pct'
  lo, hi = (vals[:, probs.index(p)] for p in (0.05, 0.95))
  seen, expected = confident_misses(scores, levels, i, pt, lo, hi, loss)
  return {
    f'bayes_error_{key}': float(np.mean(bo.calibration.error(bp, t, loss))),
    f'point_error_{key}': float(np.mean(bo.calibration.error(pt, t, loss))),
    f'prior_point_error_{key}': float(np.mean(bo.calibration.error(pp, t, loss))),
    'confident_misses': seen,
    'confident_misses_expected': expected,
    'weight': float(np.mean(w)),
  }


_U = (np.arange(400) + 0.5) / 400  # shares of the recalibrated distribution


def _bayes(score: dict, cdf_levels, i: int, loss: str) -> float:
  """The Bayes point of field ``i`` of one recording: its quantile function
  read at the recalibrated levels of evenly spaced shares."""
  u = bo.calibration.warp(_U, cdf_levels)
  return bo.calibration.bayes_point(np.interp(u, QGRID, score['qf'][:, i]), loss)


def weights(scores: list[dict], cdf_levels) -> dict[str, float]:
  """Per field, the weight of the posterior's least-error point against the
  prior's own (``bo.calibration.choose_weight``) over these recordings, their
  posteriors read at ``cdf_levels``."""
  truth = np.stack([s['truth'] for s in scores])
  out = {}
  for i, f in enumerate(FIELDS):
    loss = _LOSS[f]
    bp = np.array(
      [_bayes(s, np.asarray(cdf_levels)[:, i], i, _POINT_LOSS[f]) for s in scores]
    )
    pp = np.array([s['prior_point'][i] for s in scores])
    out[f] = bo.calibration.choose_weight(bp, pp, truth[:, i], loss)
  return out


def _coverages(summary: dict) -> np.ndarray:
  """(levels, fields) interval coverage of a summary."""
  return np.array([[summary[f][f'interval_{lv}'] for f in FIELDS] for lv in LEVELS])


def _mean_interval_score(summary: dict) -> float:
  """The parameters' mean interval score over both levels (lower: narrower
  intervals that still hold the truth)."""
  return float(np.mean([summary[f][f'interval_score_{lv}']
                        for f in posterior_lib.FIELDS for lv in LEVELS]))  # fmt: skip


def _choose(by_c: dict, space, rows, centred: bool = False) -> tuple[float, dict]:
  """The sharpness whose recalibrated intervals (recalibrated on ``rows``
  itself) score best on ``rows``' video posteriors; and each mode's tables
  at that value. ``by_c``: ``{sharpness: {mode: scores}}``."""
  best, best_score, best_recal = None, np.inf, None
  for c, scores in by_c.items():
    mine = {m: [s for s in v if s['seq'] in rows] for m, v in scores.items()}
    if not mine['video']:
      continue
    recal = {m: recalibration(v, centred) for m, v in mine.items() if v}
    score = _mean_interval_score(
      summarise(mine['video'], space, recal['video'], bayes=False)
    )
    if score < best_score:
      best, best_score, best_recal = c, score, recal
  return best, best_recal


def analyse(config: Config, runs: list[dict]) -> dict:
  """Per likelihood: the sharpness and recalibration tables an estimate ships
  with (chosen on every recording), and the coverage that procedure has on
  recordings it never saw (cross-fitted by pairs).

  The sharpness is the value whose recalibrated intervals score best
  (``_mean_interval_score``): after recalibration every candidate's intervals
  hold the truth about as often as they say, so the choice is the most
  informative posterior. The coverage reported is cross-fitted: the pairs
  fall into ``config.folds`` folds; each fold's recordings are read with the
  sharpness and tables chosen on the other folds alone, so every recording is
  held out once and none informs its own intervals (with as many folds as
  networks, each fold is one network's: ``cross_validated_by_fold`` gives the
  video's coverage per fold, so per network). The older rule (the
  sharpest value whose uncalibrated intervals never under-cover,
  ``bo.posterior.choose_sharpness``) is reported beside it."""
  space = physsim.search_space(config.material)
  centred = config.centred_levels
  folds = max(2, min(config.folds, len({r['seq'] // 2 for r in runs})))
  everyone = {r['seq'] for r in runs}
  sweep, best, fold_choice, cross, never_under, by_fold = {}, {}, {}, {}, {}, {}
  by_material, by_camera, by_wind = {}, {}, {}
  levels = [lv / 100 for lv in LEVELS]
  for form in bo.posterior.DISCREPANCY_LIKELIHOODS:
    by_c = {c: posteriors(config, runs, form, c) for c in config.sharpness_grid}
    sweep[form] = {}
    for c, scores in by_c.items():
      recal = {m: recalibration(v, centred) for m, v in scores.items() if v}
      sweep[form][c] = {
        'uncalibrated': {m: summarise(v, space, bayes=False) for m, v in scores.items()},
        'recalibrated_in_sample': {
          m: summarise(v, space, recal[m], bayes=False) if v else {}
          for m, v in scores.items()
        },
        'recalibration': {m: v.tolist() for m, v in recal.items()},
      }  # fmt: skip
    best[form], recal_all = _choose(by_c, space, everyone, centred)
    sweep[form][best[form]]['weights'] = {
      m: weights(by_c[best[form]][m], recal_all[m]) for m in recal_all
    }
    cov = {c: _coverages(v['uncalibrated']['video']) for c, v in sweep[form].items()}
    never_under[form] = bo.posterior.choose_sharpness(cov, levels)
    # Cross-fitted: each fold read with what the other folds chose.
    held = {m: [] for m in MODES}
    fold_choice[form] = []
    for k in range(folds):
      train = {s for s in everyone if fold_of(s, folds) != k}
      c_k, recal_k = _choose(by_c, space, train, centred)
      fold_choice[form].append(c_k)
      for m in MODES:
        if m not in recal_k:
          continue
        train_m = [s for s in by_c[c_k][m] if fold_of(s['seq'], folds) != k]
        w_k = weights(train_m, recal_k[m])
        for s in by_c[c_k][m]:
          if fold_of(s['seq'], folds) == k:
            held[m].append({**s, 'levels': recal_k[m], 'weights': w_k})
    cross[form] = {m: summarise(v, space) for m, v in held.items()}
    by_fold[form] = [
      coverage_of(summarise([s for s in held['video'] if fold_of(s['seq'], folds) == k],
                             space, bayes=False))
      for k in range(folds)
    ]  # fmt: skip
    by_camera[form] = by_camera_error(config, held['video'], space)
    by_wind[form] = by_wind_place(held['video'], space)
    by_material[form] = {
      m: summarise([s for s in held['video'] if s.get('material') == m], space)
      for m in study_materials(config)
    } if len(study_materials(config)) > 1 else {}  # fmt: skip
  return {
    'sweep': sweep, 'best_sharpness': best, 'folds': folds,
    'fold_sharpness': fold_choice, 'cross_validated': cross,
    'cross_validated_by_fold': by_fold,
    'cross_validated_by_material': by_material,
    'cross_validated_by_camera_error': by_camera,
    'cross_validated_by_wind': by_wind,
    'sharpest_never_under_covering': never_under,
  }  # fmt: skip


# Recordings grouped by the camera error they carried: thirds of its range.
CAMERA_BANDS = ('smallest third', 'middle third', 'largest third')


def camera_band(config: Config, seq: int) -> int:
  """Which third of the study's camera error range recording ``seq``'s
  error lies in (0, 1, 2): the mean of its shift's and its tilt's place in
  their log ranges (-1 to 1; ``camera_sd_of``)."""
  est = study_configs(config)[3]
  centre = (est.scoring.camera_sd_m, est.scoring.camera_sd_deg)
  mine = camera_sd_of(config, est, seq)
  place = np.mean([
    math.log(m / c) / config.camera_sd_spread
    for m, c in zip(mine, centre, strict=True) if c
  ])  # fmt: skip
  return min(2, max(0, int((place + 1) / 2 * 3)))


def by_camera_error(config: Config, held: list[dict], space) -> dict:
  """Held-out recordings' coverage by the camera error each carried
  (``camera_band``), where the study drew each its own (``camera_sd_spread``):
  whether the pooled tables hold at both ends of the range; {} otherwise."""
  if not config.camera_sd_spread or config.rig_runs:  # a rig's claims: its own
    return {}
  bands = {}
  for s in held:
    bands.setdefault(camera_band(config, s['seq']), []).append(s)
  return {CAMERA_BANDS[b]: summarise(bands[b], space) for b in sorted(bands)}


# Recordings grouped by where their wind lies in its prior: thirds of the box.
WIND_BANDS = ('lowest third', 'middle third', 'highest third')


def wind_band(score: dict, space: physsim.SearchSpace) -> int:
  """Which third of its fabric's wind range (``space``'s where the score
  names no fabric) recording ``score``'s true wind lies in (0, 1, 2)."""
  lo, hi = (physsim.search_space(score['material']) if score.get('material')
            else space).wind_speed  # fmt: skip
  place = (score['truth'][FIELDS.index('wind_speed')] - lo) / (hi - lo)
  return min(2, max(0, int(place * 3)))


def by_wind_place(held: list[dict], space) -> dict:
  """Held-out recordings' coverage by where their true wind lies in its
  prior (``wind_band``): tables pooled over the prior average their coverage
  over it, and a check whose winds sit in one part of it reads that part's."""
  bands = {}
  for s in held:
    bands.setdefault(wind_band(s, space), []).append(s)
  return {WIND_BANDS[b]: summarise(bands[b], space) for b in sorted(bands)}


def coverage_of(summary: dict) -> dict:
  return {
    f: {f'interval_{lv}': summary[f][f'interval_{lv}'] for lv in LEVELS} for f in FIELDS
  } if summary else {}  # fmt: skip
