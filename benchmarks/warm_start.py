"""Process start to table as a user runs an estimate: where the time goes.

Issue 41 asks for one estimate within 35 s of the process start with warm
caches, and for the time per stage in the benchmark's table. This runs
``python -m experiments.estimate`` as a user does, ``--runs`` times in a row
in fresh workdirs, each a new process, and stamps every line it prints with the
seconds since that process started. With ``JAX_LOG_COMPILES=1`` JAX logs each
jit's tracing, its lowering to MLIR and its compile (or the load of a cached
executable), so the log says how much of a stage is JAX's set-up and how much
is running.

The caches: ``--cache=DIR`` gives JAX's persistent compilation cache
(``DIR/jax``) and Warp's kernel cache (``DIR/warp``) to every run, so the first
run of an empty DIR starts cold and the later ones warm; the default is a new
temporary DIR (a cold first run); ``--cache=user`` leaves the user's own caches.
``--devices=all,0`` runs the whole series once per ``CUDA_VISIBLE_DEVICES``
setting ('all': unset). ``--profile`` adds one warm run under cProfile and
writes its heaviest functions.

  python -m benchmarks.warm_start --recording=/tmp/df/recordings/gray_interlock/0000 \
      --material=gray_interlock --runs=3 --profile --out=$OUT/warm_start.json

Stages (from the estimate's own lines): ``imports`` (process start to its first
line), ``before search`` (reading, aligning, building the problem, up to the
first simulations), ``first step`` (the first call of the fused objective: on a
warm start mostly tracing, loading the cached program and the simulator's
set-up), ``later steps`` and ``after search`` (the table, estimate.json,
pictures, exit). Prints a table and writes JSON.
"""

from __future__ import annotations

import dataclasses
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

from experiments.pipeline import cli, files

_STEP = re.compile(
  r'^iteration +(\d+): .*\((\d+) simulations ([\d.]+) s, search ([\d.]+) s(?:; [^)]*)?\)'
)
_FIRST = re.compile(r': \d+ recordings? into ')
_TABLE = re.compile(r'^\| quantity ')
# JAX's compile log (jax_log_compiles), in its 0.4-0.11 wordings
_JAX = {
  'tracing': re.compile(r'Finished tracing(?: \+ transforming)? (.+?) for p?jit in ([\d.]+) sec'),
  'lowering': re.compile(r'Finished jaxpr to MLIR module conversion (.+?) in ([\d.]+) sec'),
  'compile_or_load': re.compile(r'Finished XLA compilation of (.+?) in ([\d.]+) sec'),
}  # fmt: skip
_HIT = re.compile(r'Persistent compilation cache hit for')
# The estimate under cProfile as ``__main__`` (``python -m cProfile -m`` keeps
# its own ``__main__``, where the flag parser cannot resolve the estimate's
# type hints); cProfile writes the dump when the script exits.
_PROFILED = (
  'import cProfile, runpy, sys; dump = sys.argv[1]; '
  "sys.argv = ['experiments.estimate', *sys.argv[2:]]; "
  "cProfile.runctx(\"runpy.run_module('experiments.estimate', "
  "run_name='__main__', alter_sys=True)\", globals(), None, dump)"
)


@dataclasses.dataclass(frozen=True)
class Args:
  """The warm-start benchmark.

  Attributes:
    recording: the recording the estimate reads (required).
    material: its fabric.
    runs: processes per device setting, one after the other.
    cache: where JAX's and Warp's caches live ('' a new temporary folder, so
      the first run is cold; 'user': the user's own caches).
    devices: CUDA_VISIBLE_DEVICES settings to run the series under ('all':
      every device).
    profile: one more warm run under cProfile (the main thread's Python).
    flags: more flags for every estimate, space separated.
    out: JSON result; each run's stamped log is written beside it.
  """

  recording: str = cli.required()
  material: str = 'gray_interlock'
  runs: int = 3
  cache: str = ''
  devices: tuple[str, ...] = ('all',)
  profile: bool = False
  flags: str = ''
  out: str = 'out/benchmarks/warm_start.json'


PRESETS = {'default': Args()}


def run_stamped(cmd: list[str], env: dict, log: str) -> tuple[list, float, int]:
  """Runs ``cmd``; returns its output lines as (seconds since the start,
  text), its wall seconds and exit status, and writes them to ``log``."""
  t0 = time.perf_counter()
  proc = subprocess.Popen(
    cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    bufsize=1,
  )  # fmt: skip
  lines = [(time.perf_counter() - t0, line.rstrip('\n')) for line in proc.stdout]
  rc = proc.wait()
  wall = time.perf_counter() - t0
  files.write_text(
    log, ''.join(f'{t:8.3f} {s}\n' for t, s in lines) + f'{wall:8.3f} exit {rc}\n'
  )
  return lines, wall, rc


def stages(lines: list, wall: float) -> dict:
  """Per-stage seconds of one run from its stamped lines (module doc)."""
  first = next((t for t, s in lines if _FIRST.search(s)), float('nan'))
  table = next((t for t, s in lines if _TABLE.search(s)), float('nan'))
  steps = [(t, m) for t, s in lines if (m := _STEP.search(s))]
  out = {'total': wall, 'to_table': table, 'imports': first}
  if steps:
    t_first, m0 = steps[0]
    step0 = float(m0.group(3)) + float(m0.group(4))
    out.update({
      'before_search': t_first - step0 - first,
      'first_step': step0,
      'later_steps': steps[-1][0] - t_first,
      'to_table_after_search': table - steps[-1][0],
      'after_search': wall - steps[-1][0],
      'steps': len(steps),
    })  # fmt: skip
  return out


def jax_times(lines: list) -> dict:
  """JAX's compile log summed: seconds per phase, cache hits, the programs
  that took longest (tracing + lowering + compile or load)."""
  per_fn: dict[str, float] = {}
  sums = dict.fromkeys(_JAX, 0.0)
  hits = 0
  for _, s in lines:
    hits += bool(_HIT.search(s))
    for phase, pattern in _JAX.items():
      if m := pattern.search(s):
        sums[phase] += float(m.group(2))
        name = re.sub(r'^(jit|pjit)\((.*)\)$', r'\2', m.group(1))
        per_fn[name] = per_fn.get(name, 0.0) + float(m.group(2))
  top = sorted(per_fn.items(), key=lambda kv: -kv[1])[:8]
  return {**sums, 'cache_hits': hits, 'top': [[k, round(v, 3)] for k, v in top]}


def profile_top(path: str, n: int = 30) -> list:
  """The ``n`` functions with the most cumulative time in a cProfile dump."""
  import pstats  # noqa: PLC0415 - only with --profile

  st = pstats.Stats(path)
  rows = []
  for (file, line, fn), (_, calls, tot, cum, _) in st.stats.items():
    rows.append((cum, tot, calls, f'{os.path.basename(file)}:{line}({fn})'))
  rows.sort(reverse=True)
  return [
    {'function': f, 'cumulative_s': round(c, 3), 'own_s': round(t, 3), 'calls': k}
    for c, t, k, f in rows[:n]
  ]


def main(args: Args) -> None:
  if args.runs < 1:
    raise ValueError(f'--runs must be at least 1, got {args.runs}')
  out_dir = os.path.dirname(os.path.abspath(args.out))
  scratch = tempfile.mkdtemp(prefix='warm_start_')
  cache = args.cache or os.path.join(scratch, 'cache')
  env = dict(os.environ, JAX_LOG_COMPILES='1', PYTHONUNBUFFERED='1')
  if cache != 'user':
    env.update(PHYSNET_JAX_CACHE=f'{cache}/jax', WARP_CACHE_PATH=f'{cache}/warp')
  base = [
    sys.executable, '-m', 'experiments.estimate', f'--recording={args.recording}',
    f'--material={args.material}', *args.flags.split(),
  ]  # fmt: skip
  rows = []
  try:
    for devices in args.devices:
      denv = dict(env)
      if devices != 'all':
        denv['CUDA_VISIBLE_DEVICES'] = devices
      tag = 'all' if devices == 'all' else f'gpu{devices.replace(",", "_")}'
      for k in range(args.runs + args.profile):
        prof = args.profile and k == args.runs
        workdir = os.path.join(scratch, f'{tag}_{k}')
        cmd = list(base)
        if prof:
          dump = os.path.join(out_dir, f'warm_start_{tag}.prof')
          cmd[1:3] = ['-c', _PROFILED, dump]
        log = os.path.join(out_dir, f'warm_start_{tag}_{k}.log')
        lines, wall, rc = run_stamped([*cmd, f'--workdir={workdir}'], denv, log)
        row = {
          'devices': devices, 'run': k, 'profiled': prof, 'exit': rc,
          'stages': stages(lines, wall), 'jax': jax_times(lines),
        }  # fmt: skip
        if prof and rc == 0:
          row['profile_top'] = profile_top(dump)
        rows.append(row)
        print(
          f'{tag} run {k}{" (cProfile)" * prof}: {wall:.1f} s, exit {rc}', flush=True
        )
        if rc != 0:
          print('\n'.join(s for _, s in lines[-15:]), flush=True)
  finally:
    shutil.rmtree(scratch, ignore_errors=True)
  print(
    '| devices | run | to table s | total s | imports | before search | '
    'first step | later steps | search to table | after search | JAX tracing | '
    'lowering | compile or load | cache hits |'
  )
  print('|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
  for r in rows:
    s, j = r['stages'], r['jax']
    cells = [s.get(k, float('nan')) for k in (
      'to_table', 'total', 'imports', 'before_search', 'first_step', 'later_steps',
      'to_table_after_search', 'after_search',
    )]  # fmt: skip
    cells += [j['tracing'], j['lowering'], j['compile_or_load']]
    run = f'{r["run"]}{" (cProfile)" * r["profiled"]}'
    print(
      f'| {r["devices"]} | {run} | '
      + ' | '.join(f'{c:.1f}' for c in cells)
      + f' | {j["cache_hits"]} |'
    )
  last = next((r for r in reversed(rows) if not r['profiled']), rows[-1])
  print('programs with the most JAX set-up time, last plain run (s):')
  for name, sec in last['jax']['top']:
    print(f'  {sec:7.2f}  {name}')
  files.write_json(args.out, {
    'recording': args.recording, 'material': args.material, 'flags': args.flags,
    'cache': 'user' if cache == 'user' else ('given' if args.cache else 'fresh'),
    'rows': rows,
  })  # fmt: skip
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
