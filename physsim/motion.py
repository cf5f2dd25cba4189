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


def vertex_normals(mesh: Mesh, positions: np.ndarray) -> np.ndarray:
  """(V, 3) unit normals of one shape (V, 3): area-weighted face normals summed
  at each vertex, oriented as ``mesh.faces``."""
  p = positions[mesh.faces]
  n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # length = 2 x face area
  out = np.zeros_like(positions)
  for k in range(3):
    np.add.at(out, mesh.faces[:, k], n)
  return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def wave_slowness(
  mesh: Mesh, positions: np.ndarray, fps: float, bands: int = 10
) -> tuple[float, float]:
  """How fast the flapping travels down the sheet, from the pins to the free edge.

  Each vertex's motion normal to the sheet's time-mean shape, averaged over
  bands of rest distance below the top edge, gives one signal per band. At the
  sheet's dominant frequency f (the strongest bin of the summed band spectra) a
  wave ``cos(2 pi f (t - d / c))`` has Fourier phase ``-2 pi f d / c``; the
  amplitude-weighted slope of the unwrapped phase against d is ``-2 pi f s``.

  Args:
    mesh: rest mesh (z up; the top edge holds the pins).
    positions: (T, V, 3) vertex positions at the frame rate, metres.
    fps: frame rate, Hz.
    bands: distance bands over the sheet's height.

  Returns:
    ``(slowness, hz)``: s = 1 / c in s/m (0 for a sheet moving in phase,
    negative for waves running up the sheet), and the frequency it was
    measured at. NaN, NaN for a sheet that does not move or fewer than three
    moving bands.
  """
  x = np.asarray(positions, np.float64)
  mean = x.mean(0)
  disp = np.einsum('tvk,vk->tv', x - mean, vertex_normals(mesh, mean))
  rest_z = mesh.vertices[:, 2]
  depth = rest_z.max() - rest_z
  free = np.ones(len(rest_z), bool)
  free[mesh.pinned] = False
  edges = np.linspace(0.0, depth.max() * (1 + 1e-9), bands + 1)
  idx = np.digitize(depth, edges) - 1
  keep = [b for b in range(bands) if np.any(free & (idx == b))]
  if len(keep) < 3:
    return float('nan'), float('nan')
  d = np.array([depth[free & (idx == b)].mean() for b in keep])
  sig = np.stack([disp[:, free & (idx == b)].mean(1) for b in keep], 1)  # (T, B)
  sig = (sig - sig.mean(0)) * np.hanning(len(sig))[:, None]
  spec = np.fft.rfft(sig, axis=0)  # (F, B)
  freqs = np.fft.rfftfreq(len(sig), 1.0 / fps)
  power = np.sum(np.abs(spec[1:]) ** 2, axis=1)
  if not np.any(power > 0):
    return float('nan'), float('nan')
  k = 1 + int(np.argmax(power))
  amp = np.abs(spec[k])
  phase = np.unwrap(np.angle(spec[k]))
  slope = np.polyfit(d, phase, 1, w=np.sqrt(amp / amp.max()))[0]
  return float(-slope / (2.0 * np.pi * freqs[k])), float(freqs[k])


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
    wave_slowness_s_per_m, wave_hz: ``wave_slowness`` (1 / the speed at which
      the flapping runs down the sheet) and the frequency it was measured at.
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
  slowness, wave_hz = wave_slowness(mesh, positions, fps)
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
    'wave_slowness_s_per_m': slowness,
    'wave_hz': wave_hz,
  }


def batch_stats(mesh: Mesh, positions, valid, fps: float) -> list[dict]:
  """``motion_stats`` of every world of a batch (a ``Rollout``'s positions
  (B, T, V, 3) and valid (B,)): ``{'valid': bool, **stats}`` per world, the
  statistics only where the world did not blow up."""
  return [
    {'valid': bool(ok), **(motion_stats(mesh, x, fps) if ok else {})}
    for x, ok in zip(positions, valid, strict=True)
  ]
