"""What a measured wind or area weight adds to finished estimates.

Reads estimates written by ``experiments.estimate`` or ``experiments.tables``
(each folder with ``estimate.json`` holding the truth, and ``posterior.npz``
with the GP of its log PSD), forms each recording's posterior again from its
GP at the estimate's likelihood setting: from the video alone, with a wind
reading of relative error ``--measured_sd`` (an anemometer) and with an area
weight reading (a scale and a ruler), each reading drawn around the truth
(``posterior.simulated_reading``, seeded by ``--seed`` and the folder's
sequence id: the readings ``experiments.tables`` and a calibration check of
that seed gave their searches). With ``--pairs`` (a calibration or its
check: recordings 2k and 2k+1 share bending and area weight) the joint
modes too, without and with a wind reading at each recording. Prints, per
mode and quantity, the posterior median's mean error, the range centre's,
and how often the 50% and 90% intervals held the truth; writes JSON.
No simulation: seconds on a CPU.

  python -m benchmarks.measured_modes \\
      --estimates='out/tables/physnet_depth/fabrics/gray_interlock-*' --out=modes.json
  python -m benchmarks.measured_modes --estimates='out/check/estimates/*' --pairs --seed=3
"""

from __future__ import annotations

import dataclasses
import glob
import os

import physsim
from experiments.pipeline import cli, files
from experiments.pipeline.objective import EstimateConfig
from experiments.pipeline.recording import read_json
from experiments.studies import calibration


@dataclasses.dataclass(frozen=True)
class Args:
  """What readings add to finished estimates.

  Attributes:
    estimates: glob of estimate folders (required).
    measured_sd: relative standard error of a reading.
    out: JSON path.
    seed: seed of the readings (a check run with --seed=S: S).
    pairs: recordings 2k and 2k+1 share bending and area weight (a
      calibration or its check): add the joint modes, without and with a wind
      reading at each.
  """

  estimates: str = cli.required()
  measured_sd: float = 0.02
  out: str = 'out/benchmarks/measured_modes.json'
  seed: int = 0
  pairs: bool = False


PRESETS = {'default': Args()}


def main(args: Args) -> None:
  dirs = sorted(d for d in glob.glob(args.estimates) if os.path.isdir(d))
  if not dirs:
    raise ValueError(f'no estimate folders match {args.estimates!r}')
  runs, configs = [], set()
  for i, d in enumerate(dirs):
    est = read_json(os.path.join(d, 'estimate.json'))
    if 'truth' not in est:
      raise ValueError(f'{d}/estimate.json: no truth (a simulated recording is needed)')
    c = est['config']
    configs.add(
      (c['material'], c['likelihood'], c['sharpness'], tuple(c['posterior_grid']))
    )
    tail = os.path.basename(d).rsplit('-', 1)[-1]  # '0003' or 'gray_interlock-0003'
    seq = int(tail) if tail.isdigit() else i  # the sequence id seeds its reading
    runs.append({'seq': seq, 'truth': est['truth'], 'workdir': d})
  if len(configs) != 1:
    raise ValueError(f'estimates of several settings: {sorted(configs)}')
  material, form, sharpness, grid = configs.pop()
  study = calibration.Config(
    material=material, measured_sd=args.measured_sd, seed=args.seed,
    estimate=EstimateConfig().replace(posterior_grid=grid),
  )  # fmt: skip
  scores = calibration.posteriors(study, runs, form, sharpness, pairs=args.pairs)
  modes = [m for m in calibration.MODES if args.pairs or not m.startswith('joint')]
  space = physsim.search_space(material)
  summary = {m: calibration.summarise(scores[m], space) for m in modes}
  print(f'{len(runs)} recordings, {material}, {form} likelihood, sharpness {sharpness:g}, '
        f'readings with {100 * args.measured_sd:g}% error\n')  # fmt: skip
  print('| mode | quantity | median error (range centre) | 50% / 90% hold the truth |')
  print('|---|---|---|---|')
  for m in modes:
    for f in calibration.FIELDS:
      s = summary[m][f]
      err = (f'x{s["median_error_factor"]:.2f} (x{s["centre_error_factor"]:.2f})'
             if 'median_error_factor' in s else
             f'{s["median_error_pct"]:.1f}% ({s["centre_error_pct"]:.1f}%)')  # fmt: skip
      print(f'| {m} | {f} | {err} | {100 * s["interval_50"]:.0f}% / '
            f'{100 * s["interval_90"]:.0f}% |')  # fmt: skip
  files.write_json(args.out, {
    'estimates': dirs, 'material': material, 'likelihood': form,
    'sharpness': sharpness, 'measured_sd': args.measured_sd, 'summary': summary,
    'config': dataclasses.asdict(study),
  })  # fmt: skip
  print(f'wrote {args.out}')


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
