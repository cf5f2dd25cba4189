"""Where the estimate's GP should run: the same BO search with its GP on the CPU
and on JAX's default device (a GPU), side by side in one process.

Times every ``Minimizer.ask`` (GP fit + q-point proposal) of a short search on a
cheap quadratic, and the final ``minimizer_samples`` (the estimate's
uncertainty), twice per device: the first pays the compiles.

  python benchmarks/gp_placement.py --out=out/gp_placement.json
"""

from __future__ import annotations

import json
import time

import jax
import numpy as np
from absl import app, flags

import bo
from experiments.pipeline import files

FLAGS = flags.FLAGS
flags.DEFINE_integer('q', 4, 'points per proposal (the estimate default)')
flags.DEFINE_integer('n_init', 8, 'initial design')
flags.DEFINE_integer('n_iter', 6, 'proposals')
flags.DEFINE_string('out', 'out/gp_placement.json', 'JSON result')

BOUNDS = np.array([[-1.0, 1.0]] * 3)


def _search(device, seed: int) -> dict:
  opt = bo.Minimizer(
    BOUNDS, n_init=FLAGS.n_init, n_iter=FLAGS.n_iter, q=FLAGS.q, seed=seed,
    device=device, stop_rel_change=None,
  )  # fmt: skip
  state, ask_s = opt.start(), 0.0
  while not opt.done(state):
    t = time.perf_counter()
    x, state = opt.ask(state)
    ask_s += time.perf_counter() - t
    state = opt.tell(state, x, np.sum((np.asarray(x) - 0.3) ** 2, axis=1))
  t = time.perf_counter()
  with jax.default_device(device or jax.devices()[0]):
    bo.minimizer_samples(state.X, state.Y, BOUNDS, jax.random.key(seed))
  return {'ask_s': ask_s, 'samples_s': time.perf_counter() - t}


def main(argv):
  del argv
  rows = []
  for name, device in (('cpu', jax.devices('cpu')[0]), ('default', None)):
    for run in range(2):
      row = {'gp_device': name, 'run': run, **_search(device, run)}
      row['device'] = str(device or jax.devices()[0])
      rows.append(row)
      print(json.dumps(row), flush=True)
  print('| GP on | device | run | asks s (all proposals) | minimizer_samples s |')
  print('|---|---|---:|---:|---:|')
  for r in rows:
    print(
      f'| {r["gp_device"]} | {r["device"]} | {r["run"]} | {r["ask_s"]:.2f} | '
      f'{r["samples_s"]:.2f} |'
    )
  files.write_json(
    FLAGS.out,
    {'q': FLAGS.q, 'n_init': FLAGS.n_init, 'n_iter': FLAGS.n_iter, 'rows': rows},
  )


if __name__ == '__main__':
  app.run(main)
