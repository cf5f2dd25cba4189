"""Benchmark: PhySNet triplet training throughput, JAX against PyTorch (eager and compiled).

Times one training step (forward of anchor, positive and negative through the
shared network, squared-Euclidean triplet loss, backward, Adam update) on a
fixed random batch held on the device, so input loading is not measured.
Contenders are timed in round-robin repeats (the median is reported), so that
a drifting machine load hits all of them alike.
Throughput counts 3 * batch images per step. The same network (checked by
parameter count) runs in PyTorch in the same process, eager and under
``torch.compile``; compile time is reported apart from the steady state.

  python -m benchmarks.train_throughput --batch=32 --image_size=256 \\
      --steps=20 --repeats=5 --precision=float32

Precision: 'float32' (strict: JAX 'highest' matmul precision, PyTorch TF32
off), 'tf32' (both allow TF32 on GPUs that have it), 'bfloat16' (float32
params, bfloat16 compute: JAX ``compute_dtype``, PyTorch autocast). torch is
optional: without it, its rows are skipped with a message.
"""

import os

# JAX must leave room for PyTorch on the same GPU.
os.environ.setdefault('XLA_PYTHON_CLIENT_MEM_FRACTION', '0.45')

import dataclasses  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import model  # noqa: E402
from experiments.pipeline import cli, files  # noqa: E402
from model import train  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Args:
  """The training-throughput benchmark.

  Attributes:
    batch: triplets per step.
    image_size: square image side.
    channels: input channels (1 depth, 3 RGB).
    steps: timed steps per repeat.
    repeats: timed repeats per contender, round robin; the median is reported.
    warmup: untimed steps after compiling.
    precision: compute precision.
    pool_impls: PhySNetConfig.pool_impl values to time, one JAX row each (the
      first is the default).
    skip_torch: run only the JAX side.
    torch_compile: also time torch.compile.
    out: JSON path (empty: out/benchmarks/train_<device>.json).
  """

  batch: int = 32
  image_size: int = 256
  channels: int = 1
  steps: int = 20
  repeats: int = 5
  warmup: int = 3
  precision: str = cli.choice('float32', ['float32', 'tf32', 'bfloat16'])
  pool_impls: tuple[str, ...] = ('blocks', 'window')
  skip_torch: bool = False
  torch_compile: bool = True
  out: str = ''


PRESETS = {
  'default': Args(),
  # checks the script on a CPU in about a minute
  'smoke': Args(batch=2, image_size=64, steps=2, repeats=1, warmup=1, skip_torch=True),
}

_JAX_PRECISION = {'float32': 'highest', 'tf32': 'tensorfloat32', 'bfloat16': 'default'}


def _device_name() -> str:
  dev = jax.devices()[0]
  if dev.platform == 'cpu':
    return 'cpu'
  match = re.search(r'[A-Z]\d{2,4}', dev.device_kind)
  name = match.group(0) if match else dev.device_kind
  return re.sub(r'[^a-z0-9]+', '_', name.lower()).strip('_')


def bench_jax(
  batch: int, size: int, channels: int, warmup: int, precision: str, pool_impl: str
):
  """Compiles and warms up the jitted JAX train step (PhySNet with ``pool_impl``).

  Returns:
    (info dict, ``run(n) -> seconds`` taken by n more steps).
  """
  net_cfg = model.PhySNetConfig(
    in_channels=channels,
    image_size=(size, size),
    compute_dtype='bfloat16' if precision == 'bfloat16' else 'float32',
    pool_impl=pool_impl,
  )
  config = model.TrainConfig(physnet=net_cfg, batch_size=batch)
  network = train.make_network(config)
  optimizer, schedule = train.make_optimizer(config, 100)
  prec = _JAX_PRECISION[precision]
  with jax.default_matmul_precision(prec):
    state = jax.jit(lambda k: train.init_state(network, optimizer, k))(
      jax.random.PRNGKey(0)
    )
    keys = jax.random.split(jax.random.PRNGKey(1), 3)
    shape = (batch, size, size, channels)
    data = {
      name: jax.random.normal(k, shape, jnp.float32)
      for name, k in zip(('anchor', 'positive', 'negative'), keys, strict=True)
    }
    step = jax.jit(
      train.make_train_step(network, optimizer, schedule, config), donate_argnums=0
    )
    t0 = time.perf_counter()
    compiled = step.lower(state, data).compile()
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    state, metrics = compiled(state, data)
    jax.block_until_ready(metrics)
    first_s = time.perf_counter() - t0
    for _ in range(warmup):
      state, metrics = compiled(state, data)
    jax.block_until_ready(metrics)
  carry = {'state': state, 'metrics': metrics}

  def run(n: int) -> float:
    with jax.default_matmul_precision(prec):
      st = carry['state']
      t0 = time.perf_counter()
      for _ in range(n):
        st, m = compiled(st, data)
      jax.block_until_ready(m)
      elapsed = time.perf_counter() - t0
    carry.update(state=st, metrics=m)
    return elapsed

  info = {
    'framework': 'jax',
    'mode': f'jit ({pool_impl} pool)',
    'compile_s': compile_s,
    'first_step_s': first_s,
    'params': model.param_count(state.params['net']),
    'final_loss': lambda: float(carry['metrics']['loss']),
  }
  return info, run


def _torch_network(torch, channels: int, size: int):
  """The original PhySNet in PyTorch (NCHW)."""
  nn = torch.nn
  h = ((size - 4) // 2 - 4) // 2
  return nn.Sequential(
    nn.Conv2d(channels, 32, 5),
    nn.PReLU(),
    nn.MaxPool2d(2),
    nn.Conv2d(32, 64, 5),
    nn.PReLU(),
    nn.MaxPool2d(2),
    nn.Flatten(),
    nn.Linear(64 * h * h, 256),
    nn.PReLU(),
    nn.Linear(256, 256),
    nn.PReLU(),
    nn.Linear(256, 2),
  )


def bench_torch(
  torch,
  compiled: bool,
  batch: int,
  size: int,
  channels: int,
  warmup: int,
  precision: str,
):
  """Builds (for torch.compile: compiles) and warms up the PyTorch train step.

  Returns:
    (info dict, ``run(n) -> seconds`` taken by n more steps).
  """
  device = 'cuda' if torch.cuda.is_available() else 'cpu'
  tf32 = precision == 'tf32'
  torch.backends.cuda.matmul.allow_tf32 = tf32
  torch.backends.cudnn.allow_tf32 = tf32
  torch.manual_seed(0)
  net = _torch_network(torch, channels, size).to(device)
  opt = torch.optim.Adam(net.parameters(), lr=1e-3)
  fwd = torch.compile(net) if compiled else net
  a, p, n = (torch.randn(batch, channels, size, size, device=device) for _ in range(3))
  autocast = torch.autocast(
    device_type=device, dtype=torch.bfloat16, enabled=precision == 'bfloat16'
  )

  def step():
    opt.zero_grad(set_to_none=True)
    with autocast:
      e = fwd(torch.cat([a, p, n])).float()
    ea, ep, en = e.chunk(3)
    d_ap = (ea - ep).pow(2).sum(1)
    d_an = (ea - en).pow(2).sum(1)
    loss = torch.relu(d_ap - d_an + 1.0).mean()
    loss.backward()
    opt.step()
    return loss.detach()

  def sync():
    if device == 'cuda':
      torch.cuda.synchronize()

  sync()
  t0 = time.perf_counter()
  last = {'loss': step()}
  sync()
  first_s = time.perf_counter() - t0
  for _ in range(warmup):
    step()
  sync()

  def run(n: int) -> float:
    sync()
    t0 = time.perf_counter()
    for _ in range(n):
      last['loss'] = step()
    sync()
    return time.perf_counter() - t0

  info = {
    'framework': 'torch',
    'mode': 'compile' if compiled else 'eager',
    # Eager has nothing to compile; for torch.compile the first step is the compile.
    'compile_s': first_s if compiled else 0.0,
    'first_step_s': first_s,
    'params': sum(x.numel() for x in net.parameters()),
    'final_loss': lambda: float(last['loss']),
    'device': device,
  }
  return info, run


def main(args: Args) -> None:
  common = (args.batch, args.image_size, args.channels, args.warmup, args.precision)
  benches = [bench_jax(*common, impl) for impl in args.pool_impls]
  torch_note = ''
  if not args.skip_torch:
    try:
      import torch
    except ImportError:
      torch_note = 'torch is not importable: PyTorch rows skipped.'
      print(torch_note)
    else:
      benches.append(bench_torch(torch, False, *common))
      if args.torch_compile:
        try:
          benches.append(bench_torch(torch, True, *common))
        except (
          Exception
        ) as e:  # a broken inductor toolchain should not lose the other rows
          torch_note = f'torch.compile failed: {type(e).__name__}: {e}'
          print(torch_note)
  times = [[] for _ in benches]
  for _ in range(args.repeats):
    for i, (_, run) in enumerate(benches):
      times[i].append(run(args.steps))
  rows = []
  for (info, _), ts in zip(benches, times, strict=True):
    per_step = float(np.median(ts)) / args.steps
    rows.append(
      {
        **info,
        'final_loss': info['final_loss'](),
        'step_ms': 1e3 * per_step,
        'images_per_s': 3 * args.batch / per_step,
        'step_ms_repeats': [1e3 * t / args.steps for t in ts],
      }
    )
  ref = {r['mode']: r['images_per_s'] for r in rows if r['framework'] == 'torch'}
  for r in rows:
    for mode, ips in ref.items():
      r[f'speedup_vs_torch_{mode}'] = r['images_per_s'] / ips
  device = _device_name()
  print(
    f'\nPhySNet triplet train step, batch {args.batch} triplets ({3 * args.batch} images), '
    f'{args.image_size}x{args.image_size}x{args.channels}, {args.precision}, '
    f'{jax.devices()[0].device_kind}, median of {args.repeats} x {args.steps} steps\n'
  )
  cols = ['framework', 'mode', 'params', 'compile_s', 'step_ms', 'images_per_s'] + [
    f'speedup_vs_torch_{m}' for m in ref
  ]
  print('| ' + ' | '.join(cols) + ' |')
  print('|' + '---|' * len(cols))
  for r in rows:
    cells = [f'{r[c]:.3g}' if isinstance(r[c], float) else str(r[c]) for c in cols]
    print('| ' + ' | '.join(cells) + ' |')
  out = args.out or f'out/benchmarks/train_{device}.json'
  result = {
    'flags': {
      'batch': args.batch,
      'image_size': args.image_size,
      'channels': args.channels,
      'steps': args.steps,
      'repeats': args.repeats,
      'warmup': args.warmup,
      'precision': args.precision,
    },
    'device': jax.devices()[0].device_kind,
    'jax_version': jax.__version__,
    'note': torch_note,
    'rows': rows,
  }
  files.write_json(out, result)
  print(f'\nwrote {out}')
  if not all(np.isfinite(r['final_loss']) for r in rows if r['framework'] == 'jax'):
    raise SystemExit('JAX loss is not finite')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
