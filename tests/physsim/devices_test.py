"""Tests of physsim.devices: the world axis split over two CPU devices (as
conftest makes them) against the same function on one, and memory budgets."""

import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from physsim import devices, one_off

_TOL = 1e-6


def _per_world(x, keys, scale):
  """A per-world function with a replicated argument and PRNG keys."""
  noise = jax.vmap(lambda k: jax.random.normal(k, (3,)))(keys)
  return {'y': jnp.tanh(x @ scale) + noise, 'n': jnp.sum(x, axis=1)}


@pytest.mark.parametrize('b', [1, 3, 4, 7])
def test_split_worlds_equal_one_device(b):
  mesh = devices.world_mesh()
  assert mesh.devices.size == 2
  rng = np.random.default_rng(b)
  x = jnp.asarray(rng.standard_normal((b, 4)), jnp.float32)
  keys = jax.random.split(jax.random.key(0), b)
  scale = jnp.asarray(rng.standard_normal((4, 3)), jnp.float32)
  want = jax.jit(_per_world)(x, keys, scale)
  fn = jax.jit(devices.shard_worlds(_per_world, mesh, replicated=(2,)))
  got = fn(x, keys, scale)
  for k in want:
    assert got[k].shape == want[k].shape
    np.testing.assert_allclose(got[k], want[k], atol=_TOL)


def test_a_batch_of_few_worlds_runs_on_one_device():
  # a GPU step of up to FLAT_WORLDS worlds costs its fixed time on one device,
  # so a second only adds its set-up; larger batches keep the whole mesh
  mesh = devices.world_mesh()
  first = devices.mesh_for(mesh, devices.FLAT_WORLDS)
  assert devices.mesh_key(first) == (jax.local_devices()[0].id,)
  assert devices.mesh_for(mesh, 1).devices.size == 1
  assert devices.mesh_for(mesh, devices.FLAT_WORLDS + 1) is mesh
  assert devices.mesh_for(None, 1) is None
  single = devices.world_mesh(jax.local_devices()[:1])
  assert devices.mesh_for(single, 1) is single


def test_one_device_is_the_function_itself():
  assert devices.shard_worlds(_per_world, None) is _per_world
  mesh = devices.world_mesh(jax.local_devices()[:1])
  assert devices.shard_worlds(_per_world, mesh) is _per_world
  assert devices.mesh_key(mesh) == (jax.local_devices()[0].id,)


def test_disagreeing_world_counts_are_refused():
  fn = devices.shard_worlds(lambda a, b: a + b, devices.world_mesh())
  with pytest.raises(ValueError, match='world count'):
    jax.jit(fn)(jnp.zeros((3, 2)), jnp.zeros((4, 2)))


def test_padding_and_chunk_sizes_by_hand():
  assert devices.padded(5, 2) == 6 and devices.padded(6, 4) == 8
  # half of 10 GiB free, 1 GiB per item: 5 items; at least 1; at most the cap
  gib = 1 << 30
  assert devices.chunk_size(gib, free=10 * gib) == 5
  assert devices.chunk_size(100 * gib, free=10 * gib) == 1
  assert devices.chunk_size(gib, free=10 * gib, cap=3) == 3
  with pytest.raises(ValueError, match='bytes_per_item'):
    devices.chunk_size(0)
  assert devices.free_bytes() > 0  # the host's available memory on a CPU


def test_arrays_committed_to_one_device_enter_a_sharded_program():
  # A checkpoint's parameters live on device 0; a program sharded over both
  # devices refuses them as they are and takes them once replicated.
  mesh = devices.world_mesh()
  x = jnp.ones((3, 4), jnp.float32)
  keys = jax.random.split(jax.random.key(1), 3)
  scale = jax.device_put(jnp.eye(4, 3), jax.local_devices()[0])
  fn = jax.jit(devices.shard_worlds(_per_world, mesh, replicated=(2,)))
  with pytest.raises(ValueError, match='incompatible devices'):
    fn(x, keys, scale)
  got = fn(*devices.place((x, keys, scale), mesh))
  want = _per_world(x, keys, jnp.eye(4, 3))
  np.testing.assert_allclose(got['y'], want['y'], atol=_TOL)


def test_without_a_mesh_a_program_runs_on_one_device():
  # Parameters replicated over both devices (a data-parallel checkpoint)
  # spread a plain jit over both; placed without a mesh, it runs on one.
  mesh = devices.world_mesh()
  scale = devices.place(jnp.eye(4, 3), mesh)
  assert len(scale.devices()) == 2
  x = jnp.ones((3, 4), jnp.float32)
  keys = jax.random.split(jax.random.key(1), 3)
  spread = jax.jit(_per_world)(x, keys, scale)
  assert len(spread['y'].devices()) == 2
  one = jax.jit(_per_world)(*devices.place((x, keys, scale), None))
  assert one['y'].devices() == {jax.local_devices()[0]}
  np.testing.assert_allclose(one['y'], spread['y'], atol=_TOL)
  single = devices.world_mesh(jax.local_devices()[1:])
  assert devices.place(scale, single).devices() == {jax.local_devices()[1]}


@pytest.mark.parametrize('where', ['none', 'one', 'both'])
def test_a_program_compiled_from_shapes_is_the_one_placed_arrays_run(where):
  # abstract() describes a tree as place() puts it (shapes, dtypes, typed PRNG
  # keys, a None leaf, the sharding): a program lowered from it in a thread
  # is the one the placed arrays then call, with nothing compiled again.
  mesh = {'none': None, 'one': devices.world_mesh(jax.local_devices()[1:]),
          'both': devices.world_mesh()}[where]  # fmt: skip
  fn = jax.jit(devices.shard_worlds(lambda x, k, s, _: _per_world(x, k, s), mesh,
                                    replicated=(2, 3)))  # fmt: skip
  tree = (np.ones((4, 4), np.float32), jax.random.split(jax.random.key(2), 4),
          np.eye(4, 3, dtype=np.float32), None)  # fmt: skip
  shapes = devices.abstract(tree, mesh)
  assert shapes[3] is None and shapes[1].dtype == tree[1].dtype
  t = threading.Thread(target=lambda: fn.lower(*shapes).compile())
  t.start()
  t.join()
  meter = one_off.Meter()
  got = fn(*devices.place(tree, mesh))
  assert meter.seconds() == 0.0
  want = _per_world(*tree[:3])
  np.testing.assert_allclose(got['y'], want['y'], atol=_TOL)


def test_on_host_puts_new_arrays_on_the_hosts_first_cpu():
  # Whatever the default device, the set-up work of a stage lands on the host.
  other = jax.local_devices()[1]
  with jax.default_device(other):
    assert jnp.zeros(3).devices() == {other}
    with devices.on_host():
      x = jnp.arange(3.0) * 2
    assert x.devices() == {devices.host()}
  assert devices.host().platform == 'cpu'
