"""Gaussian-process Bayesian optimisation in JAX.

The public entry point is ``minimize``; the GP (``gp``), kernels
(``kernels``), acquisition functions (``acquisition``) and the proposal step
(``propose``) are exposed as building blocks.
"""

from bo import acquisition, gp, kernels, propose, qmc
from bo.loop import IterationInfo, Result, minimize

__all__ = [
  'IterationInfo',
  'Result',
  'acquisition',
  'gp',
  'kernels',
  'minimize',
  'propose',
  'qmc',
]
