"""Tests for experiments.tables: summaries and the markdown, on hand-made results."""

import os

import numpy as np
import pytest

from experiments import table1, tables


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

  def job(r, method, *args):
    ran.append(method)
    return (method, r['set'], r['fabric'], r['seq_id']), _res(10.0, 2.0, 2.0)

  monkeypatch.setattr(tables, '_job', job)
  assert tables.METHODS == ('physnet_depth', 'physnet_rgb', 'sdn_depth', 'sdn_rgb')
  results = tables.run_all(tables.Config(), 'eval', models, str(tmp_path / 'w'))
  assert ran == ['sdn_rgb']
  md = tables.format_tables(tables.summarise(results, tables.METHODS), tables.METHODS)
  row = next(line for line in md.splitlines() if line.startswith('| black_denim'))
  assert row.startswith(
    '| black_denim | - | - | - | - | - | - | - | - | - | 10.0 | 2.0'
  )
