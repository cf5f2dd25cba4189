"""Stationary ARD kernels (unit output scale) for the Gaussian process."""

from collections.abc import Callable

import jax.numpy as jnp

Kernel = Callable[[jnp.ndarray, jnp.ndarray, jnp.ndarray], jnp.ndarray]

_SQRT5 = 5.0**0.5
# Added inside the square root so that the gradient of the distance stays
# finite at zero distance (diagonal of K(X, X)).
_DIST_EPS = 1e-30


def _scaled_sqdist(x1, x2, lengthscales):
  """Squared distance after ARD scaling, shape ``(n1, n2)``."""
  a = x1 / lengthscales
  b = x2 / lengthscales
  d = a[:, None, :] - b[None, :, :]
  return jnp.sum(d * d, axis=-1)


def rbf(x1: jnp.ndarray, x2: jnp.ndarray, lengthscales: jnp.ndarray) -> jnp.ndarray:
  """Squared-exponential correlation ``exp(-r^2 / 2)``.

  Args:
    x1: points ``(n1, d)``.
    x2: points ``(n2, d)``.
    lengthscales: ARD lengthscales ``(d,)``.

  Returns:
    Correlation matrix ``(n1, n2)``.
  """
  return jnp.exp(-0.5 * _scaled_sqdist(x1, x2, lengthscales))


def matern52(
  x1: jnp.ndarray, x2: jnp.ndarray, lengthscales: jnp.ndarray
) -> jnp.ndarray:
  """Matern-5/2 correlation ``(1 + s + s^2/3) exp(-s)`` with ``s = sqrt(5) r``.

  Args:
    x1: points ``(n1, d)``.
    x2: points ``(n2, d)``.
    lengthscales: ARD lengthscales ``(d,)``.

  Returns:
    Correlation matrix ``(n1, n2)``.
  """
  r2 = _scaled_sqdist(x1, x2, lengthscales)
  s = _SQRT5 * jnp.sqrt(r2 + _DIST_EPS)
  return (1.0 + s + (5.0 / 3.0) * r2) * jnp.exp(-s)


KERNELS: dict[str, Kernel] = {'matern52': matern52, 'rbf': rbf}


def get(name: str) -> Kernel:
  """Returns the kernel function called ``name`` (``'matern52'`` or ``'rbf'``)."""
  if name not in KERNELS:
    raise ValueError(f'Unknown kernel {name!r}; choose from {sorted(KERNELS)}.')
  return KERNELS[name]
