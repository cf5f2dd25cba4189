"""Credible levels recalibrated on simulations, so intervals hold the truth as often as they say.

An approximate posterior (``bo.posterior``: a GP of a noisy discrepancy and a
tempered likelihood) has roughly the right shape but not the right scale in
every direction: one constant cannot make every parameter's 50% and 90%
intervals hold the truth 50% and 90% of the time. Simulation-based calibration
measures how it errs. For each held-out simulated recording with known
parameters, the truth's rank ``r`` is the share of posterior draws below it
(Talts et al. 2018); a calibrated posterior has uniform ranks.

Recalibration (Kuleshov et al. 2018, with split-conformal order statistics for
a finite-sample guarantee): to report the central interval of level ``a``, ask
the posterior for its quantiles at the CDF levels ``lo`` and ``hi`` where the
calibration ranks put ``(1 - a) / 2`` of the truths below and above:

  lo = r_(floor((n + 1) (1 - a) / 2)),  hi = r_(ceil((n + 1) (1 + a) / 2))

with ``r_(k)`` the k-th smallest of the ``n`` calibration ranks (``r_(0) = 0``,
``r_(n+1) = 1``). If the calibration and the new problem are exchangeable
(the same prior and simulator), the truth falls below ``lo`` with probability
at most ``(1 - a) / 2`` and above ``hi`` likewise, so the interval holds it at
least ``a`` of the time, and at most about ``a + 2 / (n + 1)``. A posterior that
is too narrow gets wider levels, one that is too wide narrower ones, and one
that is shifted gets shifted levels; the median's level (``r`` median) moves
the point estimate the same way.

A quantity the data do not inform keeps the nominal levels (``levels``'
``width_ratios``): where a posterior's intervals are as wide as the prior's,
the posterior is the prior, and a truth drawn from the prior has an exactly
uniform rank under it, so its intervals already hold the truth as often as
they say; any correction a finite calibration set suggests is that set's own
noise. (The shipped study's 100 area-weight truths happened to put 93% in the
central 90% of their range; the levels fitted to them narrowed area weight's
90% intervals to 86% of its posterior, which on later sets of truths held
80-83%.)

A posterior so narrow that the truth lies outside every draw (rank exactly 0
or 1) cannot be widened by any level. So ranks and intervals are read from
a defensive mixture (``defensive``): the posterior's draws with a share
``DEFENSIVE`` of the prior's, so the far tails are the prior's and an
overconfident posterior can be recalibrated into them. Where the posterior
is honest the mixture moves its quantiles by about that share only. The
calibration and every estimate must read the same mixture. Nothing here
depends on JAX: a few hundred ranks and quantiles, on the host.
"""

from __future__ import annotations

import math

import numpy as np

# The CDF levels a table stores: the point (0.5) and the bounds of the 50% and
# 90% central intervals.
PROBS = (0.05, 0.25, 0.5, 0.75, 0.95)
# Share of prior draws in the defensive mixture.
DEFENSIVE = 0.02
# A quantity whose posterior 90% intervals keep at least this share of the
# prior's width (median over the calibration) is one the data do not inform.
UNINFORMED = 0.9


def defensive(
  draws, prior_draws, share: float = DEFENSIVE, seed: int = 0
) -> np.ndarray:
  """Posterior draws with ``share`` of the sample replaced by prior draws:
  a sample of ``(1 - share) posterior + share prior``.

  Args:
    draws: (S, k) posterior draws.
    prior_draws: (S', k) prior draws (the same quantities and information,
      e.g. a measured wind, as the posterior's prior).
    share: the prior's share, in ``[0, 1)``.
    seed: which prior draws are taken.

  Returns:
    (S + m, k) with ``m = round(S share / (1 - share))`` prior rows.
  """
  draws = np.asarray(draws, np.float64)
  prior_draws = np.asarray(prior_draws, np.float64)
  if not 0.0 <= share < 1.0:
    raise ValueError(f'share must be in [0, 1), got {share}')
  if prior_draws.ndim != 2 or prior_draws.shape[1:] != draws.shape[1:]:
    raise ValueError(
      f'prior draws {prior_draws.shape} do not match draws {draws.shape}'
    )
  m = round(draws.shape[0] * share / (1.0 - share))
  idx = np.random.default_rng(seed).integers(0, prior_draws.shape[0], m)
  return np.concatenate([draws, prior_draws[idx]])


def ranks(draws, truth) -> np.ndarray:
  """The truth's rank among posterior draws, per column: the share of draws
  below it (ties count half), in ``[0, 1]``.

  Args:
    draws: (S, k) posterior draws.
    truth: (k,) the true values.

  Returns:
    (k,) ranks.
  """
  draws = np.asarray(draws, np.float64)
  truth = np.asarray(truth, np.float64)
  if draws.ndim != 2 or truth.shape != draws.shape[1:]:
    raise ValueError(
      f'need draws (S, k) and truth (k,), got {draws.shape}, {truth.shape}'
    )
  below = np.mean(draws < truth, axis=0)
  ties = np.mean(draws == truth, axis=0)
  return below + 0.5 * ties


def levels(
  calibration_ranks,
  probs=PROBS,
  width_ratios=None,
  uninformed: float = UNINFORMED,
  centred: bool = False,
) -> np.ndarray:
  """The posterior CDF levels that hold ``probs`` of the calibration truths
  below them, per column (the order statistics of the module doc); with
  ``centred``, levels symmetric about the posterior's median that hold the
  central share ``|2 p - 1|`` of the truths (``centred_levels``).

  Args:
    calibration_ranks: (n, k) ranks of ``n`` calibration problems' truths,
      ``k`` quantities.
    probs: the wanted shares; below 0.5 a lower bound (rounded down, so
      intervals err wide), above 0.5 an upper bound (rounded up), 0.5 the
      median of the ranks.
    width_ratios: optional (n, k) width of each problem's central 90%
      posterior interval over the prior's (``width_ratio``): a column whose
      median reaches ``uninformed`` keeps the nominal levels ``probs``.
    uninformed: that threshold.
    centred: width only: the posterior's median stays the point, whatever
      shift the calibration's ranks show.

  Returns:
    (len(probs), k) CDF levels in ``[0, 1]``.
  """
  r = _checked_ranks(calibration_ranks, probs)
  out = centred_levels(r, probs) if centred else _one_sided_levels(r, probs)
  if width_ratios is not None:
    w = np.asarray(width_ratios, np.float64)
    if w.shape != r.shape:
      raise ValueError(f'width ratios {w.shape} do not match the ranks {r.shape}')
    keep = np.median(w, axis=0) >= uninformed
    out[:, keep] = np.asarray(probs, np.float64)[:, None]
  return out


def _checked_ranks(calibration_ranks, probs) -> np.ndarray:
  """The ranks (n, k), sorted per column, after checking them and ``probs``."""
  r = np.sort(np.asarray(calibration_ranks, np.float64), axis=0)
  if r.ndim != 2 or r.shape[0] < 1 or not np.all(np.isfinite(r)):
    raise ValueError(f'need finite (n, k) ranks with n >= 1, got {r.shape}')
  if np.any((r < 0) | (r > 1)):
    raise ValueError('ranks must lie in [0, 1]')
  if any(not 0.0 < p < 1.0 for p in probs):
    raise ValueError(f'probs must lie in (0, 1), got {tuple(probs)}')
  return r


def _one_sided_levels(r: np.ndarray, probs) -> np.ndarray:
  """``levels``' order statistics of the sorted ranks ``r`` (n, k)."""
  n = r.shape[0]
  padded = np.concatenate([np.zeros((1, r.shape[1])), r, np.ones((1, r.shape[1]))])
  out = []
  for p in probs:
    if p == 0.5:
      out.append(np.median(r, axis=0))
      continue
    k = math.floor((n + 1) * p) if p < 0.5 else math.ceil((n + 1) * p)
    out.append(padded[min(max(k, 0), n + 1)])
  return np.stack(out)


def centred_levels(calibration_ranks, probs=PROBS) -> np.ndarray:
  """CDF levels ``0.5 -+ d`` about the posterior's median, ``d`` the order
  statistic of the truths' distances from it ``|r - 0.5|`` that holds the
  central share ``a = |2 p - 1|`` (``k = ceil((n + 1) a)``, rounded up so
  intervals err wide): split-conformal on the distance, so the central
  interval of level ``a`` holds the truth at least ``a`` of the time when the
  calibration and the problem are exchangeable, as ``levels``' do, but the
  median is never moved. Tables fitted on one kind of mismatch (another
  physics, ``experiments.calibrate --physics``) learn its bias as a shift of
  the levels; the width is what carries to a mismatch of unknown direction.

  Args:
    calibration_ranks: (n, k) ranks in ``[0, 1]``.
    probs: shares as ``levels``'.

  Returns:
    (len(probs), k) CDF levels, symmetric about 0.5.
  """
  d = np.sort(np.abs(_checked_ranks(calibration_ranks, probs) - 0.5), axis=0)
  n = d.shape[0]
  padded = np.concatenate([d, np.full((1, d.shape[1]), 0.5)])
  out = []
  for p in probs:
    k = math.ceil((n + 1) * abs(2.0 * p - 1.0))
    half = padded[min(k, n + 1) - 1] if k > 0 else np.zeros(d.shape[1])
    out.append(0.5 + np.sign(p - 0.5) * half)
  return np.stack(out)


def width_ratio(draws, prior_draws, log=None) -> np.ndarray:
  """Per column, the width of the draws' central 90% interval over the
  prior draws' (on a log scale for the columns ``log`` marks): about 1 where
  the data told the posterior nothing, towards 0 where they pin it down.

  Args:
    draws: (S, k) posterior draws.
    prior_draws: (S', k) prior draws.
    log: optional (k,) bools, columns compared as logarithms (positive).
  """
  x, p = np.asarray(draws, np.float64), np.asarray(prior_draws, np.float64)
  if x.ndim != 2 or p.ndim != 2 or x.shape[1] != p.shape[1]:
    raise ValueError(
      f"need draws (S, k) and prior draws (S', k), got {x.shape}, {p.shape}"
    )
  if log is not None:
    cols = np.asarray(log, bool)
    x, p = x.copy(), p.copy()
    x[:, cols], p[:, cols] = np.log(x[:, cols]), np.log(p[:, cols])
  width = lambda a: np.diff(np.quantile(a, [0.05, 0.95], axis=0), axis=0)[0]
  return width(x) / np.maximum(width(p), 1e-300)


def linear_quantiles(draws, q) -> np.ndarray:
  """``np.quantile(draws, q, axis=0)`` (its default linear method), the same
  numbers, from one sort: NumPy selects each level's neighbours by
  partitioning, which for many levels (the calibration reads 1001 per set of
  draws) costs far more than sorting once.

  Args:
    draws: (S,) or (S, k) values.
    q: (m,) levels in [0, 1].

  Returns:
    (m,) or (m, k) quantiles.
  """
  s = np.sort(np.asarray(draws, np.float64), axis=0)
  n = s.shape[0]
  v = (n - 1) * np.asarray(q, np.float64)  # NumPy's virtual index
  lo = np.floor(v)
  lo[v >= n - 1] = n - 1
  lo = lo.astype(np.intp)
  hi = np.minimum(lo + 1, n - 1)
  g = (v - lo).reshape(v.shape + (1,) * (s.ndim - 1))
  a, b = s[lo], s[hi]
  d = b - a
  out = a + d * g
  np.subtract(b, d * (1 - g), out=out, where=g >= 0.5)  # as NumPy's lerp
  return out


def quantiles(draws, cdf_levels) -> np.ndarray:
  """Per column, the draws' quantiles at that column's CDF levels.

  Args:
    draws: (S, k) posterior draws.
    cdf_levels: (m, k) levels (``levels``' output), or (m,) for every column.

  Returns:
    (m, k) quantiles.
  """
  draws = np.asarray(draws, np.float64)
  lv = np.asarray(cdf_levels, np.float64)
  if lv.ndim == 1:
    lv = np.repeat(lv[:, None], draws.shape[1], axis=1)
  if lv.shape[1] != draws.shape[1]:
    raise ValueError(f'levels for {lv.shape[1]} columns, draws have {draws.shape[1]}')
  return np.stack(
    [
      linear_quantiles(draws[:, j], np.clip(lv[:, j], 0.0, 1.0))
      for j in range(lv.shape[1])
    ],
    axis=1,
  )


def nominal_levels(probs=PROBS) -> np.ndarray:
  """(len(probs),) the levels of an uncalibrated posterior: the probs themselves."""
  return np.asarray(probs, np.float64)


def warp(u, cdf_levels, probs=PROBS) -> np.ndarray:
  """The posterior CDF levels at which to read shares ``u`` of the calibrated
  distribution: the recalibration map through (0, 0), ``(probs, cdf_levels)``
  and (1, 1), linear between (monotone, as ``levels`` is)."""
  return np.interp(u, [0.0, *probs, 1.0], [0.0, *np.asarray(cdf_levels), 1.0])


def unwarp(rank, cdf_levels, probs=PROBS) -> np.ndarray:
  """The inverse of ``warp``: a truth's rank under the recalibrated
  distribution, from its rank ``rank`` among the posterior's draws. Uniform
  over recordings when the recalibration holds (the check of a calibration
  on recordings it never saw)."""
  return np.interp(rank, [0.0, *np.asarray(cdf_levels), 1.0], [0.0, *probs, 1.0])


LOSSES = ('relative', 'factor', 'log')


def bayes_point(samples, loss: str, n_candidates: int = 199, weights=None) -> float:
  """The value with the least expected error over ``samples`` (the Bayes
  action for that error): ``'relative'`` |c - x| / x (a percent error),
  ``'factor'`` exp|log c - log x| (a factor error, for positive scales) or
  ``'log'`` |log c - log x| (whose action is the median: it follows the
  posterior's centre, where the percent error's leans to its low tail).

  If the samples are a calibrated posterior, no fixed guess (such as the
  centre of the search box) has a lower expected error over problems drawn
  from the prior: where the data say little, this stays near the guess that
  minimises the prior's own expected error, where a plain median scatters.

  Args:
    samples: (S,) posterior draws (or quadrature nodes), all positive.
    loss: one of ``LOSSES``.
    n_candidates: candidates tried, the samples' quantiles.
    weights: (S,) non-negative weights of the samples (default equal).
  """
  x = np.asarray(samples, np.float64)
  if loss not in LOSSES:
    raise ValueError(f'loss must be one of {LOSSES}, got {loss!r}')
  if x.ndim != 1 or not x.size or np.any(x <= 0):
    raise ValueError('need a non-empty 1-D array of positive samples')
  w = np.ones_like(x) if weights is None else np.asarray(weights, np.float64)
  if w.shape != x.shape or np.any(w < 0) or not w.sum() > 0:
    raise ValueError('weights must be non-negative, one per sample, not all zero')
  order = np.argsort(x)
  xs, ws = x[order], w[order]
  cw = np.cumsum(ws) / ws.sum()
  probs = (np.arange(n_candidates) + 0.5) / n_candidates
  c = xs[np.minimum(np.searchsorted(cw, probs), x.size - 1)]
  # Each candidate's expected error from prefix sums over the sorted samples
  # (O(S) instead of a candidates x samples matrix): with k samples at or
  # below c, 'relative' sums w |c - x| / x = c (lo(w/x) - hi(w/x)) - (lo(w) -
  # hi(w)); 'factor' sums w exp|log c - log x| = c lo(w/x) + hi(w x) / c;
  # 'log' sums w |log c - log x| = log c (lo(w) - hi(w)) - (lo(w log x) -
  # hi(w log x)).
  k = np.searchsorted(xs, c, side='right')

  def below(v):  # sums of v over the first k sorted samples, and the rest
    cum = np.concatenate([[0.0], np.cumsum(v)])
    return cum[k], cum[-1] - cum[k]

  if loss == 'log':
    w_lo, w_hi = below(ws)
    wl_lo, wl_hi = below(ws * np.log(xs))
    cost = np.log(c) * (w_lo - w_hi) - (wl_lo - wl_hi)
    return float(c[np.argmin(cost)])
  w_over_x_lo, w_over_x_hi = below(ws / xs)
  if loss == 'relative':
    w_lo, w_hi = below(ws)
    cost = c * (w_over_x_lo - w_over_x_hi) - (w_lo - w_hi)
  else:
    _, wx_hi = below(ws * xs)
    cost = c * w_over_x_lo + wx_hi / c
  return float(c[np.argmin(cost)])


def error(estimate, truth, loss: str) -> np.ndarray:
  """Percent error |e - t| / t x 100 (``'relative'``), the factor
  exp|log(e / t)| (``'factor'``) or |log(e / t)| (``'log'``), elementwise."""
  e, t = np.asarray(estimate, np.float64), np.asarray(truth, np.float64)
  if loss == 'relative':
    return 100.0 * np.abs(e - t) / t
  if loss == 'factor':
    return np.exp(np.abs(np.log(e / t)))
  if loss == 'log':
    return np.abs(np.log(e / t))
  raise ValueError(f'loss must be one of {LOSSES}, got {loss!r}')


# Candidate weights of a posterior's point against the prior's own.
WEIGHTS = tuple(np.round(np.linspace(0.0, 1.0, 11), 2))


def shrink(point, prior_point, weight: float, loss: str):
  """The prior's point moved towards the posterior's by ``weight`` (0: the
  prior's, 1: the posterior's), on a log scale for ``'factor'`` and ``'log'``
  errors."""
  point, prior_point = (
    np.asarray(point, np.float64),
    np.asarray(prior_point, np.float64),
  )
  if loss in ('factor', 'log'):
    return prior_point * (point / prior_point) ** weight
  return prior_point + weight * (point - prior_point)


def choose_weight(points, prior_points, truths, loss: str, weights=WEIGHTS) -> float:
  """The weight (``shrink``) of a posterior's point against the prior's own,
  from calibration problems: the smallest weight whose mean error is within
  one standard error of the best weight's (Breiman's one-standard-error rule),
  so the prior's point is kept unless the posterior's clearly does better.

  Where the data carry information the posterior's point wins (weight 1);
  where they carry none, its scatter only adds error and the prior's own
  point wins (weight 0): so the point is not worse than the prior's on
  problems like these.
  """
  err = np.stack([error(shrink(points, prior_points, w, loss), truths, loss)
                  for w in weights])  # fmt: skip  # (n_weights, n)
  mean = err.mean(axis=1)
  best = int(np.argmin(mean))
  n = err.shape[1]
  se = np.std(err - err[best], axis=1, ddof=1) / np.sqrt(n) if n > 1 else 0.0 * mean
  ok = mean - mean[best] <= se  # the best itself: 0 <= 0
  return float(np.asarray(weights)[np.flatnonzero(ok)[0]])


def interval_score(lo, hi, truth, level: float) -> np.ndarray:
  """Gneiting & Raftery's (2007) interval score of central intervals (lower is
  better): the width plus ``2 / (1 - level)`` times how far the truth lies
  outside. It rewards narrow intervals only while they keep their coverage."""
  lo, hi, truth = (np.asarray(a, np.float64) for a in (lo, hi, truth))
  alpha = 1.0 - level
  return (
    (hi - lo)
    + (2.0 / alpha) * np.maximum(lo - truth, 0.0)
    + (2.0 / alpha) * np.maximum(truth - hi, 0.0)
  )


def binomial_interval(k, n, z: float = 1.96) -> tuple[float, float]:
  """Wilson's score interval for a proportion ``k / n`` (default 95%): the
  range of true coverages consistent with ``k`` of ``n`` intervals holding
  the truth. Unlike ``k / n +- z sd`` it stays inside [0, 1] and keeps its
  level near 0 and 1, where coverages of 90% intervals on a few dozen
  recordings lie.

  Raises:
    ValueError: ``n < 1`` or ``k`` outside ``[0, n]``.
  """
  if n < 1 or not 0 <= k <= n:
    raise ValueError(f'need 0 <= k <= n and n >= 1, got k={k}, n={n}')
  p = k / n
  d = 1.0 + z * z / n
  centre = (p + z * z / (2 * n)) / d
  half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
  return max(0.0, centre - half), min(1.0, centre + half)
