"""The GPU paths against the CPU ones: MuJoCo Warp and MJX cloth on a CUDA device
against the MuJoCo C oracle (float64), and the ray-caster on the GPU against
itself on the host. Marked ``gpu``: skipped without a CUDA device (conftest).

Run on a GPU machine with ``python -m pytest -m gpu tests``.
"""

import jax
import numpy as np
import pytest

import physsim
from physsim import camera, render
from physsim import rollout as sim

pytestmark = pytest.mark.gpu

# float32 on the GPU against float64 in C over a 0.4 s gusty flap: the CPU
# parity test's tolerance (tests/physsim/rollout_test.py).
_PARITY_TOL = 5e-3  # m, max over vertices
_PARITY_MEDIAN_TOL = 1e-4  # m
# The same float32 ray-caster on two devices: XLA's GPU and CPU compilers
# fuse and contract (FMA) the projection and 1/z interpolation differently;
# up to 7.5e-5 m has been seen at ~1.5 m (H200). The bound is the one the
# renderer is held to against MuJoCo's OpenGL depth (render_test), far below a
# wrong triangle (cm) or a one-pixel shift.
_RENDER_TOL = 2e-4  # m
_FRAMES, _FPS = 8, 20.0


def _gpu():
  return [d for d in jax.devices() if d.platform == 'gpu']


@pytest.fixture(scope='module')
def model():
  return physsim.build(physsim.square(8), 'gray_interlock')


@pytest.fixture(scope='module')
def batch():
  return physsim.params.make(
    bending_scale=[1.0, 10.0, 0.3], wind_speed=[2.0, 4.0, 5.0],
    area_weight=[0.15, 0.37, 0.25],
  )  # fmt: skip


def _clip(model, batch, backend, **kw):
  return sim.simulate(
    model, batch, frames=_FRAMES, fps=_FPS, warmup=0.0,
    wind=physsim.Wind(gust_intensity=0.2), key=jax.random.key(7), backend=backend,
    **kw,
  )  # fmt: skip


@pytest.fixture(scope='module')
def c_out(model, batch):
  return _clip(model, batch, 'c', workers=1)


@pytest.mark.parametrize('backend', ['warp', 'mjx'])
def test_gpu_cloth_matches_mujoco_c(model, batch, c_out, backend):
  out = _clip(model, batch, backend, devices=_gpu()[:1])
  assert out.valid.all() and c_out.valid.all()
  assert np.abs(c_out.positions[:, -1] - model.mesh.vertices).max() > 0.1  # it moved
  err = np.abs(np.asarray(out.positions) - c_out.positions)
  assert err.max() < _PARITY_TOL
  assert np.median(err) < _PARITY_MEDIAN_TOL


def test_gpu_ray_caster_matches_the_host(model):
  intr = camera.Intrinsics(32, 32, 40.0, 40.0)
  pose = camera.look_at([0.3, -1.5, 1.0], [0.0, 0.0, 0.6])
  verts = np.asarray(model.mesh.vertices, np.float32)
  faces = np.asarray(model.mesh.faces)
  images = {}
  for device in (jax.devices('cpu')[0], _gpu()[0]):
    with jax.default_device(device):
      images[device.platform] = np.asarray(
        jax.jit(render.depth_image, static_argnames=('intrinsics',))(
          verts, faces, intrinsics=intr, pose=pose
        )
      )
  assert (images['cpu'] > 0).sum() > 50  # the cloth is in view
  np.testing.assert_array_equal(images['gpu'] > 0, images['cpu'] > 0)
  np.testing.assert_allclose(images['gpu'], images['cpu'], atol=_RENDER_TOL)
