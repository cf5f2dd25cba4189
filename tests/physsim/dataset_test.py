"""Tests for physsim.dataset: round trips, atomic writes, index and loader."""

import os

import cv2
import numpy as np
import pytest

from physsim import dataset, params

# Frames stored as whole millimetres must come back as the same float32 metres.
_ROUNDING_TOLERANCE_M = 0.5e-3  # arbitrary metres land within half a mm


def _row(seq_id, label=0, material='gray_interlock', valid=True, c=2, t=3):
  p = params.make(2.0, 3.0, params.search_space(material).center().area_weight)
  return dataset.make_row(
    seq_id,
    material,
    label,
    p,
    params.search_space(material),
    valid=valid,
    n_cameras=c,
    n_frames=t,
  )


def _depth(rng, c=2, t=3, h=8, w=6):
  mm = rng.integers(0, 65536, size=(c, t, h, w)).astype(np.uint16)
  mm[..., 0, 0] = 0  # an invalid pixel in every frame
  return mm


def test_mm_conversion_is_bit_exact_for_every_uint16():
  mm = np.arange(65536, dtype=np.uint16)
  metres = dataset.mm_to_depth(mm)
  assert metres.dtype == np.float32
  np.testing.assert_array_equal(dataset.depth_to_mm(metres), mm)


def test_conversion_rounds_clips_and_invalidates():
  d = np.array([0.0, -1.0, np.nan, np.inf, 1.2344, 1.2346, 70.0, 0.0004])
  np.testing.assert_array_equal(
    dataset.depth_to_mm(d), [0, 0, 0, 0, 1234, 1235, 65535, 0]
  )
  x = np.random.default_rng(0).uniform(0.3, 5.0, 1000)
  back = dataset.mm_to_depth(dataset.depth_to_mm(x))
  assert np.max(np.abs(back - x)) <= _ROUNDING_TOLERANCE_M + 1e-7


def test_write_read_round_trip(tmp_path):
  rng = np.random.default_rng(1)
  mm = _depth(rng)
  rgb = rng.integers(0, 256, size=(*mm.shape, 3)).astype(np.uint8)
  meta = {**_row('0000'), 'fps': 20.0, 'intrinsics': {'fx': 1.0}}
  path = dataset.write_sequence(str(tmp_path), meta, dataset.mm_to_depth(mm), rgb)
  assert path == os.path.join(tmp_path, 'gray_interlock', '0000')
  # what is on disk is 16-bit mm that OpenCV reads back unchanged
  png = cv2.imread(os.path.join(path, 'cam1', '0002.png'), cv2.IMREAD_UNCHANGED)
  assert png.dtype == np.uint16
  np.testing.assert_array_equal(png, mm[1, 2])
  seq = dataset.read_sequence(path)
  np.testing.assert_array_equal(dataset.depth_to_mm(seq.depth), mm)
  np.testing.assert_array_equal(seq.depth, dataset.mm_to_depth(mm))
  np.testing.assert_array_equal(seq.rgb, rgb)
  assert seq.meta['fps'] == 20.0 and seq.meta['height'] == 8
  sub = dataset.read_sequence(path, cameras=[1], frames=[2, 0], rgb=False)
  np.testing.assert_array_equal(sub.depth[0, 0], seq.depth[1, 2])
  assert sub.rgb is None
  with pytest.raises(ValueError, match='already written'):
    dataset.write_sequence(str(tmp_path), meta, dataset.mm_to_depth(mm))


def test_failed_write_leaves_no_sequence(tmp_path, monkeypatch):
  rng = np.random.default_rng(2)
  depth = dataset.mm_to_depth(_depth(rng))
  real = dataset.imwrite
  calls = []

  def flaky(path, image, *a):
    calls.append(path)
    if len(calls) > 3:
      raise OSError('disk full')
    return real(path, image, *a)

  monkeypatch.setattr(dataset, 'imwrite', flaky)
  with pytest.raises(OSError, match='disk full'):
    dataset.write_sequence(str(tmp_path), _row('0000'), depth)
  assert len(calls) == 4
  parent = tmp_path / 'gray_interlock'
  assert list(parent.iterdir()) == []  # no final folder, tmp removed
  assert not dataset.is_complete(str(tmp_path), 'gray_interlock', '0000')
  # a previous finished version survives a failed overwrite
  monkeypatch.setattr(dataset, 'imwrite', real)
  dataset.write_sequence(str(tmp_path), _row('0000'), depth)
  calls.clear()
  monkeypatch.setattr(dataset, 'imwrite', flaky)
  with pytest.raises(OSError):
    dataset.write_sequence(str(tmp_path), _row('0000'), depth * 2, overwrite=True)
  np.testing.assert_array_equal(
    dataset.read_sequence(str(parent / '0000')).depth, depth
  )
  assert [p.name for p in parent.iterdir()] == ['0000']


def test_index_rebuild_open_filter_and_tmp_cleanup(tmp_path):
  rng = np.random.default_rng(3)
  root = str(tmp_path)
  dataset.write_dataset_info(root, seed=7, config={'a': 1})
  for i, m in enumerate(['gray_interlock', 'black_denim', 'gray_interlock']):
    dataset.write_sequence(
      root, _row(f'{i:04d}', i, m), dataset.mm_to_depth(_depth(rng))
    )
  bad = _row('0003', 3, 'black_denim', valid=False)
  dataset.write_sequence(root, bad, None)
  crash = tmp_path / 'black_denim' / '.tmp-0004-deadbeef'
  (crash / 'cam0').mkdir(parents=True)
  (crash / 'cam0' / '0000.png').write_bytes(b'half')
  rows = dataset.rebuild_index(root)
  assert len(rows) == 4
  ds = dataset.open_dataset(root)
  assert ds.info['seed'] == 7 and len(ds.rows) == 4
  assert ds.materials == ('black_denim', 'gray_interlock')
  assert [r['seq_id'] for r in ds.filter('gray_interlock').rows] == ['0000', '0002']
  assert [r['seq_id'] for r in ds.filter(valid=False).rows] == ['0003']
  r = ds.filter('gray_interlock').rows[0]
  assert r['bending_scale'] == 2.0 and r['valid'] is True and r['n_frames'] == 3
  space = params.search_space('gray_interlock')
  u = params.to_unit(params.make(2.0, 3.0, r['area_weight']), space)
  np.testing.assert_array_equal(
    [r['u_bending_scale'], r['u_wind_speed'], r['u_area_weight']], u
  )
  with pytest.raises(ValueError, match='no frames'):
    dataset.read_sequence(ds.path(ds.filter(valid=False).rows[0]))
  assert dataset.clean_tmp(root) == [str(crash)]
  assert not crash.exists()


def test_training_arrays(tmp_path):
  rng = np.random.default_rng(4)
  root = str(tmp_path)
  seqs = {}
  for i in range(3):
    mm = _depth(rng)
    seqs[i] = dataset.mm_to_depth(mm)
    dataset.write_sequence(root, _row(f'{i:04d}', 10 + i), seqs[i])
  dataset.write_sequence(root, _row('0003', 13, valid=False), None)
  dataset.rebuild_index(root)
  arr = dataset.load_training_arrays(root, 'gray_interlock')
  assert arr.images.shape == (3 * 2 * 3, 8, 6)
  np.testing.assert_array_equal(np.unique(arr.labels), [10, 11, 12])
  k = 1 * 6 + 1 * 3 + 2  # sequence 1, camera 1, frame 2
  assert (arr.labels[k], arr.seq_ids[k], arr.cameras[k], arr.frames[k]) == (
    11,
    '0001',
    1,
    2,
  )
  np.testing.assert_array_equal(arr.images[k], seqs[1][1, 2])
  assert arr.params.shape == (18, 3) and arr.unit_params.shape == (18, 3)
  small = dataset.load_training_arrays(root, 'gray_interlock', size=(4, 3), frames=[0])
  assert small.images.shape == (6, 4, 3)
  # nearest neighbour: every output value is one of the input values
  assert np.isin(small.images[0], seqs[0][0, 0]).all()
  with pytest.raises(ValueError, match='no valid sequences'):
    dataset.load_training_arrays(root, 'black_denim')


def test_reader_errors_name_the_file(tmp_path):
  rng = np.random.default_rng(5)
  path = dataset.write_sequence(
    str(tmp_path), _row('0000'), dataset.mm_to_depth(_depth(rng))
  )
  frame = os.path.join(path, 'cam1', '0001.png')
  with open(frame, 'wb') as f:
    f.write(b'\x89PNG not really')
  with pytest.raises(ValueError, match='cam1/0001.png'):
    dataset.read_sequence(path)
  os.remove(frame)
  with pytest.raises(ValueError, match='cam1/0001.png: file not found'):
    dataset.read_sequence(path)
  with pytest.raises(ValueError, match='index.csv'):
    dataset.open_dataset(str(tmp_path))
  with pytest.raises(ValueError, match='depth must be'):
    dataset.write_sequence(str(tmp_path), _row('0001'), np.zeros((2, 4, 8, 6)))
  with pytest.raises(ValueError, match='folder name'):
    _row('a/b')


def test_a_full_disk_is_said_as_such_naming_the_file(tmp_path, monkeypatch):
  """cv2.imwrite only returns False on a full disk ("OpenCV could not write
  the image"); the image is encoded by OpenCV and written by Python."""
  import builtins  # noqa: PLC0415
  import errno  # noqa: PLC0415

  def full(path, mode='r', *a, **kw):
    if 'w' in mode:
      raise OSError(errno.ENOSPC, 'No space left on device', str(path))
    return builtins.open(path, mode, *a, **kw)

  monkeypatch.setattr(dataset, 'open', full, raising=False)
  image = np.zeros((4, 4), np.uint16)
  for write in (
    lambda p: dataset.imwrite(p, image),
    lambda p: dataset.write_json_atomic(p, {'a': 1}),
  ):
    path = str(tmp_path / 'x.png')
    with pytest.raises(ValueError, match=r'^disk full: .*x.png \(No space'):
      write(path)
    assert os.listdir(tmp_path) == []
  monkeypatch.undo()
  dataset.imwrite(str(tmp_path / 'y.png'), image)
  assert cv2.imread(str(tmp_path / 'y.png'), cv2.IMREAD_UNCHANGED).dtype == np.uint16
