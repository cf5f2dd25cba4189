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


def _folder(root, name, offset, frames=6):
  """A folder of 16-bit mm PNGs, each frame its own depth."""
  import cv2  # noqa: PLC0415

  folder = root / name
  folder.mkdir()
  for t in range(frames):
    cv2.imwrite(
      str(folder / f'{t:04d}.png'), np.full((8, 8), 1000 + offset + t, np.uint16)
    )
  (folder / 'fps.txt').write_text('10')
  return str(folder)


def test_many_recordings_read_by_threads_come_in_order_as_one_by_one(tmp_path):
  paths = [_folder(tmp_path, f'r{i}', 10 * i) for i in range(5)]
  kw = dict(fps=10.0, size=(8, 8))
  alone = [recording.load_recording(p, **kw) for p in paths]
  many = recording.load_recordings(paths, workers=4, **kw)
  assert [r.source for r in many] == paths
  for a, b in zip(alone, many, strict=True):
    np.testing.assert_array_equal(a.depth, b.depth)
  # frame t of recording i is 1 m + (10 i + t) mm
  np.testing.assert_allclose(many[3].depth[2], 1.032, atol=1e-6)


def test_the_first_bad_recording_of_many_is_named(tmp_path):
  paths = [
    _folder(tmp_path, 'good', 0),
    str(tmp_path / 'missing'),
    str(tmp_path / 'gone'),
  ]
  with pytest.raises(ValueError, match=r'missing: no such file or folder'):
    recording.load_recordings(paths, workers=3, fps=10.0, size=(8, 8))
