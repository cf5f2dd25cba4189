"""Which recording to make next: expected information gain of experimental designs.

A design is a recording one could make (a cloth size, a fan setting). Each is
described by a summary vector ``y`` (what a depth camera sees, reduced to a few
statistics) with Gaussian noise of covariance ``R`` (gusts, sensor) around a
mean ``f(theta)``; its slopes ``J = d f / d theta`` (a differentiable forward
model through ``linearize``, or tabulated, e.g. finite differences of a
simulator) carry what it says about the parameters ``theta`` (here log bending,
log area weight and one log wind per fan setting).

The information gain used is the Laplace (linear-Gaussian) one: with the
current belief ``N(m, S)`` and ``y = f(m) + J (theta - m) + e``, ``e ~ N(0, R)``,
the posterior is Gaussian with covariance ``(S^-1 + F)^-1``, ``F = J^T R^-1 J``
(the Fisher information), and the expected gain about the parameters ``keep``
(the others, e.g. a new recording's own wind, marginalised) is::

  EIG = 0.5 log det S[keep, keep] - 0.5 log det ((S^-1 + F)^-1)[keep, keep]

which for ``keep`` = all is ``0.5 log det(I + S F)``. It is exact for a linear
model with Gaussian noise and prior (tested against a nested Monte Carlo,
``eig_nested_mc``), needs no simulation per draw of the outcome (a simulator
run costs seconds, a nested Monte Carlo thousands of them), and is additive
over independent recordings through ``F``. Where the slopes vary over the
current posterior, ``expected_gain`` averages it over posterior draws (each
with its own ``J``, or the nearest tabulated one). Its limits: a curved or
multimodal posterior is summarised by its covariance, and a noise covariance
estimated from few replicates is itself noisy (``shrink``).

Everything here is NumPy (``eig_nested_mc`` and ``linearize`` use JAX), pure,
and free of the simulator: ``experiments.studies.protocol_slopes`` supplies the
slopes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

# A log-uniform box [lo, hi] as a Gaussian of the same variance in log space.
UNIFORM_SD = 1.0 / np.sqrt(12.0)
Z90 = 1.6448536269514722  # the standard normal's 95% point: a 90% interval is +-Z90 sd


def log_box_sd(lo: float, hi: float) -> float:
  """The standard deviation of log x for x log-uniform on [lo, hi]: the search
  box as a Gaussian prior of the same variance in log space."""
  if not (0 < lo < hi):
    raise ValueError(f'need 0 < lo < hi, got {lo}, {hi}')
  return float(np.log(hi / lo) * UNIFORM_SD)


def shrink(cov: np.ndarray, amount: float = 0.5) -> np.ndarray:
  """``cov`` pulled towards its diagonal by ``amount`` in [0, 1]: a covariance
  estimated from a few replicates, made invertible without trusting its
  off-diagonal terms (Ledoit-Wolf's target, with a fixed weight)."""
  cov = np.asarray(cov, np.float64)
  if not 0 <= amount <= 1:
    raise ValueError(f'shrink amount must be in [0, 1], got {amount}')
  return (1 - amount) * cov + amount * np.diag(np.diag(cov))


def fisher(jacobian, noise_cov) -> np.ndarray:
  """``J^T R^-1 J``: the Fisher information of a Gaussian summary.

  Args:
    jacobian: (..., m, p) slopes of the summary's mean.
    noise_cov: (..., m, m) its noise covariance (positive definite).

  Returns:
    (..., p, p) information.
  """
  j = np.asarray(jacobian, np.float64)
  r = np.asarray(noise_cov, np.float64)
  if j.shape[-2] != r.shape[-1] or r.shape[-1] != r.shape[-2]:
    raise ValueError(f'slopes {j.shape} and noise covariance {r.shape} do not match')
  rj = np.linalg.solve(r, j)
  return np.swapaxes(j, -1, -2) @ rj


def embed(info: np.ndarray, index: Sequence[int], n: int) -> np.ndarray:
  """A design's (p, p) information over its own parameters placed in the (n, n)
  information of the whole set: ``index[i]`` is where its parameter ``i`` goes
  (recordings share bending and area weight, each fan setting has its wind)."""
  info = np.asarray(info, np.float64)
  index = np.asarray(index, int)
  if info.shape != (len(index), len(index)) or index.max(initial=-1) >= n:
    raise ValueError(f'information {info.shape} with index {index.tolist()} in {n}')
  out = np.zeros((n, n))
  out[np.ix_(index, index)] = info
  return out


def combine(infos: Sequence[np.ndarray], indices: Sequence[Sequence[int]], n: int):
  """The (n, n) Fisher information of independent recordings: the sum of each
  one's, placed by ``indices`` (``embed``)."""
  if len(infos) != len(indices):
    raise ValueError(f'{len(infos)} informations but {len(indices)} index lists')
  total = np.zeros((n, n))
  for info, index in zip(infos, indices, strict=True):
    total += embed(info, index, n)
  return total


def posterior_cov(prior_cov, info) -> np.ndarray:
  """``(S^-1 + F)^-1``: the Laplace posterior covariance (the Cramer-Rao bound
  with a Gaussian prior, the van Trees bound where ``F`` is averaged)."""
  s = np.asarray(prior_cov, np.float64)
  f = np.asarray(info, np.float64)
  # (S^-1 + F)^-1 = S (I + F S)^-1: no inverse of S, which may be near-singular
  n = s.shape[-1]
  return s @ np.linalg.inv(np.eye(n) + f @ s)


def widths(prior_sd, info) -> np.ndarray:
  """Posterior standard deviations per parameter from independent Gaussian
  prior standard deviations ``prior_sd`` (n,) and information ``info`` (n, n)."""
  sd = np.asarray(prior_sd, np.float64)
  post = posterior_cov(np.diag(sd**2), info)
  return np.sqrt(np.clip(np.diag(post), 0, None))


def narrowing(prior_sd, info) -> np.ndarray:
  """Per parameter, the prior's 90% width over the posterior's (1: nothing
  learnt). For Gaussians the ratio of standard deviations."""
  return np.asarray(prior_sd, np.float64) / widths(prior_sd, info)


def _logdet(a: np.ndarray) -> float:
  sign, value = np.linalg.slogdet(a)
  if sign <= 0:
    raise ValueError('covariance is not positive definite')
  return float(value)


def eig(prior_cov, info, keep: Sequence[int] | None = None) -> float:
  """Laplace expected information gain, nats, about the parameters ``keep``
  (all if None; the others marginalised) of one recording with information
  ``info`` under the Gaussian belief ``prior_cov``."""
  s = np.asarray(prior_cov, np.float64)
  post = posterior_cov(s, info)
  k = np.arange(len(s)) if keep is None else np.asarray(keep, int)
  return 0.5 * (_logdet(s[np.ix_(k, k)]) - _logdet(post[np.ix_(k, k)]))


def weighted_cov(samples, weights=None) -> tuple[np.ndarray, np.ndarray]:
  """The weighted mean (p,) and covariance (p, p) of (S, p) samples."""
  x = np.asarray(samples, np.float64)
  w = np.ones(len(x)) if weights is None else np.asarray(weights, np.float64)
  if x.ndim != 2 or w.shape != (len(x),) or not np.all(w >= 0) or w.sum() <= 0:
    raise ValueError(f'need (S, p) samples and (S,) non-negative weights, got '
                     f'{x.shape} and {w.shape}')  # fmt: skip
  w = w / w.sum()
  mean = w @ x
  d = x - mean
  return mean, (d * w[:, None]).T @ d / max(1.0 - np.sum(w**2), 1e-12)


def expected_gain(
  samples,
  weights,
  infos,
  nuisance_sd: Sequence[float] = (),
  keep: Sequence[int] | None = None,
) -> float:
  """A design's Laplace EIG about ``keep`` averaged over the current posterior.

  Args:
    samples: (S, p) posterior draws of the shared parameters (e.g. log bending,
      log area weight), their weighted covariance the current belief.
    weights: (S,) their weights (None: equal).
    infos: the design's information over (shared + its nuisances): one
      (p + q, p + q) matrix for all draws, or (S, p + q, p + q), one per draw
      (its slopes at that draw: ``fisher(J(theta_s), R(theta_s))``).
    nuisance_sd: (q,) prior standard deviations of the design's own nuisance
      parameters (a new fan setting's log wind), independent of the rest.
    keep: the parameters the gain is about (default: the p shared ones).

  Returns:
    E_theta[EIG(theta)], nats.
  """
  x = np.asarray(samples, np.float64)
  w = np.ones(len(x)) if weights is None else np.asarray(weights, np.float64)
  _, s = weighted_cov(x, w)
  q = np.asarray(nuisance_sd, np.float64)
  p = s.shape[0]
  prior = np.zeros((p + len(q), p + len(q)))
  prior[:p, :p] = s
  prior[p:, p:] = np.diag(q**2)
  keep = list(range(p)) if keep is None else list(keep)
  infos = np.asarray(infos, np.float64)
  if infos.ndim == 2:
    return eig(prior, infos, keep)
  if infos.shape[0] != len(x):
    raise ValueError(f'{infos.shape[0]} informations for {len(x)} draws')
  gains = np.array([eig(prior, f, keep) for f in infos])
  return float(w @ gains / w.sum())


def nearest(samples, nodes) -> np.ndarray:
  """(S,) index of the nearest of (K, p) ``nodes`` to each of (S, p) samples:
  tabulated slopes looked up per posterior draw."""
  x = np.asarray(samples, np.float64)
  n = np.asarray(nodes, np.float64)
  return np.argmin(((x[:, None, :] - n[None]) ** 2).sum(-1), axis=1)


def rank(gains: dict) -> list[tuple[str, float]]:
  """Designs by gain, the most informative first."""
  return sorted(gains.items(), key=lambda kv: -kv[1])


def linearize(mean_fn: Callable, theta) -> np.ndarray:
  """(S, m, p) slopes of a differentiable ``mean_fn: (p,) -> (m,)`` at each of
  (S, p) points (``jax.jacfwd``)."""
  jac = jax.vmap(jax.jacfwd(mean_fn))(jnp.asarray(theta))
  return np.asarray(jac, np.float64)


def eig_nested_mc(
  key: jax.Array,
  prior_draws: jax.Array,
  mean_fn: Callable,
  noise_cov,
  inner: int | None = None,
) -> float:
  """Nested Monte Carlo EIG about all parameters (Ryan 2003), the reference
  the Laplace ``eig`` is tested against.

  EIG = E_{theta, y}[log p(y | theta) - log E_{theta'} p(y | theta')], with
  ``y`` simulated from each of the (N, p) ``prior_draws`` and the evidence
  estimated by the first ``inner`` draws (default all; biased upwards by
  O(1 / inner)).
  """
  with jax.enable_x64(True):
    theta = jnp.asarray(prior_draws, jnp.float64)
    r = jnp.asarray(noise_cov, jnp.float64)
    chol = jnp.linalg.cholesky(r)
    mu = jax.vmap(mean_fn)(theta)  # (N, m)
    y = mu + jax.random.normal(key, mu.shape, jnp.float64) @ chol.T
    inner_mu = mu if inner is None else mu[:inner]

    def loglik(yi, means):  # (K,) log p(yi | each mean), up to a constant
      z = jax.scipy.linalg.solve_triangular(chol, (yi[None] - means).T, lower=True)
      return -0.5 * jnp.sum(z**2, axis=0)

    own = jax.vmap(lambda yi, mi: loglik(yi, mi[None])[0])(y, mu)
    cross = jax.vmap(lambda yi: loglik(yi, inner_mu))(y)  # (N, M)
    evidence = jax.scipy.special.logsumexp(cross, axis=1) - jnp.log(cross.shape[1])
    return float(jnp.mean(own - evidence))
