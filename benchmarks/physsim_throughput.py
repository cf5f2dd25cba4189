"""Cloth simulation throughput: the project's device rollouts ('warp': MuJoCo
Warp a frame at a time; 'mjx': ``mjx.step`` per substep) vs MuJoCo Warp called
directly and MuJoCo C, side by side in one process.

Prints a markdown table and writes JSON. World-steps/s counts one MuJoCo step of
one cloth (with the JAX or NumPy wind and bending forces of that step). Compile
time is reported apart from run time. The paper's dataset is 7 materials x 30
parameter sets x 3 s (plus our 1 s warm-up from rest).

``--direct`` adds MuJoCo Warp called directly on the same MjModel (the copy MJX
runs, so its kernels are compiled once): the same worlds, solver and settings,
``mjw.step`` in a loop captured as one CUDA graph, a constant force in place of
the project's per-step wind and bending (which MuJoCo Warp alone does not
have); the project's rollouts at the same batch are compared with it.
``--ablate_forces`` adds the project's rollouts with that same constant force in
place of their wind and bending (an ablation, patched in this benchmark only):
for 'mjx', what the per-step hand-over between JAX and MuJoCo Warp costs
without the forces; for 'warp', also at the direct run's masses (area weight
0.2), i.e. the direct run's physics through the project's frame calls.
``--event_trace`` times the parts of MuJoCo Warp's step in the direct run
(its own event scopes: smooth dynamics, constraints, solver, integration).

  python -m benchmarks.physsim_throughput --batch_sizes=1,8,64 --out=out/physsim_cpu.json
  python -m benchmarks.physsim_throughput --batch_sizes=210,1024 --direct --paper_dataset
  python -m benchmarks.physsim_throughput --backends=warp --c_baseline=false
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import multiprocessing
import os
import platform
import time
from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline import cli, files
from physsim import rollout as sim


@dataclasses.dataclass(frozen=True)
class Args:
  """The simulation-throughput benchmark. The solver overrides (iterations,
  solver, edge_solref, tolerance, ls_iterations, graph_mode) leave the
  project's setting where 0 or empty.

  Attributes:
    resolution: cloth vertices per side.
    batch_sizes: device batch sizes (comma-separated).
    backends: the project's device rollouts to time (warp, mjx).
    seconds: simulated seconds per timed MJX call.
    c_seconds: simulated seconds per world for MuJoCo C.
    c_worlds_per_core: worlds each C process simulates.
    repeats: timed MJX calls per batch size (median).
    paper_dataset: also time 210 sequences x (1+3) s directly.
    gust_intensity: RMS gust intensity of the benchmarked wind.
    iterations: override the solver iteration cap (0: the project's).
    solver: override the solver ('CG' or 'Newton'; empty: the project's).
    edge_solref: override the edges' constraint time constant, s (0: the
      project's).
    tolerance: override the solver's relative tolerance (0: the project's).
    ls_iterations: override the solver's line-search iterations (MuJoCo's opt;
      0: the project's).
    event_trace: time the parts of MuJoCo Warp's step (direct).
    save_last: save each device row's last frame (.npz) to compare settings.
    graph_mode: override MJX's graph mode (empty: the project's).
    direct: also time MuJoCo Warp called directly (module doc).
    ablate_forces: also time the rollout with the direct run's constant force.
    c_baseline: also time MuJoCo C on 1 and all cores.
    out: JSON output path.
  """

  resolution: int = 25
  batch_sizes: tuple[int, ...] = (1, 16, 256, 1024, 4096)
  backends: tuple[str, ...] = ('warp', 'mjx')
  seconds: float = 0.5
  c_seconds: float = 0.5
  c_worlds_per_core: int = 1
  repeats: int = 2
  paper_dataset: bool = False
  gust_intensity: float = 0.2
  iterations: int = 0
  solver: str = cli.choice('', ['', 'CG', 'Newton'])
  edge_solref: float = 0.0
  tolerance: float = 0.0
  ls_iterations: int = 0
  event_trace: bool = False
  save_last: str = ''
  graph_mode: str = cli.choice('', ['', 'auto', 'jax', 'warp'])
  direct: bool = False
  ablate_forces: bool = False
  c_baseline: bool = True
  out: str = 'out/benchmarks/physsim_throughput.json'


PRESETS = {
  'default': Args(),
  # checks the script on a CPU in about a minute (the MJX rollout compiles)
  'smoke': Args(
    resolution=8,
    batch_sizes=(1, 2),
    backends=('mjx',),
    seconds=0.05,
    c_seconds=0.05,
    repeats=1,
  ),
}

_PAPER_SEQUENCES, _PAPER_SECONDS, _WARMUP = 210, 3.0, 1.0


def _params(b, seed=0):
  return physsim.params.sample(np.random.default_rng(seed), b, physsim.SearchSpace())


def _inputs(model, p, wind, key) -> physsim.WorldInputs:
  """World inputs of parameter sets ``p``, one gust key per world from ``key``."""
  p = physsim.params.make(*(np.atleast_1d(x) for x in p))
  keys = jax.random.split(key, p.bending_scale.shape[0])
  return physsim.world_inputs(model, *p, keys, wind)


def edge_strain_p99(mesh, xs, valid) -> float:
  """p99 |edge length / rest length - 1| over the valid worlds' last frame:
  how well the solver held the cloth's edges at this iteration cap."""
  f = np.asarray(mesh.faces)
  edges = np.unique(
    np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [0, 2]]]), 1), axis=0
  )
  rest = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
  last = np.asarray(xs)[np.asarray(valid), -1]  # (B', V, 3)
  if not len(last):
    return float('nan')
  length = np.linalg.norm(last[:, edges[:, 0]] - last[:, edges[:, 1]], axis=-1)
  return float(np.quantile(np.abs(length / rest - 1), 0.99))


def _constant_force(c, model, qpos, qvel, t, w):
  """The direct run's force (a steady push of half the weight) on the moving
  vertices, in place of ``rollout._applied_forces`` (same signature)."""
  del model, qpos, qvel, t
  lift = 0.5 * 9.81 * w.body_mass[c.body]
  return jnp.zeros((c.body.shape[0], 3), lift.dtype).at[:, 1].set(lift)


def _ablated_row(args: Args, model, b, backend):
  """The device row with the direct run's constant force in place of the wind
  and bending (programs rebuilt); for 'warp' also at the direct run's masses."""
  model.programs.clear()
  if backend == 'mjx':
    with mock.patch.object(sim, '_applied_forces', _constant_force):
      row = _device_row(args, model, b, 'mjx')
  else:
    import warp as wp
    from mujoco.mjx.third_party import mujoco_warp as mjw

    from physsim import warp_frames

    def substeps(self):
      if not hasattr(self, 'push'):  # the eager first frame, before capture
        x = np.zeros((self.d.qpos.shape[0], model.mj_model.nbody, 6), np.float32)
        bodies = model.vert_body[model.vert_qadr >= 0]
        x[:, bodies, 1] = 0.5 * 9.81 * model.mj_model.body_mass[bodies]
        self.push = wp.array(x, dtype=wp.spatial_vector, device=self.d.qpos.device)
      for _ in range(self.substeps):
        wp.copy(self.d.xfrc_applied, self.push)
        mjw.step(self.m, self.d)

    with mock.patch.object(warp_frames._Worlds, '_substeps', substeps):
      row = _device_row(args, model, b, 'warp', area_weight=0.2)
  model.programs.clear()
  return {**row, 'backend': f'{backend}, constant force (ablation)'}


def _device_row(args: Args, model, b, backend, area_weight=None):
  frames = max(1, round(args.seconds * 20))
  fn = sim.jit_program(model, frames, 20.0, 0.0, backend=backend)
  wind = physsim.Wind(gust_intensity=args.gust_intensity)

  def params(seed):
    p = _params(b, seed)
    return p if area_weight is None else p._replace(area_weight=np.full(b, area_weight))

  w = _inputs(model, params(0), wind, jax.random.key(0))
  t0 = time.perf_counter()
  compiled = fn.lower(w).compile()
  compile_s = time.perf_counter() - t0
  times, valid = [], None
  for r in range(args.repeats + 1):  # first call warms caches/graphs
    w = _inputs(model, params(r), wind, jax.random.key(r))
    t0 = time.perf_counter()
    xs, valid = jax.block_until_ready(compiled(w))
    if r:
      times.append(time.perf_counter() - t0)
  if args.save_last and area_weight is None:  # the last timed call's worlds
    base, _ = os.path.splitext(args.save_last)
    np.savez(f'{base}_{backend}_{b}.npz', last=np.asarray(xs[:, -1]), valid=valid)
  steps = b * frames * round(0.05 / model.config.timestep)
  run_s = float(np.median(times))
  return {
    'backend': backend,
    'batch': b,
    'compile_s': compile_s,
    'run_s': run_s,
    'world_steps_per_s': steps / run_s,
    'valid_fraction': float(np.mean(valid)),
    'edge_strain_p99': edge_strain_p99(model.mesh, xs, valid),
  }


def _direct_row(args: Args, model, b):
  """MuJoCo Warp's own step on the same model, ``b`` worlds (module doc)."""
  import mujoco
  import warp as wp
  from mujoco.mjx.third_party import mujoco_warp as mjw

  mjm = model.mj_model
  mjd = mujoco.MjData(mjm)
  mujoco.mj_forward(mjm, mjd)
  m = mjw.put_model(mjm)
  m.opt.run_collision_detection = False  # as the project's rollouts, which also
  m.opt.warn_overflow = int(m.opt.warn_overflow) & ~int(mjw.OverflowType.ITERATIONS)
  d = mjw.put_data(mjm, mjd, nworld=b, njmax=mjm.nflexedge + 8)
  bodies = model.vert_body[model.vert_qadr >= 0]
  x = np.zeros((b, mjm.nbody, 6), np.float32)  # a steady push of half the weight
  x[:, bodies, 1] = 0.5 * 9.81 * mjm.body_mass[bodies]
  wp.copy(d.xfrc_applied, wp.array(x, dtype=wp.spatial_vector, device=d.qpos.device))
  steps = max(1, round(args.seconds / model.config.timestep))
  cuda = d.qpos.device.is_cuda
  t0 = time.perf_counter()
  if cuda:
    with wp.ScopedCapture(device=d.qpos.device) as capture:
      for _ in range(steps):
        mjw.step(m, d)
    run = lambda: wp.capture_launch(capture.graph)
  else:
    run = lambda: [mjw.step(m, d) for _ in range(steps)]
  run()
  wp.synchronize()
  compile_s = time.perf_counter() - t0  # first pass: kernels, graph, caches
  times = []
  for _ in range(args.repeats):
    t0 = time.perf_counter()
    run()
    wp.synchronize()
    times.append(time.perf_counter() - t0)
  run_s = float(np.median(times))
  qpos = d.qpos.numpy()
  row = {
    'backend': 'mujoco-warp direct',
    'batch': b,
    'compile_s': compile_s,
    'run_s': run_s,
    'world_steps_per_s': b * steps / run_s,
    'valid_fraction': float(np.mean(np.all(np.isfinite(qpos), axis=1))),
  }
  if args.event_trace and cuda:
    row['event_ms_per_step'] = _event_trace(m, d)
  return row


def _event_trace(m, d, steps=10, before=None):
  """Milliseconds per step in each of MuJoCo Warp's event scopes (two levels);
  ``before(k)`` launches what precedes step ``k`` (the project's forces)."""
  import warp as wp
  from mujoco.mjx.third_party import mujoco_warp as mjw
  from mujoco.mjx.third_party.mujoco_warp._src import warp_util

  with warp_util.EventTracer() as tracer:
    with wp.ScopedCapture(device=d.qpos.device) as capture:
      for k in range(steps):
        if before is not None:
          before(k)
        mjw.step(m, d)
    wp.capture_launch(capture.graph)
    wp.synchronize()
    trace = tracer.trace()

  def flat(t, prefix='', depth=0):
    out = {}
    for name, (events, sub) in t.items():
      out[prefix + name] = sum(events) / steps
      if depth < 2:
        out.update(flat(sub, f'{prefix}{name}/', depth + 1))
    return out

  return flat(trace)


def _project_trace(args: Args, model, b, seconds=1.0):
  """``_event_trace`` of the project's 'warp' frame (its forces, then MuJoCo
  Warp's step) on ``b`` worlds after ``seconds`` of gusty wind from rest: the
  same parts as the direct run's trace, on the project's physics."""
  import warp as wp

  from physsim import warp_frames

  wind = physsim.Wind(gust_intensity=args.gust_intensity)
  w = jax.tree.map(np.asarray, _inputs(model, _params(b), wind, jax.random.key(0)))
  substeps = round(0.05 / model.config.timestep)
  device = wp.get_device()
  mjm = model.mj_model
  st = warp_frames._Worlds(model, b, w.gusts.wavevector.shape[1], substeps, device)
  with wp.ScopedDevice(device):
    arr = lambda a, dtype=float: wp.array(np.asarray(a, np.float32), dtype=dtype)
    zeros = np.zeros((b, mjm.nv))
    st.load(
      arr(np.broadcast_to(mjm.qpos0, (b, mjm.nq))), arr(zeros), arr(zeros),
      arr([0.0]), arr(w.speed), arr(w.direction, wp.vec3), arr(w.bending),
      arr(w.gusts.wavevector, wp.vec3), arr(w.gusts.direction, wp.vec3),
      arr(w.gusts.amplitude), arr(w.gusts.phase), arr(w.body_mass),
    )  # fmt: skip
    for i in range(round(seconds * 20)):
      wp.copy(st.inputs.time, arr([i * 0.05]))
      st._substeps()
    return _event_trace(st.m, st.d, before=st.forces)


def _c_job(job):
  mesh, material, config, b, seconds, gusts, seed = job
  model = physsim.build(mesh, material, config)
  p = _params(b, seed)
  p = physsim.params.make(*(np.atleast_1d(x) for x in p))
  wind = physsim.Wind(gust_intensity=gusts)
  w = jax.tree.map(np.asarray, _inputs(model, p, wind, jax.random.key(seed)))._asdict()
  w['body_mass'] = model.body_masses(p.area_weight)
  w['speed'], w['bending'] = p.wind_speed, p.bending_scale
  frames = max(1, round(seconds * 20))
  substeps = round(0.05 / config.timestep)
  t0 = time.perf_counter()
  xs, valid = sim._c_rollout(model, w, frames, substeps, 0, workers=1)
  return time.perf_counter() - t0, b * frames * substeps, float(valid.mean())


def _c_row(args: Args, model, cores):
  jobs = [
    (
      model.mesh,
      model.material,
      model.config,
      args.c_worlds_per_core,
      args.c_seconds,
      args.gust_intensity,
      i,
    )
    for i in range(cores)
  ]
  if cores == 1:
    results = [_c_job(jobs[0])]
  else:
    ctx = multiprocessing.get_context('spawn')
    with (
      sim.cpu_only_children(),
      concurrent.futures.ProcessPoolExecutor(cores, mp_context=ctx) as pool,
    ):
      results = list(pool.map(_c_job, jobs))
  wall = max(r[0] for r in results)  # all processes run at once
  steps = sum(r[1] for r in results)
  return {
    'backend': f'mujoco-c x{cores}',
    'batch': cores * args.c_worlds_per_core,
    'compile_s': 0.0,
    'run_s': wall,
    'world_steps_per_s': steps / wall,
    'valid_fraction': float(np.mean([r[2] for r in results])),
  }


def _paper_dataset(model, backend):
  """All 210 paper sequences (60 frames at 20 Hz after 1 s warm-up) in one call."""
  fn = sim.jit_program(model, 60, 20.0, _WARMUP, backend=backend)
  p = _params(_PAPER_SEQUENCES, 123)
  w = _inputs(model, p, physsim.Wind(gust_intensity=0.2), jax.random.key(1))
  t0 = time.perf_counter()
  compiled = fn.lower(w).compile()
  compile_s = time.perf_counter() - t0
  jax.block_until_ready(compiled(w))
  t0 = time.perf_counter()
  xs, valid = jax.block_until_ready(compiled(w))
  return {
    'compile_s': compile_s,
    'run_s': time.perf_counter() - t0,
    'valid_fraction': float(np.mean(valid)),
  }


def _model(args: Args):
  """The benchmark's cloth with the solver settings the flags override."""
  batch_sizes = list(args.batch_sizes)
  if not batch_sizes or min(batch_sizes) < 1:
    raise ValueError(f'--batch_sizes={",".join(map(str, batch_sizes))}: need positive')
  bad = [b for b in args.backends if b not in ('warp', 'mjx')]
  if bad or not args.backends:
    raise ValueError(f'--backends={",".join(args.backends)}: need warp and/or mjx')
  overrides = {
    k: v
    for k, v in (
      ('iterations', args.iterations), ('solver', args.solver),
      ('edge_solref', args.edge_solref), ('tolerance', args.tolerance),
      ('graph_mode', args.graph_mode),
    )
    if v
  }  # fmt: skip
  config = physsim.SimConfig(**overrides)
  model = physsim.build(physsim.square(args.resolution), 'gray_interlock', config)
  if args.ls_iterations:  # not a SimConfig setting: patched on the compiled model
    model.mj_model.opt.ls_iterations = args.ls_iterations
  return model


def _rows(args: Args, model, cores: int) -> list[dict]:
  """MuJoCo C's rows, then per batch size each backend's (ablated, traced,
  against MuJoCo Warp direct where asked)."""
  rows = [_c_row(args, model, 1), _c_row(args, model, cores)] if args.c_baseline else []
  for b in args.batch_sizes:
    project = []
    for backend in args.backends:
      project.append(_device_row(args, model, b, backend))
      print(project[-1], flush=True)
    for backend in args.backends if args.ablate_forces else ():
      project.append(_ablated_row(args, model, b, backend))
      print(project[-1], flush=True)
    rows += project
    if args.event_trace and 'warp' in args.backends and jax.default_backend() == 'gpu':
      row = next(r for r in project if r['backend'] == 'warp')
      row['event_ms_per_step'] = _project_trace(args, model, b)
    if args.direct:
      rows.append(_direct_row(args, model, b))
      for r in project:
        r['x_direct'] = r['world_steps_per_s'] / rows[-1]['world_steps_per_s']
      print(rows[-1], flush=True)
  paper_steps = _PAPER_SEQUENCES * (_PAPER_SECONDS + _WARMUP) / model.config.timestep
  for r in rows:
    r['paper_dataset_s'] = paper_steps / r['world_steps_per_s']
  return rows


def _print(args: Args, model, result: dict, cores: int) -> None:
  rows = result['rows']
  c_all = rows[1]['world_steps_per_s'] if args.c_baseline else float('nan')
  print(
    f'\n{args.resolution}x{args.resolution} cloth, dt {model.config.timestep * 1e3:g} ms, '
    f'{result["solver"]}, device {jax.devices()[0]}, {cores} CPU cores'
  )
  print(
    '| backend | batch | world-steps/s | x C all cores | x MuJoCo Warp direct | '
    'compile s | paper dataset s | valid | edge strain p99 |'
  )
  print('|---|---:|---:|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["backend"]} | {r["batch"]} | {r["world_steps_per_s"]:,.0f} | '
      f'{r["world_steps_per_s"] / c_all:.2f} | {r.get("x_direct", float("nan")):.2f} | '
      f'{r["compile_s"]:.1f} | {r["paper_dataset_s"]:,.1f} | {r["valid_fraction"]:.3f} | '
      f'{100 * r.get("edge_strain_p99", float("nan")):.2f}% |'
    )
  for r in rows:
    for name, ms in r.get('event_ms_per_step', {}).items():
      print(f'  {r["batch"]} worlds, {name}: {ms:.3f} ms per step')
  for backend, d in result.get('paper_dataset', {}).items():
    print(
      f'\nPaper dataset, 210 x (1+3) s in one {backend} call: {d["run_s"]:.2f} s '
      f'after {d["compile_s"]:.1f} s compile; valid {d["valid_fraction"]:.3f}'
    )


def main(args: Args) -> None:
  model = _model(args)
  cores = os.cpu_count() or 1
  rows = _rows(args, model, cores)
  result = {
    'machine': {
      'platform': platform.platform(),
      'cpu_cores': cores,
      'jax_device': str(jax.devices()[0]),
      'jax': jax.__version__,
    },
    'resolution': args.resolution,
    'timestep': model.config.timestep,
    'solver': f'{model.config.solver} x{model.config.iterations}',
    'ls_iterations': int(model.mj_model.opt.ls_iterations),
    'sim_config': dataclasses.asdict(model.config),
    'devices': [str(d) for d in jax.local_devices()],
    'rows': rows,
  }
  if args.paper_dataset:
    result['paper_dataset'] = {b: _paper_dataset(model, b) for b in args.backends}
  _print(args, model, result, cores)
  files.write_json(args.out, result)
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
