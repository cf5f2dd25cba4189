"""Where the estimate's configuration goes (issue 75, item 2): a small real
estimate (the smoke preset, the shape distance, no network, on the estimate
fixtures' recording) followed under ``tests.config_path``. Each stage should be
handed its own section, so the whole config should not come back to a module
it has left; the bound only goes down as stages take their sections."""

from __future__ import annotations

import pytest

from experiments.pipeline import estimation
from experiments.pipeline import objective as obj_lib
from tests import config_path
from tests.experiments.estimate_fixtures import CONFIG, TRUTH, load, write_recording

pytestmark = pytest.mark.slow  # a whole (small) estimate

# Returns of the config handed itself to the stages (``config_path.returns``
# of the 'direct' path), and with the config's own checks' calls, as
# measured: they may only go down. (With the values that hold it: printed.)
MAX_RETURNS = {('direct',): 0, ('direct', 'own'): 2}


def _show(calls, kinds) -> tuple[int, int]:
  stays = config_path.path(calls, kinds)
  n = config_path.returns(stays)
  short = [s.removeprefix('experiments.pipeline.') for s in stays]
  print(f'{"+".join(kinds)}: {len(stays)} stays, {n} returns:', ' -> '.join(short))
  return len(stays), n


def test_the_config_comes_back_to_few_modules_it_left(tmp_path):
  sim = CONFIG.simulation
  config = obj_lib.PRESETS['smoke'].replace(
    backend='c', workers=1, distance='shape', material=sim.material,
    cloth_resolution=sim.cloth_resolution, frames=sim.frames, warmup=sim.warmup,
    gusts=sim.gusts, cameras=sim.cameras,
  )  # fmt: skip
  rec = load(write_recording(str(tmp_path), TRUTH))
  calls = config_path.trace(
    estimation.estimate, config, rec, '', str(tmp_path / 'est'), progress=False
  )
  for call in calls:
    print(f'  {call.how:6} {call.module}.{call.function}')
  returns = {kinds: _show(calls, kinds)[1] for kinds in MAX_RETURNS}
  _show(calls, ('direct', 'own', 'held'))
  for kinds, n in returns.items():
    assert n <= MAX_RETURNS[kinds], (kinds, config_path.path(calls, kinds))
