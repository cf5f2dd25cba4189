"""Corrupt or hostile files a user may hand the scripts: each is refused with
a message that names it (no library traceback), and outputs are written with
the user's usual permissions."""

from __future__ import annotations

import os
import stat

import pytest

from experiments.pipeline import datasets, embedding
from physsim import dataset
from tests.experiments import estimate_fixtures as ef


def test_a_corrupt_checkpoint_names_its_folder(tmp_path):
  model = ef.write_hand_made_model(str(tmp_path / 'model'))
  embedding.load_embedding(model)  # intact: loads
  for folder, _, names in os.walk(os.path.join(model, 'checkpoints')):
    for name in names:
      with open(os.path.join(folder, name), 'wb') as f:
        f.write(b'not a checkpoint')
  with pytest.raises(ValueError, match='checkpoints: checkpoint step 1 cannot be read'):
    embedding.load_embedding(model)


def test_a_corrupt_dataset_json_names_the_file(tmp_path):
  (tmp_path / 'dataset.json').write_text('{"config": ')
  config = datasets.PRESETS['smoke']
  with pytest.raises(ValueError, match='dataset.json: not valid JSON'):
    datasets.run(config, str(tmp_path))


def test_index_names_that_would_leave_the_dataset_are_refused(tmp_path):
  row = dataset.make_row(
    '0000', 'gray_interlock', 0, None, None, valid=True, n_cameras=1, n_frames=2
  )
  dataset.write_index(str(tmp_path), [row])
  assert len(dataset.open_dataset(str(tmp_path)).rows) == 1
  for key, bad, msg in (
    ('material', '../../..', 'not a plain name'),
    ('seq_id', '..', 'not a plain name'),
    ('material', 'velvet', 'not one of'),
  ):
    dataset.write_index(str(tmp_path), [dict(row, **{key: bad})])
    with pytest.raises(ValueError, match=f'index.csv:2: .*{msg}'):
      dataset.open_dataset(str(tmp_path))


def test_outputs_have_the_users_usual_permissions(tmp_path):
  old = os.umask(0o022)
  try:
    path = str(tmp_path / 'out.json')
    dataset.write_json_atomic(path, {'a': 1})
  finally:
    os.umask(old)
  assert stat.S_IMODE(os.stat(path).st_mode) == 0o644


def test_a_refused_dataset_config_leaves_no_folder(tmp_path):
  import dataclasses

  bad = dataclasses.replace(datasets.PRESETS['smoke'], materials=('velvet',))
  with pytest.raises(ValueError, match='velvet'):
    datasets.run(bad, str(tmp_path / 'new'))
  assert not os.path.exists(tmp_path / 'new')
