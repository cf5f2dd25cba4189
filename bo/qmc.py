"""Scrambled Halton sequences in NumPy (quasi-random designs without SciPy)."""

import numpy as np

_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71)


def halton(n: int, d: int, *, seed: int = 0, skip: int = 0) -> np.ndarray:
  """Scrambled Halton points in the unit cube.

  Each dimension uses its own prime base and an independent random
  permutation of the digits at every digit position (zero maps to zero is
  not required: all digits are permuted, which is Owen-style digit
  scrambling restricted to one permutation per position). This removes the
  correlation between high dimensions that plain Halton shows, and with
  ``seed`` fixed the sequence is deterministic.

  Args:
    n: number of points.
    d: dimension, at most 20.
    seed: scrambling seed.
    skip: number of leading points of the sequence to drop.

  Returns:
    Array of shape ``(n, d)``, float64, in ``[0, 1)``.
  """
  if d > len(_PRIMES):
    raise ValueError(f'halton supports d <= {len(_PRIMES)}, got {d}.')
  rng = np.random.default_rng(seed)
  idx = np.arange(skip + 1, skip + n + 1, dtype=np.int64)
  out = np.zeros((n, d))
  for j in range(d):
    base = _PRIMES[j]
    n_digits = int(np.ceil(np.log(skip + n + 2) / np.log(base))) + 1
    # Enough digits to reach float64 resolution, so scrambling fills the cube.
    n_digits = max(n_digits, int(np.ceil(53 * np.log(2) / np.log(base))))
    perms = np.stack([rng.permutation(base) for _ in range(n_digits)])
    k = idx.copy()
    scale = 1.0 / base
    x = np.zeros(n)
    for pos in range(n_digits):
      digit = k % base
      x += perms[pos][digit] * scale
      k //= base
      scale /= base
    out[:, j] = x
  return out
