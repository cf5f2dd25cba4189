"""An estimate's initial design in calls of its ``q`` against one call, on MuJoCo C.

``search.Evaluator`` scores a design larger than the search's ``q`` in calls
of ``q`` on the C backend, so that a process compiles one program shape (the
design's and the steps' are then the same); on a GPU it keeps one call (a call
of 48 costs what one of 24 does there, BENCHMARKS.md). This runs the same
estimate of one recording both ways, alternating, each in a fresh
``Evaluator`` (so each pays its compiles, as a process does), and prints the
time in the objective and in the whole estimate, and the wind's posterior
median of each (the same candidates and keys: the same numbers).

  python -m experiments.demo --workdir=out/demo    # or any dataset sequence
  python -m benchmarks.design_calls --recording=out/demo/recording/gray_interlock/0000
"""

from __future__ import annotations

import contextlib
import dataclasses
import tempfile
import time
from unittest import mock

import numpy as np

from experiments.pipeline import cli, files, search
from experiments.pipeline import recording as recording_lib
from experiments.pipeline.objective import EstimateConfig


@dataclasses.dataclass(frozen=True)
class Args:
  """The comparison.

  Attributes:
    recording: a dataset sequence folder (its camera gives the shape's pose).
    material: its fabric.
    settings: the estimate's preset (``objective.PRESETS``).
    image_size: pixels a side the shape distance reads the frames at.
    repeats: runs of each way.
    out: JSON path.
  """

  recording: str = cli.required()
  material: str = 'gray_interlock'
  settings: str = 'demo'
  image_size: int = 32
  repeats: int = 2
  out: str = 'out/benchmarks/design_calls.json'


PRESETS = {'default': Args()}


def _one_call(configs, n: int, rows: int = 1) -> int:
  return n


def run_once(config: EstimateConfig, rec, one_call: bool) -> dict:
  """One estimate in a fresh Evaluator; ``one_call``: the design in one call."""
  way = (
    mock.patch.object(search, '_call_size', _one_call)
    if one_call
    else contextlib.nullcontext()
  )
  with tempfile.TemporaryDirectory() as tmp, way:
    t0 = time.perf_counter()
    r = search.estimate(
      config, rec, '', tmp, progress=False, evaluator=search.Evaluator()
    )
    seconds = time.perf_counter() - t0
  return {
    'seconds': seconds,
    'objective_s': r['seconds_in_objective'],
    'wind_median': r['estimate']['wind_speed']['median'],
  }


def main(args: Args) -> None:
  if args.repeats < 1:
    raise ValueError(f'--repeats={args.repeats}: need at least 1')
  config = EstimateConfig.preset(args.settings, material=args.material, backend='c')
  s = config.search
  if s.n_init <= s.q:
    raise ValueError(
      f'--settings={args.settings}: its design ({s.n_init}) fits one call of q={s.q}'
    )
  rec = recording_lib.load_recording(
    args.recording, fps=config.simulation.fps, size=(args.image_size,) * 2,
    frames=config.simulation.frames,
  )  # fmt: skip
  runs = {'calls of q': [], 'one call': []}
  for k in range(args.repeats):
    for name in runs:
      runs[name].append(run_once(config, rec, name == 'one call'))
      print(f'[{k + 1}/{args.repeats}] {name}: {runs[name][-1]}', flush=True)
  summary = {
    name: {
      'seconds_median': float(np.median([x['seconds'] for x in rs])),
      'objective_s_median': float(np.median([x['objective_s'] for x in rs])),
      'wind_median': [x['wind_median'] for x in rs],
    }
    for name, rs in runs.items()
  }
  print(f'\n{args.settings} settings, design {s.n_init}, q {s.q}, MuJoCo C')
  print('| design | estimate s | in the objective s | wind medians |')
  print('|---|---|---|---|')
  for name, m in summary.items():
    winds = ', '.join(f'{w:.4f}' for w in m['wind_median'])
    print(
      f'| {name} | {m["seconds_median"]:.1f} | {m["objective_s_median"]:.1f} | {winds} |'
    )
  files.write_json(args.out, {'args': dataclasses.asdict(args), 'summary': summary,
                              'runs': runs})  # fmt: skip


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
