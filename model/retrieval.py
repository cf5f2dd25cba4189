"""Parameter retrieval by physics similarity: how far PSD-near is from parameter-near.

The estimate returns the parameters whose simulation embeds PSD-closest to a
recording. Triplet and k-NN accuracy ask whether frames of one simulation
cluster; they do not ask whether a small PSD means close parameters, which is
what the estimate needs (an embedding that sees only wind can score well on
triplets and still leave bending to chance). Retrieval asks it directly, on
held-out simulations: each query video (one simulation seen from one camera)
retrieves the PSD-nearest reference video seen from the same camera, as the
estimate renders candidates from the recording's camera, and the error is
``|log(p_retrieved / p_true)|`` per parameter: scale-free, about the relative
error when small, the log of a factor for bending.

It is a grid version of the estimate: the references are a few dozen sampled
parameter sets where the optimiser searches continuously, so its floor is the
spacing of the references (``oracle_log_ratios``: the reference nearest in
parameters) and its ceiling a reference drawn at random (``chance_errors``).
``summary`` scores each parameter against that chance value, so that a
parameter the videos do not reveal (bending, on a large sheet) does not drown
the ones they do.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from model import psd as psd_lib


class Videos(NamedTuple):
  """Which clip each item comes from, and that clip's true parameters.

  Attributes:
    video: ``(N,)`` int id of the clip (one simulation seen from one camera).
    camera: ``(N,)`` int camera index; only clips of one camera are compared.
    params: ``(N, P)`` float, > 0: the physical parameters of the item's
      simulation (e.g. bending scale, wind speed, area weight).
    names: the P parameter names, for logs (default p0, p1, ...).
  """

  video: np.ndarray
  camera: np.ndarray
  params: np.ndarray
  names: tuple[str, ...] = ()


def check_videos(videos: Videos, n: int) -> Videos:
  """Validated NumPy ``Videos`` for ``n`` items.

  Raises:
    ValueError: wrong lengths, non-positive or non-finite parameters, or a
      clip whose items disagree on camera or parameters (the value is named).
  """
  video = np.asarray(videos.video).astype(np.int64)
  camera = np.asarray(videos.camera).astype(np.int64)
  params = np.asarray(videos.params, np.float64)
  if params.ndim == 1:
    params = params[:, None]
  for name, a in (('video', video), ('camera', camera), ('params', params)):
    if len(a) != n:
      raise ValueError(f'Videos.{name} has {len(a)} rows for {n} items.')
  if not np.all(np.isfinite(params) & (params > 0)):
    bad = params[~np.all(np.isfinite(params) & (params > 0), axis=1)][0]
    raise ValueError(f'Videos.params must be finite and > 0, got a row {bad.tolist()}.')
  _, first, inv = np.unique(video, return_index=True, return_inverse=True)
  for name, a in (('camera', camera), ('params', params)):
    ref = a[first][inv]
    if not np.array_equal(ref, a):
      v = video[np.flatnonzero(np.any((ref != a).reshape(n, -1), axis=1))[0]]
      raise ValueError(f'Videos: items of video {v} disagree on {name}.')
  names = tuple(videos.names) or tuple(f'p{i}' for i in range(params.shape[1]))
  if len(names) != params.shape[1]:
    raise ValueError(
      f'Videos.names has {len(names)} names for {params.shape[1]} parameters.'
    )
  return Videos(video, camera, params, names)


def _clips(videos: Videos, idx: np.ndarray) -> dict[int, np.ndarray]:
  """``{video id: item indices}`` of the items ``idx``, ids ascending."""
  idx = np.asarray(idx)
  ids = videos.video[idx]
  return {int(v): idx[ids == v] for v in np.unique(ids)}


@functools.partial(jax.jit, static_argnames='kind')
def _batched_psd(x: jax.Array, refs: jax.Array, kind: str) -> jax.Array:
  """PSD of one clip's points ``(n, d)`` to each of ``(R, m, d)``: ``(R,)``."""
  return jax.vmap(lambda r: psd_lib.psd(x, r, kind))(refs)


def _same_camera(videos: Videos, query_idx, ref_idx):
  """Yields ``(query clip's items, [items of each reference clip of its camera])``
  per query clip in clip-id order, skipping queries without such a reference."""
  queries, refs = _clips(videos, query_idx), _clips(videos, ref_idx)
  by_camera: dict[int, list[np.ndarray]] = {}
  for items in refs.values():
    by_camera.setdefault(int(videos.camera[items[0]]), []).append(items)
  for items in queries.values():
    cands = by_camera.get(int(videos.camera[items[0]]), [])
    if cands:
      yield items, cands


def _log_ratios(videos: Videos, query, refs) -> np.ndarray:
  """``(R, P)`` log(reference / query parameters) of one query clip."""
  return np.log(videos.params[[r[0] for r in refs]] / videos.params[query[0]])


def _stack(rows: list, p: int) -> np.ndarray:
  return np.asarray(rows, np.float64).reshape(len(rows), p)


def retrieval_log_ratios(
  embeddings: np.ndarray,
  videos: Videos,
  query_idx: np.ndarray,
  ref_idx: np.ndarray,
  kind: str = 'energy',
) -> np.ndarray:
  """``log(p_retrieved / p_true)`` for every query clip.

  Args:
    embeddings: ``(N, d)`` item embeddings.
    videos: ``Videos`` of the N items (``check_videos``).
    query_idx: items of the query clips (held-out simulations).
    ref_idx: items of the reference clips (another set of simulations).
    kind: the PSD (``model.psd.KINDS``, 'energy' or 'centroid').

  Returns:
    ``(Q, P)`` float64, one row per query clip that has a reference clip of
    its camera (queries without one are left out), in clip-id order.
  """
  emb = np.asarray(embeddings, np.float32)
  out = []
  for items, refs in _same_camera(videos, query_idx, ref_idx):
    x = jnp.asarray(emb[items])
    if len({len(r) for r in refs}) == 1:  # one vmapped call; ragged ones go singly
      d = np.asarray(
        _batched_psd(x, jnp.asarray(np.stack([emb[r] for r in refs])), kind)
      )
    else:
      d = np.array([float(psd_lib.psd(x, jnp.asarray(emb[r]), kind)) for r in refs])
    out.append(_log_ratios(videos, items, refs)[int(np.argmin(d))])
  return _stack(out, videos.params.shape[1])


def _per_query(videos: Videos, query_idx, ref_idx, pick) -> np.ndarray:
  """``pick(log ratios (R, P) of the same-camera references) -> (P,)`` per query clip."""
  rows = [
    pick(_log_ratios(videos, q, r)) for q, r in _same_camera(videos, query_idx, ref_idx)
  ]
  return _stack(rows, videos.params.shape[1])


def oracle_log_ratios(videos: Videos, query_idx, ref_idx) -> np.ndarray:
  """The floor of ``retrieval_log_ratios``: each query retrieves the reference
  clip of its camera nearest in parameters (least mean ``|log ratio|``)."""
  return _per_query(
    videos, query_idx, ref_idx, lambda lr: lr[int(np.argmin(np.abs(lr).mean(axis=1)))]
  )


def chance_errors(videos: Videos, query_idx, ref_idx) -> np.ndarray:
  """``(Q, P)`` expected ``|log ratio|`` of a reference of the query's camera
  drawn at random: what an embedding that knows nothing would score."""
  return _per_query(videos, query_idx, ref_idx, lambda lr: np.abs(lr).mean(axis=0))


def score(
  embeddings: np.ndarray, videos: Videos, query_idx, ref_idx, kind: str = 'energy'
) -> dict:
  """``summary`` of the query clips' retrieval among the reference clips
  (``retrieval_log_ratios`` against ``chance_errors``); {} without queries."""
  lr = retrieval_log_ratios(embeddings, videos, query_idx, ref_idx, kind)
  return summary(lr, chance_errors(videos, query_idx, ref_idx), videos.names)


def summary(log_ratios: np.ndarray, chance: np.ndarray, names) -> dict:
  """Retrieval scores of a set of query clips (empty without queries).

  Args:
    log_ratios: ``(Q, P)`` from ``retrieval_log_ratios``.
    chance: ``(Q, P)`` from ``chance_errors`` for the same queries.
    names: the P parameter names.

  Returns:
    ``{'queries': Q, 'error': mean over parameters of (mean |log ratio|) /
    (its chance value), name: mean |log ratio| per parameter, 'chance':
    {name: chance mean |log ratio|}}``. ``error`` weighs the parameters alike
    whatever their ranges: 0 = every query retrieves its own parameters, 1 =
    no better than a random reference (a parameter the embedding cannot see,
    such as bending on a large sheet, sits near 1).
  """
  lr = np.abs(np.asarray(log_ratios, np.float64))
  chance = np.asarray(chance, np.float64)
  if lr.size == 0:
    return {}
  names = list(names)
  if len(names) != lr.shape[1] or chance.shape != lr.shape:
    raise ValueError(
      f'{len(names)} names, log ratios {lr.shape} and chance {chance.shape} disagree.'
    )
  err, base = lr.mean(axis=0), chance.mean(axis=0)
  return {
    'queries': int(lr.shape[0]),
    'error': float(np.mean(err / np.maximum(base, 1e-12))),
    **{n: float(v) for n, v in zip(names, err, strict=True)},
    'chance': {n: float(v) for n, v in zip(names, base, strict=True)},
  }


def vs_chance(s: dict) -> dict[str, float]:
  """Each parameter's mean |log ratio| of a ``summary`` over its chance value
  (1 = no better than a random reference); {} for an empty summary."""
  return {n: s[n] / c for n, c in s.get('chance', {}).items() if c > 0}


def describe(ratios: dict[str, float]) -> str:
  """``vs_chance`` ratios as ``'name 0.31, ...'`` for a log line."""
  return ', '.join(f'{n} {v:.2f}' for n, v in ratios.items())
