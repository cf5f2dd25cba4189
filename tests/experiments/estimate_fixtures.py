"""Shared fixtures of the estimate and landscape tests: a hand-made embedding
saved as a model workdir, and a simulated recording with known truth.

The network is hand-made, not trained: a PhySNet with 1x1 convolutions and one
dense layer whose weights are set so that a frame's embedding is (silhouette
area share, mean metric depth over the image), each scaled to about unit
spread. It is saved as a ``model.fit`` workdir (config.json, an orbax
checkpoint, inputs.json) so ``estimate`` loads it like a trained run. Training
even a tiny PhySNet here would cost most of the time budget and make the
recovery test depend on how well an optimiser converged; a fixed embedding
keeps the tests about the estimate loop.

The recording is simulated with the estimate's own settings (mesh, frames, gust
key, camera) and written as a dataset sequence folder (16-bit mm PNGs and
meta.json), so the truth's PSD is zero up to the mm quantisation; with
``rgb=True`` it also holds 8-bit colour frames shaded in the fabric's colour.

For the other three methods (PhySNet-RGB, SDN-depth, SDN-RGB),
``write_random_model`` saves an untrained (randomly initialised) tiny network
the same way: those tests check that the estimate runs, not what it recovers.
"""

from __future__ import annotations

import json
import os

import cv2
import jax
import jax.numpy as jnp
import numpy as np

import model as model_lib
import physsim
from experiments.pipeline import embedding
from experiments.pipeline import objective as est
from experiments.pipeline import recording as recording_lib
from model import checkpoint, config_io
from physsim import dataset

SIZE = 32
MATERIAL = 'gray_interlock'
# Truth: well away from the range centre in wind and area weight.
TRUTH = dict(bending_scale=1.0, wind_speed=4.5, area_weight=0.17)
# The paper's protocol (argmin, common random numbers, the PSD through the
# hand-made network): the truth scores ~0 and repeated candidates score
# alike, which these tests rely on.
CONFIG = est.EstimateConfig().replace(
  distance='energy',
  point='argmin',
  material=MATERIAL,
  cloth_resolution=6,
  frames=8,
  fps=20.0,
  warmup=0.5,
  gusts=0.2,
  cameras=1,
  # n_init + q * max_iter <= 16 keeps every run in one GP buffer size, so the
  # proposal step compiles once for the whole file.
  q=4,
  n_init=4,
  max_iter=3,
  min_iter=3,  # the recovery run does not stop early
  stop_rel_change=0.1,
  stop_window=3,
  backend='c',
  workers=1,  # worker threads cost more than 6x6 cloths gain
  # The recording is rendered without the sensor model (an inverse crime), so
  # candidates are compared without it too; its effect is tested separately.
  sensor_noise=False,
  seed=0,
)
# Embedding scales: area share and mean depth move by ~0.1 and ~0.2 m between
# far-apart parameter sets at this size; these bring both to about unit spread.
_AREA_SCALE = 10.0
_DEPTH_SCALE = 5.0
# A valid pixel's metric input is >= 0.5 m; 1 - 4 x is then clipped to 0.
_VALID_GAIN = 4.0


def _hand_made_params(config: model_lib.PhySNetConfig) -> dict:
  """PhySNet weights that embed a frame as (area share, mean depth), scaled."""
  hw = config.image_size[0] * config.image_size[1]
  conv0 = {
    'kernel': np.array([1.0, -_VALID_GAIN], np.float32).reshape(1, 1, 1, 2),
    'bias': np.array([0.0, 1.0], np.float32),
  }  # (x, relu(1 - g x)): depth and "invalid"
  conv1 = {
    'kernel': np.array([[1.0, 0.0], [0.0, -1.0]], np.float32).reshape(1, 1, 2, 2),
    'bias': np.array([0.0, 1.0], np.float32),
  }  # (x, 1 - invalid) = (depth, valid)
  dense = np.zeros((hw, 2, 2), np.float32)  # flatten order: (pixel, channel)
  dense[:, 1, 0] = _AREA_SCALE / hw
  dense[:, 0, 1] = _DEPTH_SCALE / hw
  zero = np.zeros((), np.float32)
  return {
    'Conv_0': conv0,
    'PReLU_0': {'negative_slope': zero},  # ReLU
    'Conv_1': conv1,
    'PReLU_1': {'negative_slope': zero},
    'Dense_0': {'kernel': dense.reshape(hw * 2, 2), 'bias': np.zeros(2, np.float32)},
  }


def write_hand_made_model(workdir: str) -> str:
  """Writes a model workdir ``estimate`` loads like a trained run."""
  trunk = model_lib.PhySNetConfig(
    image_size=(SIZE, SIZE),
    conv_features=(2, 2),
    kernel_size=1,
    pool=1,
    dense_features=(),
  )
  config = model_lib.TrainConfig(network='physnet', physnet=trunk, epochs=1)
  network = model_lib.make_network(config)
  optimizer, _ = model_lib.make_optimizer(config, 1)
  state = model_lib.init_state(network, optimizer, jax.random.key(0))
  net = jax.tree.map(jnp.asarray, _hand_made_params(trunk))
  assert jax.tree.structure(net) == jax.tree.structure(state.params['net'])
  state = state.replace(params={**state.params, 'net': net})
  os.makedirs(workdir, exist_ok=True)
  config_io.write_json(os.path.join(workdir, 'config.json'), config_io.to_dict(config))
  with checkpoint.manager(workdir) as mngr:
    checkpoint.save(mngr, 1, state)
  dataset.write_json_atomic(
    os.path.join(workdir, embedding.INPUTS_FILE), {'input_mode': 'metric'}
  )
  return workdir


# SDN clip length of the tiny SDNs (CONFIG.frames = 8 holds two clips).
CLIP_FRAMES = 4


def write_random_model(workdir: str, network: str, modality: str, seed: int = 0):
  """Writes an untrained tiny PhySNet or SDN run on depth or RGB frames."""
  channels = embedding.CHANNELS[modality]
  trunk = model_lib.PhySNetConfig(
    in_channels=channels,
    image_size=(SIZE, SIZE),
    conv_features=(4,),
    kernel_size=3,
    pool=4,
    dense_features=(8,),
  )
  if network == 'physnet':
    config = model_lib.TrainConfig(network='physnet', physnet=trunk, epochs=1)
  else:
    sdn = model_lib.SDNConfig(
      in_channels=channels, num_frames=CLIP_FRAMES, num_components=2, trunk=trunk
    )
    config = model_lib.TrainConfig(network='sdn', sdn=sdn, loss='contrastive', epochs=1)
  net = model_lib.make_network(config)
  optimizer, _ = model_lib.make_optimizer(config, 1)
  state = model_lib.init_state(net, optimizer, jax.random.key(seed))
  os.makedirs(workdir, exist_ok=True)
  config_io.write_json(os.path.join(workdir, 'config.json'), config_io.to_dict(config))
  with checkpoint.manager(workdir) as mngr:
    checkpoint.save(mngr, 1, state)
  dataset.write_json_atomic(
    os.path.join(workdir, embedding.INPUTS_FILE),
    {'modality': modality, 'input_mode': 'relative'},
  )
  return workdir


def _pose() -> physsim.Pose:
  """A camera 2 m in front of the cloth and to its side, looking at its middle."""
  return physsim.look_at((0.6, -1.8, 1.0), (0.0, 0.1, 0.9))


def write_recording(
  root: str, truth: dict, config=CONFIG, rgb: bool = False, air: float = 1.0
) -> str:
  """Simulates ``truth`` with the estimate's settings; writes a sequence folder
  (with colour frames ``cam0/rgb_*.png`` if ``rgb``). ``air``: the fabric's
  air coefficient, a multiplier on the wind's density (ArcSim's sheet: 1)."""
  mesh = physsim.square(config.simulation.cloth_resolution)
  sim = physsim.SimConfig(air_density=air * physsim.SimConfig().air_density)
  cloth = physsim.build(mesh, config.simulation.material, config=sim)
  space = physsim.search_space(config.simulation.material)
  out = physsim.simulate(
    cloth,
    physsim.params.make(**truth),
    frames=config.simulation.frames,
    fps=config.simulation.fps,
    warmup=config.simulation.warmup,
    wind=physsim.Wind(gust_intensity=config.simulation.gusts),
    key=jax.random.fold_in(jax.random.key(config.seed), 2)[None],  # as estimate
    backend='c',
    space=space,
    workers=1,
  )
  assert out.valid.all()
  intr = physsim.Intrinsics(width=SIZE, height=SIZE)
  pose = _pose()
  render = physsim.make_depth_renderer(mesh.faces, intr)
  poses = jax.tree.map(lambda a: jnp.asarray(a)[None, None], pose)  # (1, 1, ...)
  depth = np.asarray(render(jnp.asarray(out.positions), poses))  # (1, 1, T, H, W)
  seq = os.path.join(root, 'seq')
  os.makedirs(os.path.join(seq, 'cam0'))
  mm = dataset.depth_to_mm(depth[0, 0])
  for t, frame in enumerate(mm):
    cv2.imwrite(os.path.join(seq, 'cam0', f'{t:04d}.png'), frame)
  meta = dict(
    truth,
    fps=config.simulation.fps,
    intrinsics=intr.to_dict(),
    extrinsics=[physsim.pose_to_dict(pose)],
  )
  if rgb:
    colour = physsim.render_rgb8(
      jnp.asarray(out.positions), mesh.faces, intr, poses,
      jnp.asarray([physsim.FABRIC_COLORS[config.simulation.material]]),
    )[0, 0]  # fmt: skip
    colour = np.asarray(colour)
    for t, frame in enumerate(colour):
      cv2.imwrite(
        os.path.join(seq, 'cam0', f'rgb_{t:04d}.png'),
        cv2.cvtColor(frame, cv2.COLOR_RGB2BGR),
      )
    # What dataset.read_sequence needs to find the colour frames.
    meta.update(
      n_cameras=1, n_frames=len(colour), height=SIZE, width=SIZE, has_rgb=True
    )
  with open(os.path.join(seq, 'meta.json'), 'w') as f:
    json.dump(meta, f)
  return seq


def load(seq: str, config=CONFIG, **kw) -> recording_lib.Recording:
  return recording_lib.load_recording(
    seq,
    fps=config.simulation.fps,
    size=(SIZE, SIZE),
    frames=config.simulation.frames,
    **kw,
  )
