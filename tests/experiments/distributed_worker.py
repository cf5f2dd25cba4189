"""One process of ``distributed_test``: joins the others from the environment,
writes its share of jobs into a shared folder, meets the others at a barrier,
and (process 0) checks every job is there and a sum over every process's
devices is right."""

import json
import os
import sys

from experiments.pipeline import distributed

assert distributed.initialize(), 'the environment describes two processes'
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax.sharding import Mesh, NamedSharding  # noqa: E402
from jax.sharding import PartitionSpec as P  # noqa: E402

out = sys.argv[1]
index, count = distributed.process()
jobs = list(range(7))
for job in distributed.share(jobs):
  with open(os.path.join(out, f'job{job}.json'), 'w') as f:
    json.dump({'job': job, 'process': index}, f)
if index == 1:  # the other process waits at the barrier meanwhile
  import time

  time.sleep(40)  # a long share: a device-collective barrier timed out here
distributed.barrier('jobs written')
# A global mesh over every process's devices: each holds its own rows.
mesh = Mesh(np.array(jax.devices()), ('worlds',))
local = np.arange(len(jax.local_devices()), dtype=np.float32) + 10 * index
x = jax.make_array_from_process_local_data(NamedSharding(mesh, P('worlds')), local)
total = float(jax.jit(jnp.sum)(x))
if distributed.is_main():
  found = sorted(int(f[3:-5]) for f in os.listdir(out) if f.startswith('job'))
  print(json.dumps({'count': count, 'jobs': found, 'total': total}))
