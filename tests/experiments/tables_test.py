"""Tests for experiments.tables: summaries and the markdown, on hand-made results."""

import os

import numpy as np
import pytest

from experiments.pipeline import measurements
from experiments.pipeline.objective import EstimateConfig
from experiments.pipeline.recording import Recording
from experiments.studies import table1, tables
from physsim import camera

pytestmark = pytest.mark.slow  # Tables 2 and 3 estimated end to end


def _res(wind, weight, factor, centre=(50.0, 5.0, 2.0)):
  one = lambda w, a, b: {'wind_speed_pct': w, 'area_weight_pct': a, 'bending_factor': b}
  return {
    'errors': {'estimate': one(wind, weight, factor), 'range_centre': one(*centre)}
  }


def test_summary_means_and_failures():
  results = {
    ('physnet_depth', 'fabrics', 'black_denim', '0000'): _res(10.0, 2.0, 2.0),
    ('physnet_depth', 'fabrics', 'black_denim', '0001'): _res(20.0, 4.0, 8.0),
    ('physnet_depth', 'fabrics', 'black_denim', '0002'): {'failed': 'exit 1'},
    ('physnet_depth', 'tshirt', 'tshirt', '0000'): {'failed': 'exit 1'},
  }
  s = tables.summarise(results, ('physnet_depth',))
  d = s[('physnet_depth', 'black_denim')]
  assert (d['n'], d['failed']) == (3, 1)
  assert d['estimate']['wind_speed_pct'] == pytest.approx(15.0)
  assert d['estimate']['area_weight_pct'] == pytest.approx(3.0)
  # factors average geometrically: sqrt(2 * 8) = 4
  assert d['estimate']['bending_factor'] == pytest.approx(4.0)
  assert s[('physnet_depth', 'tshirt')]['estimate'] is None
  md = tables.format_tables(s, ('physnet_depth',))
  assert '| black_denim | 15.0 | 3.0 | x4.00 (1/3 F)' in md
  assert '| tshirt | F | F | F (1/1 F)' in md
  assert '| 5.4 | 5.5 |' in md  # the paper's denim numbers beside ours
  assert 'Table 3: garments' in md


def _estimate(wind, weight, bending=1.0):
  """A finished estimate with truth (3 m/s, 0.2 kg/m^2, bending 1) and no errors
  yet: ``rescore`` computes them."""
  value = lambda v: {'value': v}
  return {
    'material': 'black_denim',
    'bending_matrix_Nm': np.full((3, 5), 1e-5 * bending).tolist(),
    'truth': {'bending_scale': 1.0, 'wind_speed': 3.0, 'area_weight': 0.2},
    'estimate': {
      'bending_scale': value(bending),
      'wind_speed': value(wind),
      'area_weight': value(weight),
    },
  }


def test_overall_means_medians_and_wins_over_the_centre():
  results = {
    ('physnet_depth', 'fabrics', 'black_denim', '0000'): _estimate(3.3, 0.2),
    ('physnet_depth', 'fabrics', 'black_denim', '0001'): _estimate(3.0, 0.22),
    ('physnet_depth', 'fabrics', 'black_denim', '0002'): _estimate(6.0, 0.2, 10),
    ('physnet_depth', 'jeans', 'jeans', '0000'): {'failed': 'exit 1'},
  }
  results = {k: tables.rescore(v) for k, v in results.items()}
  table = tables.overall(results, ('physnet_depth',))
  f = table[('physnet_depth', 'fabrics')]
  assert (f['n'], f['failed']) == (3, 0)
  # wind: 10%, 0%, 100%
  assert f['wind_speed_pct']['mean'] == pytest.approx(110 / 3)
  assert f['wind_speed_pct']['median'] == pytest.approx(10.0)
  # load ratio v^2 / w: 1.21 - 1, 1 - 1 / 1.1, 4 - 1
  assert f['load_ratio_pct']['median'] == pytest.approx(21.0)
  assert f['load_ratio_pct']['mean'] == pytest.approx((21 + 100 / 11 + 300) / 3)
  # bending factors 1, 1, 10: geometric mean 10^(1/3)
  assert f['bending_factor']['mean'] == pytest.approx(10 ** (1 / 3))
  # range centre for denim: 3.5 m/s (16.7% off): the 10% and 0% estimates win
  assert (f['wind_speed_pct']['beats_centre'], f['wind_speed_pct']['of']) == (2, 3)
  assert table[('physnet_depth', 'garments')]['failed'] == 1
  centre = table[('range centre', 'fabrics')]
  assert centre['n'] == 3
  assert centre['wind_speed_pct']['mean'] == pytest.approx(100 * 0.5 / 3)
  md = tables.format_overall(table)
  assert '| physnet_depth | fabrics | 3 | 36.7 / 10.0 |' in md
  assert '| physnet_depth | garments | 1 (1 F) |' in md
  assert ' 2 / ' in md and ' of 3 |' in md


def test_from_json_merges_runs_and_refuses_duplicates(tmp_path):
  depth = {'physnet_depth/fabrics/black_denim/0000': _estimate(3.3, 0.2)}
  rgb = {'sdn_rgb/fabrics/black_denim/0000': _estimate(3.0, 0.2)}
  paths = []
  for name, est in (('depth', depth), ('rgb', rgb), ('again', depth)):
    paths.append(str(tmp_path / f'{name}.json'))
    tables.files.write_json(paths[-1], {'estimates': est})
  merged = tables.from_json(paths[:2])
  assert set(merged) == {
    ('physnet_depth', 'fabrics', 'black_denim', '0000'),
    ('sdn_rgb', 'fabrics', 'black_denim', '0000'),
  }
  err = merged[('physnet_depth', 'fabrics', 'black_denim', '0000')]['errors']
  assert err['estimate']['wind_speed_pct'] == pytest.approx(10.0)
  md = tables.write_report(
    merged, tables.Config(methods=('physnet_depth', 'sdn_rgb')), str(tmp_path / 'w')
  )
  assert '| black_denim | 10.0 | 0.0 | x1.00 | 0.0 | 0.0 | x1.00 |' in md
  assert os.path.isfile(tmp_path / 'w' / 'tables.json')
  with pytest.raises(ValueError, match='also in an earlier file'):
    tables.from_json([paths[0], paths[2]])
  tables.files.write_json(paths[1], {'rows': []})
  with pytest.raises(ValueError, match='not a tables.json'):
    tables.from_json(paths[1:2])


def test_unsupported_method_and_empty_eval(tmp_path):
  with pytest.raises(ValueError, match='supports'):
    tables.run_all(tables.Config(methods=('sdn_thermal',)), str(tmp_path), '', '')
  with pytest.raises(ValueError, match='no recordings'):
    tables.recordings(str(tmp_path))
  assert np.isfinite(tables.PAPER['jeans'][0])


def test_a_method_without_networks_is_a_dash(tmp_path, monkeypatch):
  rec = {
    'set': 'fabrics',
    'fabric': 'black_denim',
    'garment': '',
    'seq_id': '0000',
    'path': 'unused',
  }
  monkeypatch.setattr(tables, 'recordings', lambda root: [rec])
  models = str(tmp_path / 'models')
  only = table1.run_dir(models, 'sdn', 'rgb', 'simulation', 'black_denim')
  os.makedirs(only)
  open(os.path.join(only, 'config.json'), 'w').close()
  ran = []

  def batched(jobs, *args):
    ran.extend(method for _, method in jobs)
    return {
      (method, r['set'], r['fabric'], r['seq_id']): _res(10.0, 2.0, 2.0)
      for r, method in jobs
    }

  monkeypatch.setattr(tables, '_batched', batched)
  assert tables.METHODS == ('physnet_depth', 'physnet_rgb', 'sdn_depth', 'sdn_rgb')
  results = tables.run_all(tables.Config(), 'eval', models, str(tmp_path / 'w'))
  assert ran == ['sdn_rgb']
  md = tables.format_tables(tables.summarise(results, tables.METHODS), tables.METHODS)
  row = next(line for line in md.splitlines() if line.startswith('| black_denim'))
  assert row.startswith(
    '| black_denim | - | - | - | - | - | - | - | - | - | 10.0 | 2.0'
  )


def test_shards_split_the_pending_estimates_and_run_them_once(tmp_path, monkeypatch):
  recs = [
    {'set': 'fabrics', 'fabric': 'black_denim', 'garment': '', 'seq_id': f'{i:04d}',
     'path': f'rec{i}'}
    for i in range(5)
  ]  # fmt: skip
  monkeypatch.setattr(tables, 'recordings', lambda root: recs)
  models = str(tmp_path / 'models')
  net = table1.run_dir(models, 'physnet', 'depth', 'simulation', 'black_denim')
  os.makedirs(net)
  open(os.path.join(net, 'config.json'), 'w').close()
  workdir = str(tmp_path / 'w')
  # One estimate already finished: it is read back, not rerun.
  done = tables._out_dir(workdir, recs[0], 'physnet_depth')
  os.makedirs(done)
  tables.files.write_json(os.path.join(done, 'estimate.json'), _res(1.0, 1.0, 1.0))
  calls = []

  def batched(jobs, models_, workdir_, config):
    calls.append([r['seq_id'] for r, _ in jobs])
    return {tables._key(r, m): _res(10.0, 2.0, 2.0) for r, m in jobs}

  monkeypatch.setattr(tables, '_batched', batched)
  seen = set()
  config = tables.Config(methods=('physnet_depth',))
  for shard in range(2):  # two processes' shares
    monkeypatch.setattr(tables.distributed, 'process', lambda s=shard: (s, 2))
    results = tables.run_all(config, 'eval', models, workdir)
    assert results[('physnet_depth', 'fabrics', 'black_denim', '0000')] == _res(
      1.0, 1.0, 1.0
    )
    seen.update(calls[-1])
  # contiguous halves of the job list (finished ones skipped): few meshes each
  assert calls == [['0001', '0002'], ['0003', '0004']]
  assert seen == {'0001', '0002', '0003', '0004'}
  # --report_only reads what has finished and runs nothing.
  fresh = str(tmp_path / 'fresh')
  report = tables.Config(methods=('physnet_depth',), report_only=True)
  assert tables.run_all(report, 'eval', models, fresh) == {}
  assert len(calls) == 2


def test_batched_runs_real_estimates(tmp_path):
  # The lockstep path end to end on the estimate tests' hand-made network and
  # simulated recording (tiny preset, MuJoCo C backend).
  from tests.experiments import estimate_fixtures as fx

  models = str(tmp_path / 'models')
  model_dir = table1.run_dir(models, 'physnet', 'depth', 'simulation', fx.MATERIAL)
  fx.write_hand_made_model(model_dir)
  seq = fx.write_recording(str(tmp_path), fx.TRUTH)
  rec = {'set': 'fabrics', 'fabric': fx.MATERIAL, 'garment': '', 'seq_id': '0000',
         'path': seq}  # fmt: skip
  bad = dict(rec, seq_id='0001', path=str(tmp_path / 'missing'))
  from experiments.pipeline import objective

  config = tables.Config(estimate=objective.PRESETS['smoke'].replace(backend='c'))
  out = tables._batched(
    [(rec, 'physnet_depth'), (bad, 'physnet_depth')], models, str(tmp_path / 'w'),
    config,
  )  # fmt: skip
  good = out[tables._key(rec, 'physnet_depth')]
  assert good['truth'] == fx.TRUTH and good['recordings_in_batch'] == 1
  assert 'missing' in out[tables._key(bad, 'physnet_depth')]['failed']


def test_the_shape_method_estimates_without_a_network(tmp_path):
  # --methods=shape: no models folder at all; every recording is estimated with
  # the shape distance from its depth frames at shape_image_size.
  from experiments.pipeline import objective
  from tests.experiments import estimate_fixtures as fx

  seq = fx.write_recording(str(tmp_path), fx.TRUTH)
  rec = {'set': 'fabrics', 'fabric': fx.MATERIAL, 'garment': '', 'seq_id': '0000',
         'path': seq}  # fmt: skip
  config = tables.Config(
    methods=('shape',), shape_image_size=fx.SIZE,
    estimate=objective.PRESETS['smoke'].replace(backend='c'),
  )  # fmt: skip
  missing = str(tmp_path / 'no_models')
  got = tables._batched([(rec, 'shape')], missing, str(tmp_path / 'w'), config)
  res = got[tables._key(rec, 'shape')]
  assert 'failed' not in res, res
  assert res['config']['distance'] == 'shape' and res['truth'] == fx.TRUTH
  assert not os.path.exists(missing)
  md = tables.write_report(got, config, str(tmp_path / 'r'))
  assert '| shape |' in md
  with pytest.raises(ValueError, match='shape_image_size=8: need 16-1024'):
    tables.Config(shape_image_size=8)


def test_simulated_wind_reading_is_the_searchs_prior(tmp_path):
  # --wind_reading_sd: the recording is estimated with an anemometer reading
  # drawn around its truth as its prior, the reading the calibration's post-hoc
  # 'known wind' mode draws for the same seed and recording number.
  from experiments.pipeline import objective
  from tests.experiments import estimate_fixtures as fx

  models = str(tmp_path / 'models')
  fx.write_hand_made_model(
    table1.run_dir(models, 'physnet', 'depth', 'simulation', fx.MATERIAL)
  )
  seq = fx.write_recording(str(tmp_path), fx.TRUTH)
  rec = {'set': 'fabrics', 'fabric': fx.MATERIAL, 'garment': '', 'seq_id': '0003',
         'path': seq}  # fmt: skip
  config = tables.Config(
    estimate=objective.PRESETS['smoke'].replace(backend='c'),
    wind_reading_sd=0.02, reading_seed=5,
  )  # fmt: skip
  out = tables._batched([(rec, 'physnet_depth')], models, str(tmp_path / 'w'), config)
  got = out[tables._key(rec, 'physnet_depth')]
  want = measurements.simulated_reading('wind_speed', fx.TRUTH, 0.02, 5, 3)
  assert got['config']['measured'] == want.to_dict()
  assert want.wind_speed != fx.TRUTH['wind_speed']
  assert want.wind_speed_sd == pytest.approx(0.02 * fx.TRUTH['wind_speed'])
  # The posterior keeps the reading: its 90% interval holds it and is narrower
  # than one cell of the smoke grid's wind axis plus the reading's +-1.645 sd
  # (the video alone leaves most of the 1-6 m/s range).
  lo, hi = got['estimate']['wind_speed']['interval_90']
  cell = 5.0 / config.estimate.search.posterior_grid[1]
  assert lo <= want.wind_speed <= hi
  assert hi - lo < cell + 2 * 1.645 * want.wind_speed_sd + 1e-9
  md = tables.write_report({tables._key(rec, 'physnet_depth'): got}, config,
                           str(tmp_path / 'r'))  # fmt: skip
  assert md.startswith('Every estimate with a simulated wind reading (2% relative')


def test_simulated_readings_are_seeded_and_unbiased():

  truth = {'wind_speed': 3.0, 'area_weight': 0.2}
  a = measurements.simulated_reading('area_weight', truth, 0.05, 1, 7)
  assert a == measurements.simulated_reading('area_weight', truth, 0.05, 1, 7)
  assert a != measurements.simulated_reading('area_weight', truth, 0.05, 2, 7)
  assert a.wind_speed == 0 and a.area_weight_sd == pytest.approx(0.01)
  z = np.array([
    measurements.simulated_reading('wind_speed', truth, 0.02, 0, k).wind_speed
    for k in range(2000)
  ]) / 3.0 - 1.0  # fmt: skip
  # 2000 standard normals times 0.02: mean within 4 standard errors of 0,
  # sd within 5% of 0.02.
  assert abs(z.mean()) < 4 * 0.02 / np.sqrt(2000)
  assert z.std() == pytest.approx(0.02, rel=0.05)
  with pytest.raises(ValueError, match='bending_scale'):
    measurements.simulated_reading('bending_scale', truth, 0.02, 0, 0)
  with pytest.raises(ValueError, match='wind_reading_sd=1.5'):
    tables.Config(wind_reading_sd=1.5)
  with pytest.raises(ValueError, match='one reading at a time'):
    tables.Config(wind_reading_sd=0.02, area_weight_reading_sd=0.02)
  rec = {'path': '/data/x/0001', 'seq_id': '0001'}
  with pytest.raises(ValueError, match='/data/x/0001: a simulated reading needs'):
    tables.simulated_measurement(tables.Config(area_weight_reading_sd=0.02), rec, None)


def test_candidate_landscapes_place_each_candidate_against_the_truth(tmp_path):
  import cv2

  import physsim

  truth = {'bending_scale': 2.0, 'wind_speed': 3.0, 'area_weight': 0.33}
  space = physsim.search_space('black_denim')
  u_truth = np.ravel(np.asarray(physsim.to_unit(physsim.params.make(**truth), space)))
  x = np.stack([u_truth, np.zeros(3), np.ones(3)])
  y = np.array([0.5, 1.0, np.nan])  # the third candidate blew up
  key = ('physnet_depth', 'fabrics', 'black_denim', '0000')
  folder = tmp_path / 'physnet_depth' / 'fabrics' / 'black_denim-0000'
  folder.mkdir(parents=True)
  np.savez(folder / 'bo_state.npz', X=x, Y=y)
  results = {
    key: {'truth': truth, 'material': 'black_denim'},
    key[:3] + ('0001',): {'failed': 'exit 1'},  # no state: left out
    ('sdn_depth',) + key[1:]: {'truth': truth, 'material': 'black_denim'},
  }
  out = tables.candidate_landscapes(results, 'physnet_depth', str(tmp_path))
  assert list(out) == ['black_denim'] and len(out['black_denim']) == 1
  ratio, rel = out['black_denim'][0]
  np.testing.assert_allclose(ratio[0], 0.0, atol=1e-6)  # the truth itself
  # The centre of the box, by hand: bending's log-centre 1 (0.1-10), wind 3.5 m/s
  # (1-6), area weight the range's middle.
  lo, hi = space.bounds()[2]
  want = np.log10([1.0 / 2.0, 3.5 / 3.0, (lo + hi) / 2 / 0.33])
  np.testing.assert_allclose(ratio[1], want, rtol=1e-5)
  np.testing.assert_allclose(
    ratio[2], np.log10([10 / 2.0, 6 / 3.0, hi / 0.33]), rtol=1e-5
  )
  np.testing.assert_array_equal(rel[:2], [1.0, 2.0])
  assert np.isnan(rel[2])
  png = str(tmp_path / 'psd_candidates.png')
  tables.plot_candidate_landscapes(out, 'physnet_depth', png)
  assert cv2.imread(png) is not None


def test_a_simulated_alignment_error_misplaces_the_camera():
  pose = camera.look_at((0.5, -1.9, 1.2), (0.0, 0.2, 1.0))
  rec = Recording(np.zeros((2, 4, 4), np.float32), 20.0, None, pose, 'set/0003')
  info = {'path': 'set/0003', 'seq_id': '0003'}
  est = EstimateConfig()
  same = tables.misplaced_camera(tables.Config(), info, rec, est)
  assert same is rec
  config = tables.Config(camera_error_m=0.05, camera_error_deg=3.0)
  moved = tables.misplaced_camera(config, info, rec, est)
  again = tables.misplaced_camera(config, info, rec, est)
  np.testing.assert_array_equal(moved.pose.position, again.pose.position)
  step = np.linalg.norm(moved.pose.position - pose.position)
  assert 0.005 < step < 0.5  # metres: a shift and a turn about the pins
  other = tables.misplaced_camera(config, {**info, 'seq_id': '0004'}, rec, est)
  assert not np.allclose(other.pose.position, moved.pose.position)
  with pytest.raises(ValueError, match='set/0003: no camera pose'):
    tables.misplaced_camera(config, info, rec._replace(pose=None), est)
