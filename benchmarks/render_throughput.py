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

  python -m benchmarks.render_throughput --batch_sizes=1,4 --frames=4 \
      --resolution=64
  python -m benchmarks.render_throughput   # GPU: 256 px, B up to 210
"""

from __future__ import annotations

import dataclasses
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

from experiments.pipeline import cli, files
from physsim import camera, devices, mesh, render

METHODS = ('raster', 'brute')


@dataclasses.dataclass(frozen=True)
class Args:
  """The depth-rendering benchmark.

  Attributes:
    resolution: image width and height, pixels.
    batch_sizes: worlds B per call (comma-separated).
    cameras: cameras C per world.
    frames: frames T per world.
    methods: physsim.render methods (raster, brute).
    cloth_resolution: cloth vertices per side.
    repeats: timed calls per row (median).
    chunk: frames per vmapped chunk (0: the method's default).
    world_chunk: worlds per call (0: what fits in free device memory).
    fragments_per_pass: raster fragments per pass (0: the default).
    brute_max_frames: skip brute rows above this many frames per call.
    mujoco_frames: frames timed for mujoco.Renderer (0: skip).
    mjwarp: also time MuJoCo Warp's batch renderer (GPU).
    out: JSON path (empty: out/benchmarks/render_<device>.json).
  """

  resolution: int = 256
  batch_sizes: tuple[int, ...] = (1, 16, 64, 210)
  cameras: int = 6
  frames: int = 60
  methods: tuple[str, ...] = METHODS
  cloth_resolution: int = 25
  repeats: int = 3
  chunk: int = 0
  world_chunk: int = 0
  fragments_per_pass: int = 0
  brute_max_frames: int = 20000
  mujoco_frames: int = 200
  mjwarp: bool = False
  out: str = ''


PRESETS = {
  'default': Args(),
  # checks the script on a CPU in seconds
  'smoke': Args(
    resolution=32,
    batch_sizes=(1, 2),
    cameras=2,
    frames=4,
    repeats=1,
    mujoco_frames=0,
  ),
}


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


def _jax_row(args: Args, method, b, m, intr):
  """B worlds rendered by ``physsim.render``: split over every local device
  (``physsim.devices``), in world chunks that fit free device memory (the
  frames of 210 worlds x 6 cameras x 60 frames at 256 px are 18.5 GiB alone),
  each chunk's frames reduced on the device (as a sweep would hand them on)."""
  c, t = args.cameras, args.frames
  mesh_ = devices.world_mesh()
  k = mesh_.devices.size
  fn = render.make_depth_renderer(
    m.faces,
    intr,
    method=method,
    chunk=args.chunk or None,
    fragments_per_pass=args.fragments_per_pass or None,
  )
  per_world = 3 * c * t * intr.width * intr.height * 4  # frames + working buffers
  chunk = args.world_chunk or devices.chunk_size(per_world, cap=b)
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
  for r in range(args.repeats + 1):  # the first call warms up
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


def _square_intrinsics(args: Args):
  # MuJoCo derives the horizontal FoV from the aspect ratio: square pixels.
  r = args.resolution
  return camera.Intrinsics(r, r, 45.0, 45.0)


def _mujoco_rows(args: Args, m):
  """mujoco.Renderer depth frames/s, with and without mesh re-upload."""
  import mujoco
  from mujoco.rendering.classic import gl_context

  intr = _square_intrinsics(args)
  poses = _poses(1, args.cameras)
  poses = camera.Pose(poses.rotation[0], poses.position[0])
  model = mujoco.MjModel.from_xml_string(_mjcf(m, poses, intr.fov_y_deg))
  data = mujoco.MjData(model)
  mujoco.mj_forward(model, data)
  backend = os.environ.get('MUJOCO_GL', 'egl').lower()
  if backend in ('egl', 'osmesa'):
    gl_context.GLContext = __import__(
      f'mujoco.{backend}', fromlist=['GLContext']
    ).GLContext
  renderer = mujoco.Renderer(model, args.resolution, args.resolution)
  renderer.enable_depth_rendering()
  n_v = len(m.vertices)
  if model.mesh_vertnum[0] != n_v:
    raise RuntimeError('MuJoCo changed the mesh vertex count; cannot re-upload')
  frames = _trajectory(m, 1, args.mujoco_frames)[0]
  gpos, gmat = data.geom_xpos[0].copy(), data.geom_xmat[0].reshape(3, 3).copy()
  rows = []
  for upload in (True, False):
    t0 = time.perf_counter()
    for i in range(args.mujoco_frames):
      if upload:
        # Mesh-local coordinates: MuJoCo recentres meshes in the geom frame.
        model.mesh_vert[:n_v] = (frames[i] - gpos) @ gmat
        mujoco.mjr_uploadMesh(model, renderer._mjr_context, 0)
      renderer.update_scene(data, camera=f'c{i % args.cameras}')
      depth = renderer.render()
    run_s = time.perf_counter() - t0
    rows.append(
      {
        'backend': 'mujoco.Renderer' + (' (mesh upload)' if upload else ' (static)'),
        'batch': 1,
        'frames_per_call': 1,
        'compile_s': 0.0,
        'run_s': run_s / args.mujoco_frames,
        'frames_per_s': args.mujoco_frames / run_s,
      }
    )
    if upload:  # check against ours on the last frame
      last = args.mujoco_frames - 1
      c = last % args.cameras
      pose = camera.Pose(poses.rotation[c], poses.position[c])
      ours = np.asarray(render.depth_image(frames[last], m.faces, intr, pose))
      ref = np.where(depth < 18.0, depth, 0.0)
      both = (ours > 0) & (ref > 0)
      rows[-1]['max_abs_diff_m'] = float(np.abs(ours - ref)[both].max())
      rows[-1]['p99_abs_diff_m'] = float(np.quantile(np.abs(ours - ref)[both], 0.99))
      rows[-1]['silhouette_mismatch'] = float(np.mean((ours > 0) != (ref > 0)))
  renderer.close()
  return rows


def _mjwarp_rows(args: Args, m, batch_sizes):
  """MuJoCo Warp batched ray-cast depth on the static mesh (GPU only)."""
  import mujoco
  import mujoco_warp as mjw
  import warp as wp

  if not wp.is_cuda_available():
    raise RuntimeError('MuJoCo Warp rendering is benchmarked on CUDA only')
  intr = _square_intrinsics(args)
  poses = _poses(1, args.cameras)
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
      cam_res=(args.resolution, args.resolution),
      render_rgb=False,
      render_depth=True,
    )
    mjw.render(mw, dw, rc)
    wp.synchronize()
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(args.repeats):
      t0 = time.perf_counter()
      mjw.render(mw, dw, rc)
      wp.synchronize()
      times.append(time.perf_counter() - t0)
    run_s = float(np.median(times))
    frames = b * args.cameras
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


def main(args: Args) -> None:
  batch_sizes = list(args.batch_sizes)
  if not batch_sizes or min(batch_sizes) < 1:
    raise ValueError(f'--batch_sizes={",".join(map(str, batch_sizes))}: need positive')
  bad = [m for m in args.methods if m not in METHODS]
  if bad or not args.methods:
    raise ValueError(f'--methods={",".join(args.methods)}: need some of {METHODS}')
  device = jax.devices()[0]
  kind = device.device_kind.replace(' ', '_').lower()
  m = mesh.square(args.cloth_resolution)
  intr = camera.Intrinsics(args.resolution, args.resolution)
  rows = []
  for method in args.methods:
    for b in batch_sizes:
      frames = b * args.cameras * args.frames
      if method == 'brute' and frames > args.brute_max_frames:
        continue
      rows.append(_jax_row(args, method, b, m, intr))
      print(rows[-1], flush=True)
  if args.mujoco_frames > 0:
    try:
      rows += _mujoco_rows(args, m)
    except Exception as e:  # noqa: BLE001 - no GL here: report, keep going
      print(f'mujoco.Renderer skipped: {type(e).__name__}: {e}')
  if args.mjwarp:
    try:
      rows += _mjwarp_rows(args, m, batch_sizes)
    except Exception as e:  # noqa: BLE001
      print(f'mujoco_warp render skipped: {type(e).__name__}: {e}')
  print(
    f'\nDepth frames/s, {args.resolution}x{args.resolution}, cloth '
    f'{args.cloth_resolution}x{args.cloth_resolution} ({len(m.faces)} triangles), '
    f'C={args.cameras}, T={args.frames}, on {device.device_kind}\n'
  )
  print('| backend | B | frames/call | compile s | run s | frames/s |')
  print('|---|---:|---:|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["backend"]} | {r["batch"]} | {r["frames_per_call"]} | '
      f'{r["compile_s"]:.2f} | {r["run_s"]:.4f} | {r["frames_per_s"]:,.0f} |'
    )
  out = args.out or f'out/benchmarks/render_{kind}.json'
  settings = dataclasses.asdict(args)
  result = {
    'device': device.device_kind,
    'platform': platform.platform(),
    'jax': jax.__version__,
    'flags': {
      k: (settings[k] or None) if k in ('chunk', 'fragments_per_pass') else settings[k]
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
  files.write_json(out, result)
  print(f'wrote {out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
