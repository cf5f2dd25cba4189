"""The fabric dataset sweep, simulated and rendered into the ``physsim.dataset`` format.

For each material: parameter sets drawn uniformly in its normalised search box
(seeded per material), simulated in fixed batches (``physsim.simulate``), each
world seen by random cameras (``physsim.sample_poses``) through the JAX
ray-caster in one jitted call per batch, and written sequence by sequence,
atomically. A rerun resumes: finished sequences are kept as they are.
``experiments/generate_dataset.py`` is its command line.

Invalid (blown-up) worlds are written with ``valid=False`` and no frames; they
are rendered with the rest mesh in their place only to keep the batch shape
fixed, and those frames are discarded.

The sweep's settings are in ``dataset_config``, its cameras and renderer in
``dataset_render``, its folder (dataset.json, meta.json, montages) in
``dataset_folder``; this module runs it call by call: simulate, render, write.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import functools
import os
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from absl import logging

import physsim
from experiments.pipeline import (
  dataset_folder,
  dataset_render,
  deadline,
  distributed,
  embedding,
  progress,
)
from experiments.pipeline.dataset_config import (
  PRESETS,  # noqa: F401 - the sweep's presets, read here by its users
  Config,
  check_config,
  check_params,
  cloth_mesh,
  material_params,
  material_stream,
)
from physsim import dataset

# The sweep's parts under the names its tests call them by.
_check_config = check_config
_identity = dataset_folder.identity
_coverage = dataset_render.coverage
_frame_cameras = dataset_render.frame_cameras
_renderer = dataset_render.renderer
_render_chunk = dataset_render.render_chunk
_chunked = dataset_render.chunked

# PNG encoding releases the GIL: sequences of a batch are written in parallel.
_WRITERS = 8


def _batches_per_call(backend: str, n_devices: int) -> int:
  """Batches a simulation call takes: one per local device on a device
  backend, so that a batch under a GPU step's fixed cost (``physsim.devices.
  FLAT_WORLDS``) still splits over the devices (each world keeps its batch's
  keys: its inputs do not depend on the device count); one on MuJoCo C,
  which simulates world after world (a padded call would cost its padding)."""
  return 1 if backend == 'c' else n_devices


def _call_worlds(jobs: list, batches: list[int], bs: int, per_call: int):
  """A device call's worlds: each of ``batches``' chunk of ``jobs`` padded to
  ``bs`` with its last, then the call to ``per_call`` chunks with the last
  world (so one program shape serves every call); and each batch's first
  world in the call."""
  worlds, first = [], {}
  for b in batches:
    chunk = jobs[b * bs : (b + 1) * bs]
    first[b] = len(worlds)
    worlds += chunk + [chunk[-1]] * (bs - len(chunk))
  return worlds + [worlds[-1]] * (per_call * bs - len(worlds)), first


def _call_keys(root_key, batches: list[int], bs: int, n: int):
  """(gust keys, sensor-noise key data), each for n worlds, of a call: batch
  ``b``'s two keys from ``fold_in(root_key, 2 + b)``, split over its ``bs``
  worlds, the call's padding repeating the last (``_call_worlds``)."""
  wind, noise = [], []
  for b in batches:
    k_wind, k_noise = jax.random.split(jax.random.fold_in(root_key, 2 + b))
    wind.append(jax.random.split(k_wind, bs))
    noise.append(jax.random.split(k_noise, bs))
  idx = np.minimum(np.arange(n), len(batches) * bs - 1)
  noise = np.asarray(jax.random.key_data(jnp.concatenate(noise)))
  return jnp.concatenate(wind)[idx], noise[idx]


@dataclasses.dataclass(frozen=True)
class _Sweep:
  """What every call of a sweep shares (``_plan``)."""

  config: Config
  backend: str
  intrinsics: physsim.Intrinsics
  mesh: physsim.Mesh
  model: Any  # physsim.build's: one for every material (bending per world)
  wind: Any  # the physics' wind model
  root_key: jax.Array
  params: dict  # material -> physsim.Params, (sequences,) each
  cam_keys: dict  # material -> its cameras' key
  jobs: list  # (material index, sequence index), in order
  calls: list  # per device call: its batch indices
  per_call: int  # batches a call
  render: Callable  # dataset_render.chunked: a call's worlds
  redraw: Callable  # the same, for the few worlds whose cameras are drawn again


@dataclasses.dataclass
class _Tally:
  """A sweep's running counts and seconds (the first call includes compiles)."""

  seconds: dict = dataclasses.field(
    default_factory=lambda: {
      'simulate': 0.0,
      'simulate_first_batches': 0.0,
      'render': 0.0,
      'first_render_call': None,
      'write': 0.0,
      'redraw': 0.0,
    }
  )
  frames_simulated: int = 0
  sim_calls: int = 0
  frames_rendered: int = 0
  cameras_redrawn: int = 0


def _open(config: Config, workdir: str, params: dict | None):
  """Checks the sweep and opens its folder; returns (backend, given params).

  Several processes (jax.distributed) share the batches: process 0 opens (or
  checks) the folder first, each writes its batches' sequences, and process 0
  indexes them all once every process is done."""
  check_config(config)
  backend = physsim.resolve_backend(config.backend)
  given = check_params(config, params)
  if distributed.is_main():
    dataset_folder.open_workdir(workdir, config, backend, given)
  distributed.barrier(f'dataset {workdir}: opened')
  if not distributed.is_main():
    dataset_folder.check_workdir(workdir, config, backend, given)
  return backend, given


def _plan(config: Config, backend: str, given: dict | None) -> _Sweep:
  """The sweep's model, renderers, keys and its jobs grouped into calls."""
  intrinsics = physsim.Intrinsics(width=config.resolution, height=config.resolution)
  mesh = cloth_mesh(config)
  # A fine mesh needs a shorter step; MuJoCo's stiffest safe constraint time
  # constant is two steps.
  physics = physsim.MISMATCHES[config.physics]
  sim_config = physsim.config_for_mesh(
    mesh, config.fps, config.timestep, scaled_edges=config.scaled_edges,
    **physics.sim_fields(),
  )  # fmt: skip
  world_mesh = physsim.devices.world_mesh()
  bs = config.batch_size
  n_dev = world_mesh.devices.size
  # Every process groups the batches alike (they share the calls by index):
  # by the fewest devices any process has.
  fewest = min(collections.Counter(d.process_index for d in jax.devices()).values())
  per_call = _batches_per_call(backend, min(n_dev, fewest))
  renderer = dataset_render.renderer(mesh.faces, intrinsics, config, world_mesh)
  chunk = dataset_render.render_chunk(config, bs * per_call, n_dev)
  # Cameras drawn again (min_coverage) are few: their worlds go in chunks of
  # an eighth, one more program shape, where that is at least a world a device.
  redraw = dataset_render.chunked(renderer, chunk // 8 // n_dev * n_dev or chunk)
  root_key = jax.random.key(config.seed)
  # One compiled model for every material (bending is scaled per world), so
  # batches run across materials: jobs are (material index, sequence index).
  hem = (
    physsim.hem_mass(mesh, config.cloth_resolution, config.hem_mass)
    if config.hem_mass
    else None
  )
  jobs = [(k, i) for k in range(len(config.materials)) for i in range(config.sequences)]
  n_batches = -(-len(jobs) // bs)
  return _Sweep(
    config=config,
    backend=backend,
    intrinsics=intrinsics,
    mesh=mesh,
    model=physsim.build(mesh, config.materials[0], sim_config, extra_mass=hem),
    wind=physics.wind(config.gust_intensity),
    root_key=root_key,
    params={
      m: given[m] if given else material_params(config, m) for m in config.materials
    },  # fmt: skip
    cam_keys={
      m: jax.random.fold_in(
        jax.random.fold_in(root_key, material_stream(config.seed, m)), 1
      )
      for m in config.materials
    },
    jobs=jobs,
    calls=[
      list(range(c, min(c + per_call, n_batches)))
      for c in range(0, n_batches, per_call)
    ],
    per_call=per_call,
    render=dataset_render.chunked(renderer, chunk),
    redraw=redraw,
  )


def _unwritten(sweep: _Sweep, workdir: str, c: int) -> tuple[dict, list]:
  """Call ``c``'s batches -> their sequences not yet written (batches with
  none left out), and the (material index, sequence) of those written."""
  bs = sweep.config.batch_size
  todo, written = {}, []
  for b in sweep.calls[c]:
    chunk = sweep.jobs[b * bs : (b + 1) * bs]
    left = [
      (k, i)
      for k, i in chunk
      if not dataset.is_complete(workdir, sweep.config.materials[k], f'{i:04d}')
    ]
    written += list(set(chunk) - set(left))
    if left:
      todo[b] = left
  return todo, written


def _simulate(sweep: _Sweep, todo: dict):
  """Simulates a call's worlds (``todo``'s batches, padded: ``_call_worlds``).

  Returns:
    (its (material index, sequence) per world, each batch's first world,
    material per world, the worlds' noise key data, ``physsim.simulate``'s
    output, seconds simulating).
  """
  config = sweep.config
  world_jobs, first_world = _call_worlds(
    sweep.jobs, list(todo), config.batch_size, sweep.per_call
  )
  names = [config.materials[k] for k, _ in world_jobs]
  p = physsim.Params(
    *(
      np.array(
        [
          getattr(sweep.params[n], f)[i]
          for n, (_, i) in zip(names, world_jobs, strict=True)
        ]
      )
      for f in physsim.Params._fields
    )
  )
  wind_keys, noise_keys = _call_keys(
    sweep.root_key, list(todo), config.batch_size, len(world_jobs)
  )
  t0 = time.perf_counter()
  out = physsim.simulate(
    sweep.model,
    p,
    frames=config.frames,
    fps=config.fps,
    warmup=config.warmup,
    wind=sweep.wind,
    key=wind_keys,
    backend=sweep.backend,
    workers=config.workers or None,
    material=names,
  )
  return world_jobs, first_world, names, noise_keys, out, time.perf_counter() - t0


def _render(sweep: _Sweep, world_jobs, names, noise_keys, out):
  """Renders a call's simulated worlds, drawing again the cameras that see too
  little cloth (``min_coverage``).

  Returns:
    ((poses, depth, rgb, draws, coverage) as ``dataset_render.frame_cameras``'s,
    the poses on the host), seconds rendering, seconds drawing again.
  """
  config = sweep.config
  # Cameras per sequence, independent of batching.
  draw = functools.partial(
    dataset_render.draw_poses,
    config,
    jnp.stack([sweep.cam_keys[n] for n in names]),
    jnp.asarray([i for _, i in world_jobs]),
  )
  poses = draw(0)  # (B, C)
  # Blown-up worlds render the rest mesh: same shapes, frames discarded.
  positions = np.where(
    out.valid[:, None, None, None],
    out.positions,
    sweep.mesh.vertices.astype(np.float32),
  )
  t0 = time.perf_counter()
  colors = np.array([embedding.rgb_color(n) for n in names], np.float32)
  depth, rgb = sweep.render(positions, poses, noise_keys, colors)
  render_s = time.perf_counter() - t0
  t0 = time.perf_counter()
  poses, depth, rgb, draws, coverage = dataset_render.frame_cameras(
    config,
    draw,
    dataset_render.some_worlds(sweep.redraw, positions, noise_keys, colors),
    poses,
    (depth, rgb),
    out.valid,
  )
  poses = jax.tree.map(np.asarray, poses)  # on the host (min_coverage off)
  frames = (poses, depth, rgb, draws, coverage)
  return frames, render_s, time.perf_counter() - t0


def _meta(sweep: _Sweep, k: int, i: int, w: int, valid: bool, frames) -> dict:
  """Sequence ``i`` of material ``k``'s meta.json, world ``w`` of its call."""
  config = sweep.config
  poses, depth, _, draws, coverage = frames
  material = config.materials[k]
  row = dataset.make_row(
    f'{i:04d}',
    material,
    k * config.sequences + int(i),
    physsim.Params(*(f[i] for f in sweep.params[material])),
    physsim.search_space(material),
    valid=valid,
    n_cameras=config.cameras,
    n_frames=config.frames,
  )
  meta = dataset_folder.sequence_meta(
    config, row, sweep.intrinsics, sweep.mesh.name, sweep.backend,
    jax.tree.map(lambda a: a[w], poses), depth[w] if valid else None,
  )  # fmt: skip
  if coverage is not None and valid:  # min_coverage is on
    meta['pose_draws'] = draws[w].tolist()
    meta['coverage_min'] = [round(float(x), 5) for x in coverage[w]]
    if coverage[w].min() < config.min_coverage:
      logging.warning(
        '%s/%04d: the best of %d camera poses sees the cloth on %.4f of a frame',
        material, i, config.pose_draws, coverage[w].min(),
      )  # fmt: skip
  return meta


def _write(sweep: _Sweep, workdir: str, writers, todo: dict, first_world: dict,
           valid, frames):  # fmt: skip
  """Submits a call's unwritten sequences to ``writers``.

  Returns:
    (the writes' futures, each written sequence's material, cameras drawn
    again among them).
  """
  config, bs = sweep.config, sweep.config.batch_size
  _, depth, rgb, draws, coverage = frames
  pending, materials, redrawn = [], [], 0
  for b, left in todo.items():
    for j, (k, i) in enumerate(sweep.jobs[b * bs : (b + 1) * bs]):
      if (k, i) not in left:
        continue
      w = first_world[b] + j  # its world in the call
      ok = bool(valid[w])
      meta = _meta(sweep, k, i, w, ok, frames)
      if coverage is not None and ok:
        redrawn += int((draws[w] > 1).sum())
      pending.append(
        writers.submit(
          dataset.write_sequence,
          workdir,
          meta,
          depth[w] if ok else None,
          rgb[w] if ok and rgb is not None else None,
        )
      )
      materials.append(config.materials[k])
  return pending, materials, redrawn


def _run_call(sweep, workdir, writers, c, todo, tally, counts, bar) -> None:
  """Simulates, renders and writes call ``c``'s unwritten sequences (``todo``),
  adding to ``tally`` and ``counts``."""
  world_jobs, first_world, names, noise_keys, out, dt = _simulate(sweep, todo)
  seconds = tally.seconds
  tally.sim_calls += 1
  if c == 0:
    seconds['simulate_first_batches'] += dt
  else:
    seconds['simulate'] += dt
    tally.frames_simulated += len(world_jobs) * sweep.config.frames
  frames, render_s, redraw_s = _render(sweep, world_jobs, names, noise_keys, out)
  if seconds['first_render_call'] is None:
    seconds['first_render_call'] = render_s  # includes the compile
  else:
    seconds['render'] += render_s
    tally.frames_rendered += frames[1].size // (sweep.config.resolution**2)
  seconds['redraw'] += redraw_s
  t0 = time.perf_counter()
  pending, materials, redrawn = _write(
    sweep, workdir, writers, todo, first_world, out.valid, frames
  )
  tally.cameras_redrawn += redrawn
  for material in materials:
    counts[material]['written'] += 1
  for f in concurrent.futures.as_completed(pending):
    f.result()  # re-raises a failed write
  bar.done(len(pending))
  if jax.process_count() == 1:  # one process: the index follows every call
    dataset.rebuild_index(workdir)
  seconds['write'] += time.perf_counter() - t0


def _montages(workdir: str, config: Config, counts: dict, rows: list) -> dict:
  """Each material's montage (drawn again where it wrote), its valid and
  invalid counts filled in ``counts`` from the index ``rows``."""
  main = distributed.is_main()
  montages = {}
  for material in config.materials:
    mrows = [r for r in rows if r['material'] == material]
    counts[material]['valid'] = sum(r['valid'] for r in mrows)
    counts[material]['invalid'] = sum(not r['valid'] for r in mrows)
    drawn = dataset_folder.montage_path(workdir, material)
    if not main:
      montages[material] = None
    elif counts[material]['written'] == 0 and os.path.isfile(drawn):
      montages[material] = drawn  # a resumed sweep: the same sequences as drawn
    else:
      montages[material] = dataset_folder.montage(workdir, material, mrows)
  return montages


def _summary(sweep: _Sweep, counts: dict, tally: _Tally, montages: dict) -> dict:
  """``run``'s summary: counts, seconds and rates."""
  config, seconds = sweep.config, tally.seconds
  sim_total = seconds['simulate'] + seconds['simulate_first_batches']
  return {
    'backend': sweep.backend,
    'device': jax.default_backend(),
    'counts': counts,
    'sequences_written': sum(c['written'] for c in counts.values()),
    'seconds': seconds,
    'frames_rendered_after_compile': tally.frames_rendered,
    'cameras_redrawn': tally.cameras_redrawn,  # min_coverage: poses drawn again
    'render_frames_per_s': tally.frames_rendered / seconds['render']
    if seconds['render']
    else None,
    'frames_simulated_after_first_batches': tally.frames_simulated,
    'simulated_world_frames_per_s_with_compile': (
      tally.sim_calls * sweep.per_call * config.batch_size * config.frames / sim_total
      if sim_total
      else None
    ),
    'simulated_world_frames_per_s': (
      tally.frames_simulated / seconds['simulate'] if seconds['simulate'] else None
    ),
    'montages': montages,
    'processes': jax.process_count(),
  }


def run(config: Config, workdir: str, params: dict | None = None) -> dict:
  """Generates (or resumes) the dataset in ``workdir``; returns the summary.

  Args:
    config: the sweep.
    workdir: dataset root (``physsim.dataset`` layout).
    params: optional ``{material: physsim.Params}`` with ``sequences``
      parameter sets each, instead of the seeded uniform draw (a study that
      needs recordings sharing some parameters); recorded in dataset.json.

  Returns:
    The summary also written to ``<workdir>/summary.json``: counts per
    material, seconds simulating / rendering / writing, frames per second.
  """
  sweep = _plan(config, *_open(config, workdir, params))
  bs, many = config.batch_size, jax.process_count() > 1
  n_batches = -(-len(sweep.jobs) // bs)
  tally = _Tally()
  counts = {
    m: {'existing': 0, 'written': 0, 'valid': 0, 'invalid': 0} for m in config.materials
  }
  mine = distributed.share(list(range(len(sweep.calls))))
  bar = progress.Bar(
    sum(len(sweep.jobs[b * bs : (b + 1) * bs]) for c in mine for b in sweep.calls[c]),
    'simulate + render',
    'seq',
  )
  # --time_limit's forecast of the next call: the last one's time, less its
  # compile and set-up (the calls of a sweep run one program shape)
  last_call_s, one_off = 0.0, physsim.one_off.Meter()
  with concurrent.futures.ThreadPoolExecutor(_WRITERS) as writers:
    for c in mine:
      todo, written = _unwritten(sweep, workdir, c)
      for k, _ in written:
        counts[config.materials[k]]['existing'] += 1
      bar.skip(len(written))
      if not todo:
        continue
      first, last = sweep.calls[c][0] + 1, sweep.calls[c][-1] + 1
      deadline.check(
        last_call_s,
        f'batch {first} of {n_batches}'
        if first == last
        else f'batches {first}-{last} of {n_batches}',
      )
      t_call = time.perf_counter()
      one_off.mark()
      _run_call(sweep, workdir, writers, c, todo, tally, counts, bar)
      last_call_s = max(time.perf_counter() - t_call - one_off.seconds(), 0.0)
  bar.close()
  if many:  # each process's counts, for process 0's summary
    dataset.write_json_atomic(
      os.path.join(workdir, f'.counts.{jax.process_index()}.json'), counts
    )
  distributed.barrier(f'dataset {workdir}: written')
  if many:
    counts = dataset_folder.gathered_counts(workdir, config.materials)
  main = distributed.is_main()
  rows = dataset.rebuild_index(workdir) if main else []
  montages = _montages(workdir, config, counts, rows)
  summary = _summary(sweep, counts, tally, montages)
  if main:
    dataset.write_json_atomic(os.path.join(workdir, 'summary.json'), summary)
  distributed.barrier(f'dataset {workdir}: indexed')  # the index is whole for all
  return summary


def describe(s: dict, out: str) -> str:
  """A summary from ``run`` as a short report: counts per material and timings."""
  lines = [
    f'{out}: {s["sequences_written"]} sequences written ({s["backend"]} backend, '
    f'{s["device"]})',
    '| material | existing | written | valid | invalid |',
    '|---|---:|---:|---:|---:|',
  ]
  for m, c in s['counts'].items():
    lines.append(
      f'| {m} | {c["existing"]} | {c["written"]} | {c["valid"]} | {c["invalid"]} |'
    )
  sec = s['seconds']
  nan = float('nan')
  lines.append(
    f'simulate: first batch (with compile) {sec["simulate_first_batches"]:.1f} s, '
    f'later batches {sec["simulate"]:.1f} s '
    f'({s["simulated_world_frames_per_s"] or nan:.1f} world-frames/s); render: first '
    f'call (with compile) {sec["first_render_call"] or 0:.1f} s, later '
    f'{sec["render"]:.1f} s ({s["render_frames_per_s"] or nan:.0f} frames/s); '
    f'write {sec["write"]:.1f} s'
  )
  return '\n'.join(lines)
