"""Tests for physsim.motion against hand-made trajectories with known answers."""

import numpy as np
import pytest

import physsim
from physsim import motion

_TOL = 1e-9


def _wave(mesh, amp, hz, fps=20.0, frames=60, sag=0.0):
  """Every vertex moves along y as amp/2 sin(2 pi hz t); the top middle drops."""
  t = np.arange(frames) / fps
  x = np.repeat(mesh.vertices[None], frames, axis=0)
  x[..., 1] += 0.5 * amp * np.sin(2 * np.pi * hz * t)[:, None]
  return x, t


def test_pure_translation_has_no_strain_and_known_spectrum():
  mesh = physsim.square(5)
  # 2 Hz is bin 6 of a 60-frame clip at 20 Hz (bins are 1/3 Hz apart).
  x, _ = _wave(mesh, amp=0.1, hz=2.0)
  s = motion.motion_stats(mesh, x, fps=20.0)
  assert s['strain_max'] < _TOL
  assert s['centre_dominant_hz'] == pytest.approx(2.0)
  # samples fall every 36 degrees of phase, so the sampled peaks are sin(72 deg)
  assert s['centre_amplitude_m'] == pytest.approx(0.1 * np.sin(np.radians(72)))
  assert s['centre_rms_m'] == pytest.approx(0.1 / 2 / np.sqrt(2), rel=1e-6)
  assert s['flutter_fraction'] > 0.99
  assert abs(s['mean_deflection_m']) < 1e-3


def test_batch_stats_per_world_and_blown_up_worlds_without_stats():
  mesh = physsim.square(5)
  x, _ = _wave(mesh, amp=0.1, hz=2.0)
  batch = np.stack([x, np.full_like(x, np.nan)])
  one, bad = motion.batch_stats(mesh, batch, np.array([True, False]), fps=20.0)
  assert one == {'valid': True, **motion.motion_stats(mesh, x, fps=20.0)}
  assert bad == {'valid': False}


def test_slow_swing_is_not_flutter():
  mesh = physsim.square(5)
  x, _ = _wave(mesh, amp=0.2, hz=1 / 3)
  s = motion.motion_stats(mesh, x, fps=20.0)
  assert s['centre_dominant_hz'] == pytest.approx(1 / 3)
  assert s['flutter_fraction'] < 0.05


def test_strain_and_sag_by_hand():
  mesh = physsim.square(3, size=1.0)  # vertices 0.5 m apart
  x = np.repeat(mesh.vertices[None], 4, axis=0)
  x[:, 1, 2] -= 0.1  # top middle vertex drops 10 cm
  s = motion.motion_stats(mesh, x, fps=20.0)
  assert s['sag_m'] == pytest.approx(0.1, abs=_TOL)
  # the vertical edge below it shrinks 0.5 -> 0.4 m (the top edges only to
  # sqrt(0.26) / 0.5 - 1 = 2%)
  assert s['strain_max'] == pytest.approx(0.2, abs=_TOL)


def test_bad_shapes():
  mesh = physsim.square(3)
  with pytest.raises(ValueError, match='positions must be'):
    motion.motion_stats(mesh, np.zeros((10, 4, 3)), 20.0)
  with pytest.raises(ValueError, match='at least 4 frames'):
    motion.motion_stats(mesh, np.zeros((2, 9, 3)), 20.0)


def _travelling(mesh, speed, hz=4 / 3, fps=20.0, frames=60, amp=0.02):
  """Motion normal to the sheet (y) of ``amp sin(2 pi hz (t - d / speed))``,
  d the rest distance below the top edge (speed inf: all in phase)."""
  t = np.arange(frames)[:, None] / fps
  d = mesh.vertices[:, 2].max() - mesh.vertices[:, 2]
  x = np.repeat(mesh.vertices[None], frames, axis=0)
  x[..., 1] += amp * np.sin(2 * np.pi * hz * (t - d[None] / speed))
  return x


@pytest.mark.parametrize('speed', [0.6, 1.5, -1.0])
def test_wave_slowness_of_a_travelling_wave(speed):
  # 4/3 Hz is bin 4 of 60 frames at 20 Hz; the 1 m sheet holds 0.6-1.5 wavelengths
  mesh = physsim.square(8)
  s = motion.motion_stats(mesh, _travelling(mesh, speed), fps=20.0)
  assert s['wave_hz'] == pytest.approx(4 / 3)
  assert s['wave_slowness_s_per_m'] == pytest.approx(1 / speed, rel=0.02)


def test_in_phase_motion_has_no_slowness_and_a_still_sheet_none_at_all():
  mesh = physsim.square(8)
  moving = motion.motion_stats(mesh, _travelling(mesh, np.inf), fps=20.0)
  assert abs(moving['wave_slowness_s_per_m']) < 1e-9
  still = np.repeat(mesh.vertices[None], 20, axis=0)
  slowness, hz = motion.wave_slowness(mesh, still, 20.0)
  assert np.isnan(slowness) and np.isnan(hz)
