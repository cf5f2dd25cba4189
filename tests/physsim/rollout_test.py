"""Tests for physsim.rollout: the device backends ('mjx': ``mjx.step`` per
substep; 'warp': MuJoCo Warp a frame at a time) vs the MuJoCo C oracle, and
physics checks.

Each device rollout compiles once per module (Warp kernels then XLA), on an
8x8 cloth with a handful of frames.
"""

import os
import subprocess
import sys

import jax
import mujoco
import numpy as np
import pytest

import physsim
from physsim import rollout as sim

# MJX-warp runs float32, the oracle float64; a 5 m/s gusty flap amplifies the
# difference to a few mm by 0.4 s. Max over all vertices, and the median.
_PARITY_TOL = 5e-3  # m, 0.5% of the cloth's size
_PARITY_MEDIAN_TOL = 1e-4  # m
_FRAMES, _FPS = 8, 20.0


@pytest.fixture(scope='module')
def model():
  return physsim.build(physsim.square(8), 'gray_interlock')


@pytest.fixture(scope='module')
def batch():
  # world 0 = reference; 1 more wind; 2 heavier; 3 stiffer; 4 gusty reference twin
  return physsim.params.make(
    bending_scale=[1.0, 1.0, 1.0, 10.0, 0.3],
    wind_speed=[2.0, 4.0, 2.0, 2.0, 5.0],
    area_weight=[0.15, 0.15, 0.37, 0.15, 0.25],
  )


def _gusty(model, batch, backend, **kw):
  """The batch's clip in 20% gusts (one key), on ``backend``."""
  return sim.simulate(
    model, batch, frames=_FRAMES, fps=_FPS, warmup=0.0,
    wind=physsim.Wind(gust_intensity=0.2), key=jax.random.key(7), backend=backend,
    **kw,
  )  # fmt: skip


@pytest.fixture(scope='module')
def mjx_out(model, batch):
  return _gusty(model, batch, 'mjx')


@pytest.fixture(scope='module')
def c_out(model, batch):
  return _gusty(model, batch, 'c', workers=1)


@pytest.fixture(scope='module')
def warp_out(model, batch):
  return _gusty(model, batch, 'warp')


@pytest.mark.parametrize('backend', ['mjx', 'warp'])
def test_device_backend_matches_mujoco_c(model, c_out, backend, request):
  out = request.getfixturevalue(f'{backend}_out')
  assert out.positions.shape == (5, _FRAMES, 64, 3)
  assert out.valid.all() and c_out.valid.all()
  moved = np.abs(c_out.positions[:, -1] - model.mesh.vertices).max()
  assert moved > 0.1  # the comparison is not between two resting cloths
  err = np.abs(out.positions - c_out.positions)
  assert err.max() < _PARITY_TOL
  assert np.median(err) < _PARITY_MEDIAN_TOL


# The same worlds on one device and split over two (conftest gives two CPU
# devices): the same float32 operations per world, but batches of other
# shapes (5 worlds against 3 per device) are not summed in the same order, and
# the stiff edge constraints amplify rounding over the clip: up to 2e-5 m has
# been seen (a run under load). 1e-4 m is 50x under the MJX-vs-C tolerance
# and far below what a wrong split would give (another world's motion, cm).
_SHARDING_TOL = 1e-4  # m


@pytest.mark.parametrize('backend', ['mjx', 'warp'])
def test_worlds_split_over_devices_move_as_on_one(model, batch, backend, request):
  split = request.getfixturevalue(f'{backend}_out')
  assert len(jax.local_devices()) == 2  # it ran split (5 worlds padded to 6)
  one = _gusty(model, batch, backend, devices=jax.local_devices()[:1])
  np.testing.assert_array_equal(one.valid, split.valid)
  np.testing.assert_allclose(one.positions, split.positions, atol=_SHARDING_TOL)


def test_total_mass_is_area_times_area_weight(model):
  moving = model.vert_qadr >= 0
  for w in (0.1, 0.2, 0.37):
    vm = model.vertex_masses(w)
    assert vm.sum() == pytest.approx(model.mesh.area * w, rel=1e-12)
    # Bodies carry the moving vertices' masses; pinned ones rest on the pins.
    assert model.body_masses(w).sum() == pytest.approx(vm[moving].sum(), rel=1e-12)
  # Mass sits where the area is: an interior vertex carries 4x a corner's share
  # on this grid's alternating diagonals (6 or 2 adjacent half-cells).
  va = model.mesh.vertex_areas
  assert va.max() / va[model.mesh.pinned].max() > 1.9


def test_pins_do_not_move(model, mjx_out):
  pins = model.mesh.pinned
  np.testing.assert_array_equal(
    mjx_out.positions[:, :, pins],
    np.broadcast_to(model.mesh.vertices[pins], (5, _FRAMES, 2, 3)),
  )


def _deflection(out):
  """Mean wind-wise (y) displacement over the last half of the clip, per world."""
  return out.positions[:, _FRAMES // 2 :, :, 1].mean(axis=(1, 2))


def _curvature(model, out):
  """Mean |dihedral angle| over hinges at the last frame, per world (rad)."""
  hv = model.hinge_verts
  x = out.positions[:, -1]
  p0, p1, p2, p3 = (x[:, hv[:, k]] for k in range(4))
  n1 = np.cross(p1 - p0, p2 - p0)
  n2 = np.cross(p3 - p0, p1 - p0)
  cos = np.sum(n1 * n2, -1) / np.linalg.norm(n1, axis=-1) / np.linalg.norm(n2, axis=-1)
  return np.arccos(np.clip(cos, -1, 1)).mean(axis=1)


def test_physics_moves_the_right_way(model, batch):
  steady = sim.simulate(model, batch, frames=_FRAMES, fps=_FPS, warmup=0.5)
  y = _deflection(steady)
  assert y[1] > y[0] + 0.02  # more wind deflects more
  assert y[2] < y[0] - 0.02  # heavier cloth deflects less


def test_stiffer_bending_curves_less():
  # At 1 m a fabric's bending length (D / w g)^(1/3) is only 1-7 cm, so bending
  # barely shapes the sheet; a 20 cm denim swatch shows it clearly.
  small = physsim.build(physsim.square(8, size=0.2), 'black_denim')
  p = physsim.params.make([0.1, 10.0, 0.1, 10.0], [1.0, 1.0, 2.0, 2.0], 0.3)
  out = sim.simulate(
    small, p, frames=_FRAMES, fps=_FPS, warmup=0.5, backend='c', workers=1
  )
  k = _curvature(small, out)
  assert k[1] < 0.5 * k[0] and k[3] < 0.5 * k[2]


@pytest.mark.parametrize('name', physsim.GARMENTS)
def test_garments_hang_and_billow(name):
  # Coarse single-panel garments in a 3 m/s wind on the C backend: they stay
  # whole (strain held by the edge constraints), hang from their two pins and
  # are pushed along the wind.
  model = physsim.build(physsim.garment(name, spacing=0.1), 'gray_interlock')
  out = sim.simulate(
    model,
    physsim.params.make(1.0, 3.0, 0.2),
    frames=_FRAMES,
    fps=_FPS,
    warmup=0.5,
    backend='c',
    workers=1,
  ).check()
  x = out.positions[0]
  pins = model.mesh.pinned
  np.testing.assert_array_equal(
    x[:, pins], np.broadcast_to(x[0, pins], x[:, pins].shape)
  )
  s = physsim.motion.motion_stats(model.mesh, x, _FPS)
  assert s['strain_p99'] < 0.05
  assert s['mean_deflection_m'] > 0.05


def test_one_model_serves_every_material():
  # MuJoCo's bending stencil is linear in the rigidity, so interlock's model
  # told to be denim moves exactly like denim's own model.
  mesh = physsim.square(6, size=0.3)
  p = physsim.params.make([3.0, 0.3], 2.0, 0.3)
  kw = dict(frames=4, fps=_FPS, warmup=0.2, backend='c', workers=1)
  own = sim.simulate(physsim.build(mesh, 'black_denim'), p, **kw)
  other = physsim.build(mesh, 'gray_interlock')
  told = sim.simulate(other, p, material=['black_denim'] * 2, **kw)
  np.testing.assert_allclose(told.positions, own.positions, atol=1e-6)
  plain = sim.simulate(other, p, **kw)
  assert np.abs(plain.positions - own.positions).max() > 1e-4
  with pytest.raises(ValueError, match='material names'):
    sim.simulate(other, p, material=['black_denim'], **kw)


def test_changing_values_does_not_recompile(model, batch, mjx_out):
  fn = sim.jit_program(model, _FRAMES, _FPS, 0.0, backend='mjx')
  before = fn._cache_size()
  other = physsim.params.make(
    batch.bending_scale[::-1], batch.wind_speed, batch.area_weight[::-1]
  )
  sim.simulate(
    model,
    other,
    frames=_FRAMES,
    fps=_FPS,
    warmup=0.0,
    wind=physsim.Wind(gust_intensity=0.2),
    key=jax.random.key(8),
    backend='mjx',
  )
  assert fn._cache_size() == before


def test_passive_forces_off_changes_nothing():
  # The MJCF disables MuJoCo's passive pass (springs, dampers, flex
  # elasticity) for speed: the cloth has no passive forces of MuJoCo's own, so
  # the motion is the same to the last bit with the pass back on.
  model = physsim.build(physsim.square(6), 'gray_interlock')
  p = physsim.params.make([1.0, 5.0], [3.0, 5.0], [0.15, 0.3])
  kw = dict(frames=4, fps=_FPS, warmup=0.1, backend='c', workers=1,
            wind=physsim.Wind(gust_intensity=0.2), key=jax.random.key(3))  # fmt: skip
  off = sim.simulate(model, p, **kw).positions
  dsbl = mujoco.mjtDisableBit
  assert model.mj_model.opt.disableflags & dsbl.mjDSBL_SPRING
  model.mj_model.opt.disableflags &= ~int(dsbl.mjDSBL_SPRING | dsbl.mjDSBL_DAMPER)
  np.testing.assert_array_equal(sim.simulate(model, p, **kw).positions, off)


def test_blow_up_is_flagged_not_passed_on():
  # A 20 ms step with a 40 ms constraint time constant is far past stability.
  cfg = physsim.SimConfig(timestep=0.025, edge_solref=0.05, iterations=2)
  model = physsim.build(physsim.square(6), 'pink_nylon', cfg)
  p = physsim.params.make([0.1, 0.1], [6.0, 1.0], [0.16, 0.2])
  out = sim.simulate(model, p, frames=40, warmup=0.0, backend='c', workers=1)
  assert not out.valid[0]
  with pytest.raises(ValueError, match=r'worlds \[0'):
    out.check()


@pytest.mark.parametrize(
  ('kwargs', 'match'),
  [
    ({'frames': 0}, 'frames'),
    ({'fps': 7.0}, 'multiple of the timestep'),
    ({'wind': physsim.Wind(direction=(0, 0, 0))}, 'direction'),
    ({'wind': physsim.Wind(gust_intensity=0.2)}, 'PRNG key'),
    ({'backend': 'cuda'}, 'backend'),
  ],
)
def test_bad_inputs_raise_clear_errors(model, kwargs, match):
  p = physsim.params.make(1.0, 3.0, 0.2)
  with pytest.raises(ValueError, match=match):
    sim.simulate(model, p, backend=kwargs.pop('backend', 'c'), **kwargs)


def test_out_of_range_params_are_rejected_before_simulating(model):
  with pytest.raises(ValueError, match='wind_speed'):
    sim.simulate(model, physsim.params.make(1.0, 9.0, 0.2), backend='c')


# The traceable rollout takes float32 parameters and masses; simulate's C path
# float64: the two differ by float32 rounding amplified over the flap.
_CALLBACK_TOLERANCE = 2e-4  # m


def test_c_rollout_inside_jit_equals_simulate(model, batch):
  # rollout_fn('c') is MuJoCo C behind a pure_callback: one jitted pipeline
  # can hold it where MJX would go.
  wind = physsim.Wind(gust_intensity=0.2)
  keys = jax.random.split(jax.random.key(7), 5)
  fn = sim.rollout_fn(
    model, frames=_FRAMES, fps=_FPS, warmup=0.0, backend='c', workers=1
  )
  w = physsim.world_inputs(model, *batch, keys, wind)
  xs, valid = jax.jit(fn)(w)
  ref = sim.simulate(
    model, batch, frames=_FRAMES, fps=_FPS, warmup=0.0, wind=wind, key=keys,
    backend='c', workers=1,
  )  # fmt: skip
  np.testing.assert_array_equal(np.asarray(valid), ref.valid)
  np.testing.assert_allclose(np.asarray(xs), ref.positions, atol=_CALLBACK_TOLERANCE)


def test_c_worker_threads_give_each_world_what_one_thread_gives(model, batch, c_out):
  """Worlds split over 3 threads (each with its own copy of the MjModel, whose
  masses a world sets) move exactly as on one: float64, the same operations."""
  split = _gusty(model, batch, 'c', workers=3)
  np.testing.assert_array_equal(split.valid, c_out.valid)
  np.testing.assert_array_equal(split.positions, c_out.positions)


def test_a_plain_script_simulates_with_c_workers(tmp_path):
  """No ``if __name__ == '__main__'`` guard needed: the C backend starts no
  processes (spawned ones re-import the script and fail)."""
  script = tmp_path / 'plain.py'
  script.write_text(
    'import physsim\n'
    'from physsim import rollout\n'
    "m = physsim.build(physsim.square(4), 'gray_interlock')\n"
    'p = physsim.params.make([1.0, 2.0], [2.0, 3.0], [0.2, 0.2])\n'
    "out = rollout.simulate(m, p, frames=2, warmup=0.0, backend='c', workers=2)\n"
    "print('valid', out.valid.tolist())\n"
  )
  root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
  env = dict(
    os.environ, PYTHONPATH=root + os.pathsep + os.environ.get('PYTHONPATH', '')
  )
  done = subprocess.run(
    [sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300
  )
  assert done.returncode == 0, done.stderr[-2000:]
  assert done.stdout.strip() == 'valid [True, True]'


def test_prefetch_imports_a_backends_modules_in_the_background():
  # In a fresh interpreter (this one has imported them): a daemon thread
  # leaves MJX imported whole; MuJoCo C has nothing to import.
  assert sim.prefetch('c') is None
  code = (
    'import sys, physsim; print("mujoco.mjx" in sys.modules); '
    't = physsim.rollout.prefetch("mjx"); print(t.daemon); t.join(); '
    'print(hasattr(sys.modules.get("mujoco.mjx"), "step"))'
  )
  out = subprocess.run(
    [sys.executable, '-c', code], capture_output=True, text=True, check=True,
    env={**os.environ, 'JAX_PLATFORMS': 'cpu'},
  ).stdout.split()  # fmt: skip
  assert out == ['False', 'True', 'True']
