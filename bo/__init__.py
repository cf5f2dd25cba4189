"""Gaussian-process Bayesian optimisation in JAX.

The public entry points are ``minimize`` (or ``Minimizer``, its loop as
ask/tell steps, for drivers that batch many searches) and ``PosteriorSearch``
(a likelihood-free posterior from a GP of a noisy discrepancy, with the same
ask/tell interface); ``batched`` asks many searches at once, their GP steps as
one device program (a single ``ask`` is its batch of one); the GP (``gp``), kernels (``kernels``), acquisition
functions (``acquisition``) and the proposal step (``propose``) are exposed as
building blocks; ``calibration`` recalibrates a posterior's credible levels
on simulations whose truth is known.
"""

from bo import (
  acquisition,
  batched,
  calibration,
  gp,
  kernels,
  posterior,
  propose,
  qmc,
  uncertainty,
)
from bo.loop import IterationInfo, Minimizer, Result, State, minimize
from bo.posterior import PosteriorConfig, PosteriorSearch
from bo.uncertainty import MinimizerSamples, minimizer_samples

__all__ = [
  'IterationInfo',
  'Minimizer',
  'MinimizerSamples',
  'PosteriorConfig',
  'PosteriorSearch',
  'Result',
  'State',
  'acquisition',
  'batched',
  'calibration',
  'gp',
  'kernels',
  'minimize',
  'minimizer_samples',
  'posterior',
  'propose',
  'qmc',
  'uncertainty',
]
