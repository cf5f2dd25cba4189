"""model.checkpoint's process-local manager (jax.distributed runs) against orbax's."""

import jax
import jax.numpy as jnp
import numpy as np

from model import checkpoint


def test_local_checkpoints_round_trip_prune_and_read_through_orbax(tmp_path):
  state = {'w': jnp.arange(6.0).reshape(2, 3), 'n': jnp.int32(7)}
  target = jax.eval_shape(lambda: state)
  local = checkpoint.LocalManager(str(tmp_path / 'checkpoints'), max_to_keep=2)
  for step in (1, 2, 3):
    checkpoint.save(local, step, jax.tree.map(lambda a, s=step: a * s, state))
  assert local.all_steps() == [2, 3] and local.latest_step() == 3
  got = checkpoint.restore(local, target)
  np.testing.assert_array_equal(got['w'], 3 * np.arange(6.0).reshape(2, 3))
  assert got['n'].dtype == np.int32 and int(got['n']) == 21
  # A single-process run opens the same folder with orbax's manager.
  with checkpoint.manager(str(tmp_path)) as mngr:
    again = checkpoint.restore(mngr, target, step=2)
  np.testing.assert_array_equal(again['w'], 2 * np.arange(6.0).reshape(2, 3))
