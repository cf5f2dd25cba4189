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


_SAVE = """
import jax, jax.numpy as jnp, numpy as np
from model import checkpoint
mesh = jax.sharding.Mesh(np.array(jax.devices()), ('d',))
rep = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
state = {{'w': jax.device_put(jnp.arange(6.0).reshape(2, 3), rep)}}
assert len(jax.devices()) == 2
with checkpoint.manager({root!r}) as mngr:
  checkpoint.save(mngr, 1, state)
"""
_RESTORE = """
import jax, numpy as np
from model import checkpoint
assert len(jax.devices()) == 1
with checkpoint.manager({root!r}) as mngr:
  got = checkpoint.restore(mngr, {{'w': jax.ShapeDtypeStruct((2, 3), np.float32)}})
np.testing.assert_array_equal(got['w'], np.arange(6.0).reshape(2, 3))
print('restored on', got['w'].sharding.device_set)
"""


def test_a_checkpoint_saved_over_two_devices_loads_on_one(tmp_path):
  # What the scripts write (one CPU device per core, state replicated over
  # them) read back in a process with one device (a user's own Python).
  import os
  import subprocess
  import sys

  root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

  def run(code: str, devices: int) -> str:
    env = dict(
      os.environ, PYTHONPATH=root, JAX_PLATFORMS='cpu',
      XLA_FLAGS=f'--xla_force_host_platform_device_count={devices}',
    )  # fmt: skip
    out = subprocess.run(
      [sys.executable, '-c', code.format(root=str(tmp_path))],
      cwd=root, env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout

  run(_SAVE, 2)
  assert 'restored on' in run(_RESTORE, 1)
