"""Motion statistics of a cloth rollout: edge strain, sag, and how the centre moves.

These are the numbers that say whether a simulation moves like fabric in a fan's
wind (the paper's sheets billow and flutter at 1-2 Hz): how much edges stretch,
how far the top edge sags between the pins, and the amplitude and frequency
content of the centre's wind-wise motion. NumPy, float64, one world at a time.
"""

from __future__ import annotations

import numpy as np

from physsim.mesh import Mesh

# Above this, motion counts as flutter rather than the slow swing of the sheet.
FLUTTER_HZ = 1.0


def edge_strain(mesh: Mesh, positions: np.ndarray) -> np.ndarray:
  """(T, E) relative edge stretch ``|e| / |e0| - 1`` for positions (T, V, 3)."""
  e = mesh.edges
  rest = np.linalg.norm(mesh.vertices[e[:, 1]] - mesh.vertices[e[:, 0]], axis=-1)
  cur = np.linalg.norm(positions[:, e[:, 1]] - positions[:, e[:, 0]], axis=-1)
  return cur / rest - 1.0


def centre_vertex(mesh: Mesh) -> int:
  """Index of the vertex nearest the rest mesh's centroid."""
  v = mesh.vertices
  return int(np.argmin(np.linalg.norm(v - v.mean(0), axis=1)))


def top_sag(mesh: Mesh, positions: np.ndarray) -> np.ndarray:
  """(T,) drop in metres of the top edge's middle below the pins' mean height."""
  v = mesh.vertices
  top = np.flatnonzero(np.isclose(v[:, 2], v[:, 2].max()))
  mid = top[np.argmin(np.abs(v[top, 0] - v[mesh.pinned, 0].mean()))]
  return positions[:, mesh.pinned, 2].mean(-1) - positions[:, mid, 2]


def spectrum(signal: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
  """One-sided power spectrum of a mean-removed, Hann-windowed signal (T,)."""
  y = np.asarray(signal, np.float64)
  y = (y - y.mean()) * np.hanning(len(y))
  return np.fft.rfftfreq(len(y), 1.0 / fps), np.abs(np.fft.rfft(y)) ** 2


def motion_stats(mesh: Mesh, positions: np.ndarray, fps: float) -> dict[str, float]:
  """Summary of one world's rollout.

  Args:
    mesh: the rest mesh the rollout was made from.
    positions: (T, V, 3) vertex positions at the frame rate, metres.
    fps: frame rate, Hz.

  Returns:
    strain_max, strain_p99: largest and 99th-percentile |edge strain|.
    sag_m: mean top-edge sag between the pins.
    centre_amplitude_m: peak-to-peak of the centre's wind-wise (y) motion.
    centre_rms_m: its standard deviation.
    centre_dominant_hz: frequency of the strongest non-zero spectral bin.
    flutter_fraction: share of the centre's motion power above ``FLUTTER_HZ``
      (0 = a slow swing, 1 = all flutter).
    mean_deflection_m: mean wind-wise displacement over vertices and frames.
  """
  positions = np.asarray(positions, np.float64)
  if positions.ndim != 3 or positions.shape[1:] != mesh.vertices.shape:
    raise ValueError(
      f'positions must be (T, {len(mesh.vertices)}, 3), got {positions.shape}'
    )
  if len(positions) < 4:
    raise ValueError(f'need at least 4 frames for a spectrum, got {len(positions)}')
  strain = np.abs(edge_strain(mesh, positions))
  y = positions[:, centre_vertex(mesh), 1]
  freqs, power = spectrum(y, fps)
  total = power[1:].sum()
  return {
    'strain_max': float(strain.max()),
    'strain_p99': float(np.quantile(strain, 0.99)),
    'sag_m': float(top_sag(mesh, positions).mean()),
    'centre_amplitude_m': float(np.ptp(y)),
    'centre_rms_m': float(y.std()),
    'centre_dominant_hz': float(freqs[1:][np.argmax(power[1:])]),
    'flutter_fraction': float(power[freqs > FLUTTER_HZ].sum() / total)
    if total > 0
    else 0.0,
    'mean_deflection_m': float((positions[..., 1] - mesh.vertices[:, 1]).mean()),
  }


def batch_stats(mesh: Mesh, positions, valid, fps: float) -> list[dict]:
  """``motion_stats`` of every world of a batch (a ``Rollout``'s positions
  (B, T, V, 3) and valid (B,)): ``{'valid': bool, **stats}`` per world, the
  statistics only where the world did not blow up."""
  return [
    {'valid': bool(ok), **(motion_stats(mesh, x, fps) if ok else {})}
    for x, ok in zip(positions, valid, strict=True)
  ]
