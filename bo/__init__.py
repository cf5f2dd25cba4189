"""Gaussian-process Bayesian optimisation in JAX.

The public entry point is ``minimize`` (or ``Minimizer``, its loop as
ask/tell steps, for drivers that batch many searches); the GP (``gp``), kernels
(``kernels``), acquisition functions (``acquisition``) and the proposal step
(``propose``) are exposed as building blocks.
"""

from bo import acquisition, gp, kernels, propose, qmc, uncertainty
from bo.loop import IterationInfo, Minimizer, Result, State, minimize
from bo.uncertainty import MinimizerSamples, minimizer_samples

__all__ = [
  'IterationInfo',
  'Minimizer',
  'MinimizerSamples',
  'Result',
  'State',
  'acquisition',
  'gp',
  'kernels',
  'minimize',
  'minimizer_samples',
  'propose',
  'qmc',
  'uncertainty',
]
