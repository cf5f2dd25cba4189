"""Depth rendering throughput: physsim.render (brute, raster) vs MuJoCo's renderers.

Renders B worlds x C cameras x T frames of a swinging cloth in one jitted call
and counts depth frames per second; compile time is reported apart. Side by
side, in the same process: MuJoCo's OpenGL `mujoco.Renderer` on the same cloth
(one frame at a time, re-uploading the deformed mesh each frame, and without
re-upload: a static mesh seen from a new camera), and, with ``--mjwarp`` on a
GPU, MuJoCo Warp's batched ray-cast renderer on the static mesh (B worlds x C
cameras per call). Both MuJoCo rows are checked against our depth on one frame.

The cloth frames are analytic (a swing that grows toward +y down the cloth plus
travelling ripples), so no simulation is needed; coverage matches the dataset.

  PYTHONPATH=. python benchmarks/render_throughput.py --batch_sizes=1,4 --frames=4 \
      --resolution=64
  PYTHONPATH=. python benchmarks/render_throughput.py   # GPU: 256 px, B up to 210
"""

from __future__ import annotations

import json
import os
import platform
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
from absl import app, flags

from physsim import camera, devices, mesh, render

FLAGS = flags.FLAGS
flags.DEFINE_integer('resolution', 256, 'image width and height, pixels')
flags.DEFINE_list('batch_sizes', ['1', '16', '64', '210'], 'worlds B per call')
flags.DEFINE_integer('cameras', 6, 'cameras C per world')
flags.DEFINE_integer('frames', 60, 'frames T per world')
flags.DEFINE_list('methods', ['raster', 'brute'], 'physsim.render methods')
flags.DEFINE_integer('cloth_resolution', 25, 'cloth vertices per side')
flags.DEFINE_integer('repeats', 3, 'timed calls per row (median)')
flags.DEFINE_integer('chunk', None, 'frames per vmapped chunk (default per method)')
flags.DEFINE_integer(
  'world_chunk', 0, 'worlds per call (0: what fits in free device memory)'
)
flags.DEFINE_integer('fragments_per_pass', None, 'raster fragments per pass')
flags.DEFINE_integer(
  'brute_max_frames', 20000, 'skip brute rows above this many frames per call'
)
flags.DEFINE_integer('mujoco_frames', 200, 'frames timed for mujoco.Renderer (0: skip)')
flags.DEFINE_bool('mjwarp', False, "also time MuJoCo Warp's batch renderer (GPU)")
flags.DEFINE_string(
  'out', None, 'JSON path (default benchmarks/results/render_<device>.json)'
)


def _trajectory(m: mesh.Mesh, b: int, t: int, seed: int = 0) -> np.ndarray:
  """(B, T, V, 3) float32 swinging-cloth frames, a few cm to 0.5 m toward +y."""
  rng = np.random.default_rng(seed)
  v = m.vertices
  x, z = v[:, 0], v[:, 2]
  drop = (z.max() - z) / (z.max() - z.min())  # 0 at the pinned top, 1 at the hem
  time_s = np.arange(t) / 20.0
  amp = rng.uniform(0.1, 0.5, (b, 1, 1))
  freq = rng.uniform(0.5, 2.0, (b, 1, 1))
  phase = rng.uniform(0, 2 * np.pi, (b, 1, 1))
  tt = time_s[None, :, None]
  swing = amp * (0.7 + 0.3 * np.sin(2 * np.pi * freq * tt + phase)) * drop**2
  ripple = 0.05 * drop * np.sin(6 * x + 2 * np.pi * 1.5 * tt + phase)
  pos = np.broadcast_to(v, (b, t) + v.shape).copy()
  pos[..., 1] = swing + ripple
  pos[..., 2] = v[:, 2] + 0.5 * swing**2  # a pendulum of ~1 m rises y^2 / 2
  return pos.astype(np.float32)


def _poses(b: int, c: int, seed: int = 0) -> camera.Pose:
  keys = jax.random.split(jax.random.key(seed), b)
  return jax.vmap(lambda k: camera.sample_poses(k, c))(keys)


def _jax_row(method, b, m, intr):
  """B worlds rendered by ``physsim.render``: split over every local device
  (``physsim.devices``), in world chunks that fit free device memory (the
  frames of 210 worlds x 6 cameras x 60 frames at 256 px are 18.5 GiB alone),
  each chunk's frames reduced on the device (as a sweep would hand them on)."""
  c, t = FLAGS.cameras, FLAGS.frames
  mesh_ = devices.world_mesh()
  k = mesh_.devices.size
  fn = render.make_depth_renderer(
    m.faces,
    intr,
    method=method,
    chunk=FLAGS.chunk,
    fragments_per_pass=FLAGS.fragments_per_pass,
  )
  per_world = 3 * c * t * intr.width * intr.height * 4  # frames + working buffers
  chunk = FLAGS.world_chunk or devices.chunk_size(per_world, cap=b)
  chunk = min(devices.padded(chunk, k), devices.padded(b, k))
  sharded = jax.jit(
    lambda pos, poses: jnp.mean(devices.shard_worlds(fn, mesh_)(pos, poses) > 0)
  )
  pos = jnp.asarray(_trajectory(m, chunk, t))
  poses = _poses(chunk, c)
  t0 = time.perf_counter()
  compiled = sharded.lower(pos, poses).compile()
  compile_s = time.perf_counter() - t0
  times, coverage = [], []
  for r in range(FLAGS.repeats + 1):  # the first call warms up
    pos = jnp.asarray(_trajectory(m, b, t, seed=r))
    poses = _poses(b, c, seed=r)
    jax.block_until_ready((pos, poses))
    t0 = time.perf_counter()
    cover = []
    for start in range(0, b, chunk):
      idx = np.minimum(np.arange(start, start + chunk), b - 1)
      cover.append(compiled(pos[idx], jax.tree.map(lambda a: a[idx], poses)))  # noqa: B023
    cover = [float(x) for x in jax.block_until_ready(cover)]
    if r:
      times.append(time.perf_counter() - t0)
      coverage.append(np.mean(cover))
  run_s = float(np.median(times))
  frames = b * c * t
  return {
    'backend': f'physsim.{method}',
    'batch': b,
    'frames_per_call': frames,
    'world_chunk': chunk,
    'devices': k,
    'compile_s': compile_s,
    'run_s': run_s,
    'frames_per_s': frames / run_s,
    'coverage': float(np.mean(coverage)),
  }


def _mjcf(m, poses, fovy):
  faces = np.concatenate([m.faces, m.faces[:, ::-1]])  # both sides
  fmt = lambda a: ' '.join(f'{x:.9g}' for x in np.ravel(a))
  cams = []
  for i in range(poses.rotation.shape[0]):
    r = np.asarray(poses.rotation[i], np.float64)
    xy = np.concatenate([r[:, 0], -r[:, 1]])  # MuJoCo cameras: -z forward, y up
    cams.append(
      f'<camera name="c{i}" pos="{fmt(poses.position[i])}" xyaxes="{fmt(xy)}" '
      f'fovy="{fovy}"/>'
    )
  return f"""
<mujoco>
  <statistic extent="1" center="0 0 1"/>
  <visual><map znear="0.01" zfar="20"/></visual>
  <asset><mesh name="cloth" vertex="{fmt(m.vertices)}" face="{fmt(faces)}"
    inertia="shell"/></asset>
  <worldbody>
    <geom type="mesh" mesh="cloth" contype="0" conaffinity="0"/>
    {' '.join(cams)}
  </worldbody>
</mujoco>"""


def _square_intrinsics():
  # MuJoCo derives the horizontal FoV from the aspect ratio: square pixels.
  r = FLAGS.resolution
  return camera.Intrinsics(r, r, 45.0, 45.0)


def _mujoco_rows(m):
  """mujoco.Renderer depth frames/s, with and without mesh re-upload."""
  import mujoco
  from mujoco.rendering.classic import gl_context

  intr = _square_intrinsics()
  poses = _poses(1, FLAGS.cameras)
  poses = camera.Pose(poses.rotation[0], poses.position[0])
  model = mujoco.MjModel.from_xml_string(_mjcf(m, poses, intr.fov_y_deg))
  data = mujoco.MjData(model)
  mujoco.mj_forward(model, data)
  backend = os.environ.get('MUJOCO_GL', 'egl').lower()
  if backend in ('egl', 'osmesa'):
    gl_context.GLContext = __import__(
      f'mujoco.{backend}', fromlist=['GLContext']
    ).GLContext
  renderer = mujoco.Renderer(model, FLAGS.resolution, FLAGS.resolution)
  renderer.enable_depth_rendering()
  n_v = len(m.vertices)
  if model.mesh_vertnum[0] != n_v:
    raise RuntimeError('MuJoCo changed the mesh vertex count; cannot re-upload')
  frames = _trajectory(m, 1, FLAGS.mujoco_frames)[0]
  gpos, gmat = data.geom_xpos[0].copy(), data.geom_xmat[0].reshape(3, 3).copy()
  rows = []
  for upload in (True, False):
    t0 = time.perf_counter()
    for i in range(FLAGS.mujoco_frames):
      if upload:
        # Mesh-local coordinates: MuJoCo recentres meshes in the geom frame.
        model.mesh_vert[:n_v] = (frames[i] - gpos) @ gmat
        mujoco.mjr_uploadMesh(model, renderer._mjr_context, 0)
      renderer.update_scene(data, camera=f'c{i % FLAGS.cameras}')
      depth = renderer.render()
    run_s = time.perf_counter() - t0
    rows.append(
      {
        'backend': 'mujoco.Renderer' + (' (mesh upload)' if upload else ' (static)'),
        'batch': 1,
        'frames_per_call': 1,
        'compile_s': 0.0,
        'run_s': run_s / FLAGS.mujoco_frames,
        'frames_per_s': FLAGS.mujoco_frames / run_s,
      }
    )
    if upload:  # check against ours on the last frame
      last = FLAGS.mujoco_frames - 1
      c = last % FLAGS.cameras
      pose = camera.Pose(poses.rotation[c], poses.position[c])
      ours = np.asarray(render.depth_image(frames[last], m.faces, intr, pose))
      ref = np.where(depth < 18.0, depth, 0.0)
      both = (ours > 0) & (ref > 0)
      rows[-1]['max_abs_diff_m'] = float(np.abs(ours - ref)[both].max())
      rows[-1]['p99_abs_diff_m'] = float(np.quantile(np.abs(ours - ref)[both], 0.99))
      rows[-1]['silhouette_mismatch'] = float(np.mean((ours > 0) != (ref > 0)))
  renderer.close()
  return rows


def _mjwarp_rows(m, batch_sizes):
  """MuJoCo Warp batched ray-cast depth on the static mesh (GPU only)."""
  import mujoco
  import mujoco_warp as mjw
  import warp as wp

  if not wp.is_cuda_available():
    raise RuntimeError('MuJoCo Warp rendering is benchmarked on CUDA only')
  intr = _square_intrinsics()
  poses = _poses(1, FLAGS.cameras)
  poses = camera.Pose(poses.rotation[0], poses.position[0])
  mjm = mujoco.MjModel.from_xml_string(_mjcf(m, poses, intr.fov_y_deg))
  mjd = mujoco.MjData(mjm)
  mujoco.mj_forward(mjm, mjd)
  rows = []
  for b in batch_sizes:
    mw = mjw.put_model(mjm)
    dw = mjw.put_data(mjm, mjd, nworld=b)
    t0 = time.perf_counter()
    rc = mjw.create_render_context(
      mjm,
      nworld=b,
      cam_res=(FLAGS.resolution, FLAGS.resolution),
      render_rgb=False,
      render_depth=True,
    )
    mjw.render(mw, dw, rc)
    wp.synchronize()
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(FLAGS.repeats):
      t0 = time.perf_counter()
      mjw.render(mw, dw, rc)
      wp.synchronize()
      times.append(time.perf_counter() - t0)
    run_s = float(np.median(times))
    frames = b * FLAGS.cameras
    rows.append(
      {
        'backend': 'mujoco_warp.render (static)',
        'batch': b,
        'frames_per_call': frames,
        'compile_s': compile_s,
        'run_s': run_s,
        'frames_per_s': frames / run_s,
      }
    )
  return rows


def main(argv):
  del argv
  device = jax.devices()[0]
  kind = device.device_kind.replace(' ', '_').lower()
  m = mesh.square(FLAGS.cloth_resolution)
  intr = camera.Intrinsics(FLAGS.resolution, FLAGS.resolution)
  batch_sizes = [int(b) for b in FLAGS.batch_sizes]
  rows = []
  for method in FLAGS.methods:
    for b in batch_sizes:
      frames = b * FLAGS.cameras * FLAGS.frames
      if method == 'brute' and frames > FLAGS.brute_max_frames:
        continue
      rows.append(_jax_row(method, b, m, intr))
      print(rows[-1], flush=True)
  if FLAGS.mujoco_frames > 0:
    try:
      rows += _mujoco_rows(m)
    except Exception as e:  # noqa: BLE001 - no GL here: report, keep going
      print(f'mujoco.Renderer skipped: {type(e).__name__}: {e}')
  if FLAGS.mjwarp:
    try:
      rows += _mjwarp_rows(m, batch_sizes)
    except Exception as e:  # noqa: BLE001
      print(f'mujoco_warp render skipped: {type(e).__name__}: {e}')
  print(
    f'\nDepth frames/s, {FLAGS.resolution}x{FLAGS.resolution}, cloth '
    f'{FLAGS.cloth_resolution}x{FLAGS.cloth_resolution} ({len(m.faces)} triangles), '
    f'C={FLAGS.cameras}, T={FLAGS.frames}, on {device.device_kind}\n'
  )
  print('| backend | B | frames/call | compile s | run s | frames/s |')
  print('|---|---:|---:|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["backend"]} | {r["batch"]} | {r["frames_per_call"]} | '
      f'{r["compile_s"]:.2f} | {r["run_s"]:.4f} | {r["frames_per_s"]:,.0f} |'
    )
  out = FLAGS.out or f'benchmarks/results/render_{kind}.json'
  result = {
    'device': device.device_kind,
    'platform': platform.platform(),
    'jax': jax.__version__,
    'flags': {
      k: FLAGS[k].value
      for k in (
        'resolution',
        'batch_sizes',
        'cameras',
        'frames',
        'methods',
        'cloth_resolution',
        'repeats',
        'chunk',
        'fragments_per_pass',
        'mujoco_frames',
        'mjwarp',
      )
    },
    'rows': rows,
  }
  os.makedirs(os.path.dirname(out) or '.', exist_ok=True)
  with tempfile.NamedTemporaryFile(
    'w', dir=os.path.dirname(out) or '.', delete=False
  ) as f:
    json.dump(result, f, indent=1)
  os.replace(f.name, out)
  print(f'wrote {out}')


if __name__ == '__main__':
  app.run(main)
