"""Tests for experiments.generate_dataset: smoke sweep, resume, invalid worlds."""

import dataclasses
import json
import os
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import physsim
from experiments.pipeline import datasets as gd
from physsim import dataset

pytestmark = pytest.mark.slow  # dataset sweeps simulated and rendered

# A smoke sweep on the MuJoCo C backend (MJX compiles for ~90 s on this CPU).
_SMOKE = dataclasses.replace(gd.PRESETS['smoke'], backend='c', workers=1)
# Depth where the cloth is can only lie between the nearest and farthest camera
# distance allowed by the pose ranges, give or take the cloth's extent.
_DEPTH_BOUNDS_M = (0.5, 4.0)


def _mtimes(root):
  return {
    p: os.path.getmtime(os.path.join(p, 'meta.json'))
    for p in dataset.finished_sequences(root)
  }


def test_smoke_sweep_then_resume(tmp_path):
  root = str(tmp_path / 'ds')
  s = gd.run(_SMOKE, root)
  n = len(_SMOKE.materials) * _SMOKE.sequences
  assert s['sequences_written'] == n
  assert os.path.isfile(os.path.join(root, 'summary.json'))
  for m in _SMOKE.materials:
    assert os.path.isfile(os.path.join(root, f'montage_{m}.png'))
  ds = dataset.open_dataset(root)
  assert len(ds.rows) == n and len({r['label'] for r in ds.rows}) == n
  for r in ds.rows:
    space = physsim.search_space(r['material'])
    p = physsim.params.make(r['bending_scale'], r['wind_speed'], r['area_weight'])
    np.testing.assert_allclose(
      [r['u_bending_scale'], r['u_wind_speed'], r['u_area_weight']],
      physsim.to_unit(p, space),
      atol=1e-12,
    )
  # parameters are the seeded per-material draw
  first = ds.filter('gray_interlock').rows
  ref = gd.material_params(_SMOKE, 'gray_interlock')
  np.testing.assert_array_equal([r['bending_scale'] for r in first], ref.bending_scale)
  seq = dataset.read_sequence(ds.path(first[1]))
  assert seq.depth.shape == (2, 4, 32, 32)
  hit = seq.depth[seq.depth > 0]
  assert hit.size > 0
  assert _DEPTH_BOUNDS_M[0] < hit.min() and hit.max() < _DEPTH_BOUNDS_M[1]
  assert len(seq.meta['extrinsics']) == 2 and seq.meta['fps'] == 20.0
  arr = dataset.load_training_arrays(root, 'black_denim')
  assert arr.images.shape == (2 * 2 * 4, 32, 32)

  # Interrupt: one sequence gone, a half-written tmp folder left behind.
  gone = ds.path(first[1])
  before = seq.depth
  shutil.rmtree(gone)
  tmp = os.path.join(root, 'gray_interlock', '.tmp-0001-abcd1234')
  os.makedirs(os.path.join(tmp, 'cam0'))
  kept = _mtimes(root)
  # Montages: drawn again where a sequence was written, else kept as they are
  # (marked here, so that a redraw shows).
  montage = {m: os.path.join(root, f'montage_{m}.png') for m in _SMOKE.materials}
  for path in montage.values():
    with open(path, 'wb') as f:
      f.write(b'kept')
  s2 = gd.run(_SMOKE, root)
  with open(montage['gray_interlock'], 'rb') as f:
    assert f.read(8) == b'\x89PNG\r\n\x1a\n'  # a sequence written: redrawn
  with open(montage['black_denim'], 'rb') as f:
    assert f.read() == b'kept'  # nothing written: not drawn again
  assert s2['montages']['black_denim'] == montage['black_denim']
  assert s2['sequences_written'] == 1
  assert s2['counts']['gray_interlock'] == {
    'existing': 1,
    'written': 1,
    'valid': 2,
    'invalid': 0,
  }
  after = _mtimes(root)
  assert all(after[p] == t for p, t in kept.items())  # not rewritten
  assert gone in after and not os.path.exists(tmp)
  # same seed, same batch: the rewritten sequence is the same, bit for bit
  np.testing.assert_array_equal(dataset.read_sequence(gone).depth, before)

  with pytest.raises(ValueError, match='different config.*frames'):
    gd.run(dataclasses.replace(_SMOKE, frames=5), root)


def test_recordings_of_another_physics(tmp_path):
  """``physics='mismatched'`` (physsim.mismatch.WORLD) draws the same
  parameters and cameras, simulates another world (other frames), says so in
  each sequence's meta, and is another dataset: an 'own' workdir refuses it."""
  own_root, other_root = str(tmp_path / 'own'), str(tmp_path / 'other')
  one = dataclasses.replace(_SMOKE, materials=('gray_interlock',), sequences=1,
                            batch_size=1, cameras=1)  # fmt: skip
  other = dataclasses.replace(one, physics='mismatched')
  gd.run(one, own_root)
  gd.run(other, other_root)
  a, b = (dataset.open_dataset(r) for r in (own_root, other_root))
  ra, rb = a.rows[0], b.rows[0]
  assert (
    ra['wind_speed'] == rb['wind_speed'] and ra['bending_scale'] == rb['bending_scale']
  )
  sa, sb = dataset.read_sequence(a.path(ra)), dataset.read_sequence(b.path(rb))
  assert sa.meta['extrinsics'] == sb.meta['extrinsics']
  assert sb.meta['physics'] == 'mismatched' and 'physics' not in sa.meta
  both = (sa.depth > 0) & (sb.depth > 0)
  assert np.abs(sa.depth - sb.depth)[both].max() > 1e-3  # metres: another world
  with pytest.raises(ValueError, match='different config.*physics'):
    gd.run(other, own_root)


def test_invalid_world_recorded_without_frames(tmp_path, monkeypatch):
  real = physsim.simulate

  def first_blows_up(*a, **k):
    out = real(*a, **k)
    valid = out.valid.copy()
    valid[0] = False
    pos = out.positions.copy()
    pos[0] = np.nan
    return out._replace(valid=valid, positions=pos)

  monkeypatch.setattr(gd.physsim, 'simulate', first_blows_up)
  cfg = dataclasses.replace(_SMOKE, materials=('red_violet',))
  root = str(tmp_path / 'ds')
  s = gd.run(cfg, root)
  assert s['counts']['red_violet']['invalid'] == 1
  ds = dataset.open_dataset(root)
  bad = ds.filter(valid=False).rows
  assert [r['seq_id'] for r in bad] == ['0000']
  path = ds.path(bad[0])
  assert sorted(os.listdir(path)) == ['meta.json']
  with open(os.path.join(path, 'meta.json')) as f:
    assert json.load(f)['has_depth'] is False
  arr = dataset.load_training_arrays(root, 'red_violet')
  assert set(arr.seq_ids) == {'0001'}


def test_flags_override_preset():
  from experiments import generate_dataset as script
  from experiments.pipeline import cli

  argv = ['prog', '--preset=smoke', '--frames=7', '--materials=red_violet']
  args = cli.parse(script.Args, script.PRESETS, argv)
  cfg = args.sweep
  assert cfg.frames == 7 and cfg.materials == ('red_violet',)
  assert cfg.cameras == gd.PRESETS['smoke'].cameras
  assert args.out == 'data/sim'  # a field of the script, not of the sweep


def test_rgb_and_sensor_noise(tmp_path):
  cfg = dataclasses.replace(
    _SMOKE, materials=('pink_nylon',), sequences=1, batch_size=1, rgb=True, noise=True
  )
  clean_cfg = dataclasses.replace(cfg, rgb=False, noise=False)
  gd.run(cfg, str(tmp_path / 'noisy'))
  gd.run(clean_cfg, str(tmp_path / 'clean'))
  noisy = dataset.read_sequence(str(tmp_path / 'noisy' / 'pink_nylon' / '0000'))
  clean = dataset.read_sequence(str(tmp_path / 'clean' / 'pink_nylon' / '0000'))
  assert noisy.rgb.shape == (*noisy.depth.shape, 3) and noisy.rgb.max() > 0
  assert clean.rgb is None
  # shaded in the fabric's colour: each channel at most (lit fully) its colour
  color = np.asarray(physsim.FABRIC_COLORS['pink_nylon'])
  assert noisy.meta['rgb_color'] == list(color)
  peak = noisy.rgb.reshape(-1, 3).max(axis=0)
  assert np.all(peak <= np.round(255 * color)) and peak[0] > peak[1] > 0
  # noise only removes or perturbs pixels the clean render hit
  assert not np.any((noisy.depth > 0) & (clean.depth == 0))
  both = (noisy.depth > 0) & (clean.depth > 0)
  assert both.any() and np.any(noisy.depth[both] != clean.depth[both])


def test_min_coverage_redraws_only_poorly_framed_cameras(tmp_path):
  # Reference sweep without the rule, then a threshold between its cameras'
  # coverages: cameras below it get new poses, the rest stay bit for bit.
  cfg = dataclasses.replace(_SMOKE, materials=('gray_interlock',))
  gd.run(cfg, str(tmp_path / 'a'))
  seqs = ('0000', '0001')
  ref = {
    s: dataset.read_sequence(str(tmp_path / 'a' / 'gray_interlock' / s)) for s in seqs
  }
  cover = {s: (r.depth > 0).mean(axis=(-1, -2)).min(axis=-1) for s, r in ref.items()}
  flat = np.sort(np.concatenate(list(cover.values())))
  assert flat[0] < flat[-1], 'need cameras of different coverage'
  threshold = float((flat[0] + flat[1]) / 2)  # only the worst camera is below
  draws = 8
  s = gd.run(
    dataclasses.replace(cfg, min_coverage=threshold, pose_draws=draws),
    str(tmp_path / 'b'),
  )
  with open(tmp_path / 'a' / 'dataset.json') as f:
    assert 'min_coverage' not in json.load(f)['config']  # old datasets still resume
  redrawn = 0
  for seq in seqs:
    new = dataset.read_sequence(str(tmp_path / 'b' / 'gray_interlock' / seq))
    got = (new.depth > 0).mean(axis=(-1, -2)).min(axis=-1)
    np.testing.assert_allclose(new.meta['coverage_min'], got, atol=1e-5)
    for c in range(cfg.cameras):
      if cover[seq][c] >= threshold:
        assert new.meta['pose_draws'][c] == 1
        assert new.meta['extrinsics'][c] == ref[seq].meta['extrinsics'][c]
        np.testing.assert_array_equal(new.depth[c], ref[seq].depth[c])
      else:
        redrawn += 1
        assert 1 < new.meta['pose_draws'][c] <= draws
        assert got[c] >= threshold or new.meta['pose_draws'][c] == draws
        assert got[c] > cover[seq][c]  # the best draw is kept
        assert new.meta['extrinsics'][c] != ref[seq].meta['extrinsics'][c]
  assert redrawn == 1 and s['cameras_redrawn'] == 1


def test_rendering_split_over_devices_and_chunks_equals_one_call():
  # The sweep renders its batch over both CPU devices (conftest) in chunks that
  # fit memory; sensor noise is drawn per world, so neither changes a frame.
  config = dataclasses.replace(_SMOKE, noise=True, rgb=True, resolution=24, frames=3)
  mesh = physsim.square(6)
  intr = physsim.Intrinsics(width=24, height=24)
  b = 5
  rng = np.random.default_rng(0)
  positions = np.broadcast_to(mesh.vertices, (b, 3, *mesh.vertices.shape)).copy()
  positions[..., 1] += 0.05 * rng.standard_normal(positions.shape[:-1])
  positions = positions.astype(np.float32)
  poses = jax.vmap(lambda k: physsim.sample_poses(k, 2))(
    jax.random.split(jax.random.key(1), b)
  )
  keys = jax.random.split(jax.random.key(2), b)
  colors = jnp.full((b, 3), 0.5)
  whole = gd._renderer(mesh.faces, intr, config)(positions, poses, keys, colors)
  split = gd._chunked(
    gd._renderer(mesh.faces, intr, config, physsim.devices.world_mesh()), 2
  )(positions, poses, np.asarray(jax.random.key_data(keys)), colors)  # host data
  assert split[0].shape == (b, 2, 3, 24, 24) and split[1].shape == (b, 2, 3, 24, 24, 3)
  np.testing.assert_allclose(split[0], np.asarray(whole[0]), atol=1e-6)
  np.testing.assert_array_equal(split[1], np.asarray(whole[1]))
  assert gd._render_chunk(config, 30, 2) % 2 == 0


def _sequences(root):
  """{(material, seq): (depth, meta without paths)} of a finished sweep."""
  out = {}
  for p in dataset.finished_sequences(root):
    s = dataset.read_sequence(p)
    key = tuple(os.path.normpath(p).split(os.sep)[-2:])
    out[key] = (s.depth, s.meta)
  return out


def test_batches_per_call_leave_the_recordings_as_they_are(tmp_path, monkeypatch):
  # A device call takes one batch per device (on a GPU: so that a batch under
  # a step's fixed cost still splits); every world keeps its batch's gusts,
  # noise and cameras, so two batches a call (the last call padded) give the
  # recordings of one a call, to the bit, and a resume of a call with one
  # batch left writes that batch as it was.
  config = dataclasses.replace(
    _SMOKE, sequences=3, gust_intensity=0.3, noise=True, batch_size=2,
    min_coverage=0.25, pose_draws=5,
  )  # fmt: skip  # 6 sequences: batches 0-2, calls [0, 1] and [2] (padded);
  # cameras drawn again (rendered alone) in most of them
  one = str(tmp_path / 'one')
  gd.run(config, one)
  per_call = []
  monkeypatch.setattr(
    gd, '_batches_per_call', lambda backend, n: per_call.append(n) or 2
  )
  two = str(tmp_path / 'two')
  gd.run(config, two)
  a, b = _sequences(one), _sequences(two)
  assert len(a) == 6 and a.keys() == b.keys()
  for k in a:
    np.testing.assert_array_equal(a[k][0], b[k][0], err_msg=str(k))
    assert a[k][1]['extrinsics'] == b[k][1]['extrinsics']
    assert a[k][1]['pose_draws'] == b[k][1]['pose_draws']
  assert sum(max(a[k][1]['pose_draws']) > 1 for k in a) >= 3
  # batch 1 (gray_interlock 0002, black_denim 0000) loses one: call 0 holds it alone
  gone = os.path.join(two, 'gray_interlock', '0002')
  shutil.rmtree(gone)
  s = gd.run(config, two)
  assert sum(c['written'] for c in s['counts'].values()) == 1
  np.testing.assert_array_equal(
    dataset.read_sequence(gone).depth, a[('gray_interlock', '0002')][0]
  )
  assert per_call  # the seam was asked
