"""experiments.pipeline.recording: a recording's frames, camera and truth, loaded."""

from __future__ import annotations

import json

import numpy as np
import pytest

from experiments.pipeline import recording

# Frames are resampled to the nearest source frame and resized by nearest
# neighbour: values pass through unchanged.
_EXACT = 0.0


def _npz(tmp_path, frames=10, fps=10.0):
  depth = 1.0 + 0.01 * np.arange(frames, dtype=np.float32)[:, None, None]
  depth = np.broadcast_to(depth, (frames, 8, 8)).copy()
  path = tmp_path / 'clip.npz'
  np.savez(path, depth=depth, fps=fps)
  return str(path), depth


def test_an_npz_is_resampled_in_time_and_cut_to_frames(tmp_path):
  path, depth = _npz(tmp_path, frames=10, fps=10.0)
  rec = recording.load_recording(path, fps=5.0, size=(8, 8), frames=3)
  assert rec.depth.shape == (3, 8, 8) and rec.fps == 5.0
  # 5 Hz out of 10 Hz: every second source frame.
  np.testing.assert_allclose(rec.depth, depth[[0, 2, 4]], atol=_EXACT)
  assert rec.intrinsics is None and rec.pose is None and rec.truth is None


def test_a_camera_file_without_intrinsics_is_named(tmp_path):
  path, _ = _npz(tmp_path)
  cam = tmp_path / 'camera.json'
  cam.write_text(json.dumps({'fx': 500}))
  with pytest.raises(ValueError, match=r'camera\.json: no "intrinsics"'):
    recording.load_recording(path, fps=10.0, size=(8, 8), camera_json=str(cam))


def test_a_corrupt_json_is_named(tmp_path):
  bad = tmp_path / 'meta.json'
  bad.write_text('{"wind_speed": ')
  with pytest.raises(ValueError, match=r'meta\.json: cannot read JSON'):
    recording.read_json(str(bad))


def test_truth_of_reads_the_three_parameters_or_none():
  meta = {'bending_scale': '2', 'wind_speed': 3.5, 'area_weight': 0.2, 'fps': 24}
  assert recording.truth_of(meta) == {
    'bending_scale': 2.0, 'wind_speed': 3.5, 'area_weight': 0.2
  }  # fmt: skip
  assert recording.truth_of({'fps': 24}) is None
