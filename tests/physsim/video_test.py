"""Tests for physsim.video: formats, time resampling, masking and bad input."""

import json
import os

import cv2
import numpy as np
import pytest

from physsim import dataset, video, video_files

# MJPG is lossy; flat grey frames come back within a few intensity levels.
_VIDEO_TOLERANCE = 4 / 255
_FLOAT_TOLERANCE = 1e-6


def _frames(t=12, h=6, w=5, seed=0):
  """(T, H, W) metres whose frame i is identifiable: 1 + 0.01 i plus small noise."""
  rng = np.random.default_rng(seed)
  base = 1.0 + 0.01 * np.arange(t)[:, None, None]
  return (base + rng.integers(0, 5, size=(t, h, w)) * 1e-3).astype(np.float32)


def _png_folder(path, mm):
  os.makedirs(path, exist_ok=True)
  for t, f in enumerate(mm):
    assert cv2.imwrite(os.path.join(path, f'{t:04d}.png'), f)
  return str(path)


def test_png16_folder_with_fps_from_meta(tmp_path):
  d = _frames()
  mm = dataset.depth_to_mm(d)
  folder = _png_folder(tmp_path / 'cam0', mm)
  (tmp_path / 'meta.json').write_text(json.dumps({'fps': 20.0}))
  out = video.load_depth_video(folder, size=None)
  assert out.fps == 20.0 and not out.normalised
  assert out.source.startswith('png16:')
  np.testing.assert_array_equal(out.depth, dataset.mm_to_depth(mm))


def test_simulated_sequence_camera_folder(tmp_path):
  d = np.stack([_frames(4), _frames(4, seed=1)])  # (C, T, H, W)
  row = dataset.make_row(
    '0000', 'red_violet', 0, None, None, valid=True, n_cameras=2, n_frames=4
  )
  rgb = np.zeros((*d.shape, 3), np.uint8)
  path = dataset.write_sequence(str(tmp_path), {**row, 'fps': 20.0}, d, rgb)
  out = video.load_depth_video(os.path.join(path, 'cam1'), size=None)
  assert out.fps == 20.0 and out.depth.shape == (4, 6, 5)  # rgb_* skipped
  np.testing.assert_array_equal(out.depth, dataset.read_sequence(path).depth[1])


def test_resample_24_to_20_nearest_picks_closest_frames(tmp_path):
  d = _frames(t=30)
  np.save(tmp_path / 'd.npy', d)
  out = video.load_depth_video(str(tmp_path / 'd.npy'), source_fps=24, size=None)
  # independent reference: the source frame whose time is nearest k / 20 s
  n_out = len(out.depth)
  assert n_out == int((30 - 1) / 24 * 20) + 1
  ref = [int(np.argmin(np.abs(np.arange(30) / 24 - k / 20))) for k in range(n_out)]
  assert ref[:7] == [0, 1, 2, 4, 5, 6, 7]
  np.testing.assert_array_equal(out.depth, d[ref])
  assert out.fps == 20.0


def test_resample_linear_matches_interp(tmp_path):
  d = _frames(t=13)
  np.save(tmp_path / 'd.npy', d)
  out = video.load_depth_video(
    str(tmp_path / 'd.npy'), source_fps=24, size=None, interpolation='linear'
  )
  ts = np.arange(len(out.depth)) / 20
  ref = np.apply_along_axis(lambda x: np.interp(ts, np.arange(13) / 24, x), 0, d)
  np.testing.assert_allclose(out.depth, ref, atol=_FLOAT_TOLERANCE)


def test_fps_sources_and_frame_count(tmp_path):
  d = _frames(t=10)
  np.savez(tmp_path / 'a.npz', depth=d, fps=10.0)
  out = video.load_depth_video(str(tmp_path / 'a.npz'), fps=5, size=None)
  np.testing.assert_array_equal(out.depth, d[::2])
  (tmp_path / 'fps.txt').write_text('5\n')
  np.save(tmp_path / 'b.npy', d)
  out = video.load_depth_video(str(tmp_path / 'b.npy'), fps=5, size=None, frames=3)
  np.testing.assert_array_equal(out.depth, d[:3])
  with pytest.raises(ValueError, match='only 10 frames'):
    video.load_depth_video(str(tmp_path / 'b.npy'), fps=5, size=None, frames=11)
  os.remove(tmp_path / 'fps.txt')
  with pytest.raises(ValueError, match='b.npy: source frame rate unknown'):
    video.load_depth_video(str(tmp_path / 'b.npy'), size=None)
  out = video.load_depth_video(str(tmp_path / 'b.npy'), fps=None, size=None)
  assert out.fps is None and len(out.depth) == 10


def test_depth_range_masks(tmp_path):
  d = _frames(t=4)
  d[:, 0, 0] = 0.3
  d[:, 1, 1] = 7.0
  d[:, 2, 2] = 0.0
  np.save(tmp_path / 'd.npy', d)
  out = video.load_depth_video(
    str(tmp_path / 'd.npy'), fps=None, size=None, depth_range=(0.5, 4.0)
  )
  ref = np.where((d >= 0.5) & (d <= 4.0), d, 0)
  np.testing.assert_array_equal(out.depth, ref)
  assert (out.depth[:, 0, 0] == 0).all() and (out.depth[:, 1, 1] == 0).all()
  with pytest.raises(ValueError, match='frame 0 has no valid pixel inside depth_range'):
    video.load_depth_video(
      str(tmp_path / 'd.npy'), fps=None, size=None, depth_range=(8.0, 9.0)
    )


def test_resize_nearest_and_valid_area(tmp_path):
  d = np.zeros((1, 8, 8), np.float32)
  d[0, :, :4] = 1.0  # left half cloth, right half invalid
  d[0, :, 4:] = 0.0
  d[0, 0, 0] = 0.0
  np.save(tmp_path / 'd.npy', d)
  near = video.load_depth_video(str(tmp_path / 'd.npy'), fps=None, size=(4, 4))
  assert set(np.unique(near.depth)) <= {0.0, 1.0}  # no blended edge values
  area = video.load_depth_video(
    str(tmp_path / 'd.npy'), fps=None, size=(4, 4), resize='valid_area'
  )
  np.testing.assert_allclose(area.depth[0, :, :2], 1.0, atol=_FLOAT_TOLERANCE)
  np.testing.assert_array_equal(area.depth[0, :, 2:], 0.0)


def test_png8_normalised_folder(tmp_path):
  rng = np.random.default_rng(0)
  g = rng.integers(1, 256, size=(3, 6, 5)).astype(np.uint8)
  folder = _png_folder(tmp_path / 'real', g)
  out = video.load_depth_video(folder, source_fps=20, size=None)
  assert out.normalised and out.source.startswith('png8:')
  np.testing.assert_allclose(out.depth, g / 255, atol=_FLOAT_TOLERANCE)
  with pytest.raises(ValueError, match='normalised'):
    video.load_depth_video(folder, source_fps=20, depth_range=(0.5, 2))
  # 3-channel grey PNGs read as one channel
  colour = _png_folder(tmp_path / 'rgb', np.repeat(g[..., None], 3, axis=-1))
  out = video.load_depth_video(colour, source_fps=20, size=None)
  np.testing.assert_allclose(out.depth, g / 255, atol=_FLOAT_TOLERANCE)


def test_video_file(tmp_path):
  path = str(tmp_path / 'clip.avi')
  writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*'MJPG'), 24.0, (32, 16))
  assert writer.isOpened()
  levels = [40 + 8 * t for t in range(12)]
  for v in levels:
    writer.write(np.full((16, 32, 3), v, np.uint8))
  writer.release()
  out = video.load_depth_video(path, fps=None, size=None)
  assert out.normalised and out.fps == pytest.approx(24.0)
  assert out.depth.shape == (12, 16, 32)
  np.testing.assert_allclose(
    out.depth.mean(axis=(1, 2)), np.array(levels) / 255, atol=_VIDEO_TOLERANCE
  )
  out = video.load_depth_video(path, size=(8, 8))
  assert out.fps == 20.0 and out.depth.shape == (10, 8, 8)


def test_bad_inputs_name_the_file(tmp_path):
  mm = dataset.depth_to_mm(_frames(t=3))
  with pytest.raises(ValueError, match='nothing: no such file'):
    video.load_depth_video(str(tmp_path / 'nothing'))
  (tmp_path / 'empty').mkdir()
  with pytest.raises(ValueError, match='empty: no frames'):
    video.load_depth_video(str(tmp_path / 'empty'))

  corrupt = _png_folder(tmp_path / 'corrupt', mm)
  with open(os.path.join(corrupt, '0001.png'), 'wb') as f:
    f.write(b'\x89PNG\r\n\x1a\n garbage')
  with pytest.raises(ValueError, match='0001.png: not a readable image'):
    video.load_depth_video(corrupt, source_fps=20)

  mixed = _png_folder(tmp_path / 'mixed', mm)
  cv2.imwrite(os.path.join(mixed, '0002.png'), np.ones((4, 4), np.uint16))
  with pytest.raises(ValueError, match='0002.png: shape/dtype'):
    video.load_depth_video(mixed, source_fps=20)
  mixed_dtype = _png_folder(tmp_path / 'mixed_dtype', mm)
  cv2.imwrite(os.path.join(mixed_dtype, '0002.png'), np.ones((6, 5), np.uint8))
  with pytest.raises(ValueError, match='0002.png: shape/dtype'):
    video.load_depth_video(mixed_dtype, source_fps=20)

  blank = mm.copy()
  blank[1] = 0
  folder = _png_folder(tmp_path / 'blank', blank)
  with pytest.raises(ValueError, match='0001.png has no valid pixel'):
    video.load_depth_video(folder, source_fps=20)

  cases = {
    'nan.npy': (np.where(np.arange(3)[:, None, None] == 2, np.nan, 1.0), 'NaN/inf'),
    'inf.npy': (np.full((2, 3, 3), np.inf), 'NaN/inf'),
    'neg.npy': (np.full((2, 3, 3), -1.0), 'negative depth'),
    'mm.npy': (np.full((2, 3, 3), 1500.0), 'looks like millimetres'),
    'rank.npy': (np.ones((3, 3)), r'must be \(T, H, W\)'),
    'rank4.npy': (np.ones((2, 3, 3, 1)), r'must be \(T, H, W\)'),
  }
  for name, (arr, msg) in cases.items():
    np.save(tmp_path / name, arr)
    with pytest.raises(ValueError, match=f'{name}: .*{msg}'):
      video.load_depth_video(str(tmp_path / name), source_fps=20)
  (tmp_path / 'bad.npy').write_bytes(b'not numpy')
  with pytest.raises(ValueError, match='bad.npy: not a readable NumPy file'):
    video.load_depth_video(str(tmp_path / 'bad.npy'), source_fps=20)
  (tmp_path / 'x.txt').write_text('hi')
  with pytest.raises(ValueError, match='x.txt: unknown format'):
    video.load_depth_video(str(tmp_path / 'x.txt'))
  (tmp_path / 'broken.mp4').write_bytes(b'\x00' * 100)
  with pytest.raises(ValueError, match='broken.mp4'):
    video.load_depth_video(str(tmp_path / 'broken.mp4'), source_fps=20)


def test_frame_names_natural_order_and_non_frames_skipped(tmp_path):
  folder = tmp_path / 'rec'
  folder.mkdir()
  for t in range(1, 11):  # 1.png ... 10.png: lexical order would put 10 second
    cv2.imwrite(str(folder / f'{t}.png'), np.full((4, 4), 1000 + t, np.uint16))
  for extra in ('preview.png', 'mask.png', 'mask_0001.png', 'rgb_0001.png'):
    cv2.imwrite(str(folder / extra), np.full((4, 4), 7, np.uint16))
  (folder / 'notes.txt').write_text('not a frame')
  out = video.load_depth_video(str(folder), source_fps=20, fps=None, size=None)
  np.testing.assert_allclose(
    out.depth[:, 0, 0], 1.0 + 0.001 * np.arange(1, 11), atol=1e-6
  )
  assert video_files.frame_files(str(folder))[:3] == ['1.png', '2.png', '3.png']
  clip = video.load_depth_video(
    str(folder), source_fps=20, fps=None, size=None, start=4
  )
  assert clip.depth.shape[0] == 6 and abs(clip.depth[0, 0, 0] - 1.005) < 1e-6
  only_ten = video.load_depth_video(
    str(folder), source_fps=20, fps=None, size=None, pattern='1*.png'
  )
  assert only_ten.depth.shape[0] == 2  # 1.png and 10.png
  with pytest.raises(ValueError, match='start 10 but only 10 frames'):
    video.load_depth_video(str(folder), source_fps=20, start=10)


def test_depth_units_and_frame_rate_are_checked(tmp_path):
  folder = tmp_path / 'tum'
  folder.mkdir()
  for t in range(3):  # 1.5 m in TUM's 5000 units per metre
    cv2.imwrite(str(folder / f'{t}.png'), np.full((4, 4), 7500, np.uint16))
  with pytest.raises(ValueError, match=r'nearest surfaces lie at 7.5 m .*depth_scale'):
    video.load_depth_video(str(folder), source_fps=20)
  out = video.load_depth_video(
    str(folder), source_fps=20, depth_scale=0.0002, size=None
  )
  np.testing.assert_allclose(out.depth, 1.5, atol=1e-6)
  (folder / 'fps.txt').write_text('1e-9')
  with pytest.raises(ValueError, match=r'fps.txt: fps must be a number in \[1, 1000\]'):
    video.load_depth_video(str(folder), depth_scale=0.0002)
  with pytest.raises(ValueError, match='depth_scale must be'):
    video.load_depth_video(str(folder), source_fps=20, depth_scale=0.0)


def _returns_within(fn, timeout: float = 10.0):
  """fn()'s error in a daemon thread: one that blocks (open() on a FIFO)
  fails the test instead of hanging it."""
  import threading  # noqa: PLC0415

  out = {}

  def target():
    try:
      fn()
    except ValueError as e:
      out['error'] = str(e)

  t = threading.Thread(target=target, daemon=True)
  t.start()
  t.join(timeout)
  assert not t.is_alive(), f'blocked for {timeout} s'
  return out.get('error', '')


def test_a_fifo_named_like_a_frame_is_refused_by_name(tmp_path):
  folder = tmp_path / 'f'
  _png_folder(folder, (_frames(t=6) * 1000).astype(np.uint16))
  os.mkfifo(folder / '0006.png')
  msg = _returns_within(lambda: video.load_depth_video(str(folder), source_fps=20))
  assert msg.startswith(str(folder / '0006.png')) and 'FIFO' in msg
  msg = _returns_within(lambda: video_files.read_header(str(folder)))
  assert 'FIFO' in msg
  # A FIFO as the recording itself, and as the fps.txt beside frames.
  os.mkfifo(tmp_path / 'rec.npy')
  msg = _returns_within(lambda: video.load_depth_video(str(tmp_path / 'rec.npy')))
  assert msg.startswith(str(tmp_path / 'rec.npy')) and 'FIFO' in msg
  os.remove(folder / '0006.png')
  os.mkfifo(folder / 'fps.txt')
  msg = _returns_within(lambda: video.load_depth_video(str(folder)))
  assert msg.startswith(str(folder / 'fps.txt')) and 'FIFO' in msg
