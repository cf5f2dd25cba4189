"""Train/test splits: by simulation (held-out groups) and the paper's random per-image split."""

import jax
import numpy as np

SPLITS = ('simulation', 'random', 'none')


def _check_fraction(test_fraction: float) -> None:
  if not 0.0 < test_fraction < 1.0:
    raise ValueError(f'test_fraction must be in (0, 1), got {test_fraction}.')


def split_by_group(
  key: jax.Array, groups, test_fraction: float
) -> tuple[np.ndarray, np.ndarray]:
  """Holds out whole groups: no test image shares a group with a training image.

  Pass ``groups=labels`` to hold out whole simulations (the honest test of a
  physics embedding: test parameter sets were never seen), or a sequence id
  (simulation x camera) to hold out camera sequences only.

  Args:
    key: PRNG key.
    groups: ``(N,)`` integer group ids.
    test_fraction: fraction of groups held out (rounded, at least one group,
      at most all but one).

  Returns:
    (train, test) sorted int64 index arrays into ``groups``.
  """
  _check_fraction(test_fraction)
  groups = np.asarray(groups)
  unique = np.unique(groups)
  if unique.size < 2:
    raise ValueError(
      f'groups must hold at least two distinct ids to split, got {unique.size}.'
    )
  n_test = int(np.clip(round(test_fraction * unique.size), 1, unique.size - 1))
  perm = np.asarray(jax.random.permutation(key, unique.size))
  test_mask = np.isin(groups, unique[perm[:n_test]])
  return np.flatnonzero(~test_mask), np.flatnonzero(test_mask)


def split_random(
  key: jax.Array, n: int, test_fraction: float
) -> tuple[np.ndarray, np.ndarray]:
  """The paper's protocol: a random per-image split (test images come from training simulations).

  Args:
    key: PRNG key.
    n: number of images.
    test_fraction: fraction of images held out (at least one, at most n - 1).

  Returns:
    (train, test) sorted int64 index arrays.
  """
  _check_fraction(test_fraction)
  if n < 2:
    raise ValueError(f'need at least two images to split, got {n}.')
  n_test = int(np.clip(round(test_fraction * n), 1, n - 1))
  perm = np.asarray(jax.random.permutation(key, n))
  return np.sort(perm[n_test:]), np.sort(perm[:n_test])


def split(
  key: jax.Array, kind: str, labels, groups, test_fraction: float
) -> tuple[np.ndarray, np.ndarray]:
  """Dispatches on ``kind``: 'simulation' (by ``groups``), 'random' or 'none' (empty test).

  Args:
    key: PRNG key.
    kind: one of ``SPLITS``.
    labels: ``(N,)`` labels.
    groups: ``(N,)`` group ids (used by 'simulation').
    test_fraction: see the split functions.

  Returns:
    (train, test) index arrays.
  """
  n = len(labels)
  if kind == 'simulation':
    return split_by_group(key, groups, test_fraction)
  if kind == 'random':
    return split_random(key, n, test_fraction)
  if kind == 'none':
    return np.arange(n), np.zeros((0,), np.int64)
  raise ValueError(f'split must be one of {SPLITS}, got {kind!r}.')
