"""Do the estimate's credible intervals hold the truth as often as they say?

Simulation-based calibration (Talts et al. 2018) of the whole estimate, at the
demo's size: a network trained as the demo trains it, then many held-out
simulated recordings made with the evaluation recipe (other seeds, unseen
camera poses, a finer mesh, gustier wind, 24 fps, the depth-sensor model),
their parameters drawn from the prior (the material's search box, bending
log-uniform). Each is estimated by the default posterior search; per
parameter and for the load ratio, the study reports how often the 50% and 90%
intervals hold the truth, the rank of the truth among posterior draws (uniform
when calibrated), and the point estimate's error beside the range centre's.

The recordings come in pairs that share bending and area weight (one fabric,
two fan settings), so the same simulations also measure the joint estimate.
What a measured wind or area weight adds is measured too: a reading with 2%
error (``measured_sd``) enters as a prior.

The likelihood's one constant (``sharpness``) is chosen on the first
``calibration_share`` of the pairs (``bo.posterior.choose_sharpness``: the
sharpest value whose intervals hold the truth at least as often as they say)
and reported on the rest: the posterior of
every recording is formed again from its saved GP for each candidate value,
without new simulations (the searches ran with the default value, which only
steers where they simulated). ``experiments/calibrate.py`` is its command line.
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax
import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import bo  # noqa: E402
import physsim  # noqa: E402
from experiments.pipeline import cli, distributed, files, search  # noqa: E402
from experiments.pipeline import datasets as gen  # noqa: E402
from experiments.pipeline import demo as demo_lib  # noqa: E402
from experiments.pipeline import posterior as posterior_lib  # noqa: E402
from experiments.pipeline import recording as recording_lib  # noqa: E402
from experiments.pipeline import training as train_lib  # noqa: E402
from experiments.pipeline.objective import EstimateConfig  # noqa: E402

FIELDS = (*posterior_lib.FIELDS, 'load_ratio')
LEVELS = (50, 90)
MODES = ('video', 'known wind', 'known area weight', 'joint pair')
RESULT_FILE = 'calibration.json'


@dataclasses.dataclass(frozen=True)
class Config:
  """A calibration study.

  Attributes:
    material: the fabric (physsim.FABRICS).
    pairs: pairs of held-out simulated recordings (each pair shares bending
      and area weight; every recording's parameters are a prior draw).
    calibration_share: share of the pairs that choose the sharpness; the rest
      report.
    sharpness_grid: candidate values of the likelihood's constant (the
      searches run with the estimate's sharpness).
    measured_sd: relative standard error of a measured wind or area weight.
    sequences: training simulations of the network (the demo's recipe).
    batch_size: recordings simulated per batch when making them.
    backend: simulator: 'auto' (MJX on a GPU, else MuJoCo C), 'mjx' or 'c'.
    seed: the study's seed (truths, recordings, network, searches).
    estimate: the estimate settings (material, cloth and clock follow the
      demo's).
  """

  material: str = 'gray_interlock'
  pairs: int = 100
  calibration_share: float = 0.5
  sharpness_grid: tuple[float, ...] = (0.15, 0.25, 0.35, 0.5, 0.7, 1.0, 1.4)
  measured_sd: float = 0.02
  sequences: int = 24
  batch_size: int = 64
  backend: str = cli.choice('auto', ('auto', 'mjx', 'c'))
  seed: int = 0
  estimate: EstimateConfig = cli.nested(
    EstimateConfig(q=8, n_init=16, max_iter=6, posterior_grid=(12, 64, 24)),
    skip=('material', 'cloth_resolution', 'frames', 'warmup', 'backend', 'seed',
          'point', 'measured'),
  )  # fmt: skip


PRESETS = {
  'default': Config(),
  # A few pairs on a CPU: checks the whole study end to end.
  'smoke': Config(
    pairs=3,
    sequences=8,
    batch_size=6,
    sharpness_grid=(0.25, 0.5, 1.0),
    estimate=EstimateConfig(q=4, n_init=8, max_iter=2, posterior_grid=(6, 16, 8)),
  ),
}


def truths(config: Config) -> physsim.Params:
  """(2 * pairs,) parameter sets, pair-major: recordings 2k and 2k+1 share
  bending and area weight and draw their own wind; all uniform in the unit
  cube of the search box (the prior)."""
  rng = np.random.default_rng([config.seed, 7])
  u = rng.uniform(-1.0, 1.0, size=(config.pairs, 2, 3))
  u[:, 1, [0, 2]] = u[:, 0, [0, 2]]
  return physsim.from_unit(u.reshape(-1, 3), physsim.search_space(config.material))


def _configs(config: Config):
  data, rec, training, est = demo_lib.configs(
    config.material, config.sequences, config.seed, config.backend
  )
  n = 2 * config.pairs
  rec = dataclasses.replace(
    rec, sequences=n, batch_size=min(config.batch_size, n), seed=5000 + config.seed
  )
  est = dataclasses.replace(
    config.estimate, material=config.material,
    cloth_resolution=est.cloth_resolution, frames=est.frames, warmup=est.warmup,
    backend=config.backend, seed=config.seed, point='median',
  )  # fmt: skip
  return data, rec, training, est


def simulate_and_estimate(config: Config, workdir: str) -> list[dict]:
  """Trains the network, makes the recordings and estimates each (resumable).

  Under several processes (``distributed``) process 0 makes the data, the
  network and the recordings, each process estimates its share of the
  recordings, and process 0 gathers every result (the others return []).

  Returns:
    Per recording: ``{'seq', 'truth', 'workdir', 'result'}``.
  """
  data_cfg, rec_cfg, train_cfg, est = _configs(config)
  model_dir = os.path.join(workdir, 'model', config.material)
  rec_root = os.path.join(workdir, 'recordings')
  if distributed.is_main():
    gen.run(data_cfg, os.path.join(workdir, 'data'))
    train_lib.run(
      train_cfg, os.path.join(workdir, 'data'), os.path.join(workdir, 'model')
    )
    gen.run(rec_cfg, rec_root, params={config.material: truths(config)})
  distributed.barrier('calibration: network and recordings made')
  index = physsim.dataset.open_dataset(rec_root)
  rows = sorted(index.filter(material=config.material).rows, key=lambda r: r['seq_id'])
  jobs, meta = [], []
  for r in rows:
    if not r['valid']:
      continue
    rec = recording_lib.load_recording(
      index.path(r), fps=est.fps, size=demo_lib.IMAGE_SIZE, frames=est.frames
    )
    wd = os.path.join(workdir, 'estimates', r['seq_id'])
    jobs.append(search.Job(est, rec, model_dir, wd))
    meta.append({'seq': int(r['seq_id']), 'truth': rec.truth, 'workdir': wd})
  if jax.process_count() > 1:
    mine = distributed.share(jobs)
    print(f'{len(mine)} of {len(jobs)} recordings in lockstep', flush=True)
    search.estimate_many(mine, figures=False)
    distributed.barrier('calibration: estimates done')
    if not distributed.is_main():
      return []
  else:
    print(f'{len(jobs)} recordings in lockstep', flush=True)
  results = search.estimate_many(jobs, figures=False)  # finished ones read back
  out = []
  for m, res in zip(meta, results, strict=True):
    if isinstance(res, Exception):
      print(f'recording {m["seq"]}: {res}', flush=True)
      continue
    out.append({**m, 'result': res})
  return out


# ------------------------------------------------------------------ analysis


def _saved(workdir: str) -> dict:
  with np.load(os.path.join(workdir, search.POSTERIOR_FILE)) as z:
    return {k: z[k] for k in z.files}


def _draws(rng, grid, log_post, n: int) -> np.ndarray:
  """Draws from a grid posterior (numpy; as ``bo.posterior.sample_grid``)."""
  pts = bo.posterior.grid_points(grid)
  p = np.exp(log_post - np.max(log_post))
  idx = rng.choice(len(pts), size=n, p=p / p.sum())
  width = 2.0 / np.asarray(grid, np.float64)
  return np.clip(pts[idx] + (rng.random((n, 3)) - 0.5) * width, -1.0, 1.0)


def _log_lik(z: dict, form: str, sharpness: float) -> np.ndarray:
  return np.asarray(
    bo.posterior.log_likelihood(
      z['gp_mean'], z['gp_var'], z['floor'], z['noise_sd'], form=form,
      sharpness=sharpness,
    )
  )  # fmt: skip


def _physical_with_ratio(unit, space) -> np.ndarray:
  p = posterior_lib.physical(unit, space)
  return np.concatenate([p, physsim.load_ratio(p[:, 1], p[:, 2])[:, None]], axis=1)


def _measured_prior(
  points, space, name: str, truth: dict, sd: float, rng
) -> np.ndarray:
  """The log prior of a reading of ``name`` with relative error ``sd``."""
  v = truth[name] * (1.0 + sd * rng.standard_normal())
  m = posterior_lib.Measured(**{name: v, f'{name}_sd': sd * truth[name]})
  return posterior_lib.log_prior(points, space, m)


def _score(draws_phys: np.ndarray, truth_row: np.ndarray) -> dict:
  """Coverage of central intervals, the truth's rank (share of draws below it)
  and the median, per field."""
  out = {
    'rank': np.mean(draws_phys < truth_row, axis=0),
    'median': np.median(draws_phys, 0),
  }
  for level in LEVELS:
    lo, hi = np.quantile(draws_phys, [(1 - level / 100) / 2, (1 + level / 100) / 2], 0)
    out[f'covered_{level}'] = (lo <= truth_row) & (truth_row <= hi)
  return out


def posteriors(config: Config, runs: list[dict], form: str, sharpness: float,
               n: int = 2000) -> dict[str, list[dict]]:  # fmt: skip
  """Every recording's scores under each mode, at one likelihood setting."""
  space = physsim.search_space(config.material)
  grid = tuple(config.estimate.posterior_grid)
  points = bo.posterior.grid_points(grid)
  rng = np.random.default_rng([config.seed, 11, int(sharpness * 1000)])
  out = {m: [] for m in MODES}
  by_seq = {r['seq']: r for r in runs}
  for r in runs:
    z = _saved(r['workdir'])
    t = r['truth']
    row = np.array([t[f] for f in posterior_lib.FIELDS]
                   + [physsim.load_ratio(t['wind_speed'], t['area_weight'])])  # fmt: skip
    ll = _log_lik(z, form, sharpness)
    base = posterior_lib.log_prior(points, space, posterior_lib.Measured())
    priors = {
      'video': base,
      'known wind': _measured_prior(
        points, space, 'wind_speed', t, config.measured_sd, rng
      ),
      'known area weight': _measured_prior(
        points, space, 'area_weight', t, config.measured_sd, rng
      ),
    }
    for mode, lp in priors.items():
      post = bo.posterior.log_normalise(lp + ll)
      draws = _physical_with_ratio(_draws(rng, grid, np.asarray(post), n), space)
      out[mode].append({'seq': r['seq'], 'truth': row, **_score(draws, row)})
    mate = by_seq.get(r['seq'] ^ 1)  # the pair's other recording
    if mate is not None and r['seq'] % 2 == 0:
      zm = _saved(mate['workdir'])
      j = posterior_lib.joint(
        [ll, _log_lik(zm, form, sharpness)], grid, base,
        jax.random.key(int(rng.integers(1 << 30))), n=n,
      )  # fmt: skip
      for k, (rr, samples) in enumerate(zip((r, mate), j['samples'], strict=True)):
        tt = rr['truth']
        trow = np.array([tt[f] for f in posterior_lib.FIELDS]
                        + [physsim.load_ratio(tt['wind_speed'], tt['area_weight'])])  # fmt: skip
        draws = _physical_with_ratio(samples, space)
        out['joint pair'].append({'seq': rr['seq'], 'pair_member': k, 'truth': trow,
                                  **_score(draws, trow)})  # fmt: skip
  return out


def summarise(scores: list[dict], space: physsim.SearchSpace) -> dict:
  """Coverage, rank uniformity and errors over recordings, per field."""
  if not scores:
    return {}
  truth = np.stack([s['truth'] for s in scores])
  median = np.stack([s['median'] for s in scores])
  rank = np.stack([s['rank'] for s in scores])
  centre = np.array([*map(float, space.center()),
                     float(physsim.load_ratio(space.center().wind_speed,
                                              space.center().area_weight))])  # fmt: skip
  out = {'n': len(scores)}
  for i, f in enumerate(FIELDS):
    cell = {f'interval_{lv}': float(np.mean([s[f'covered_{lv}'][i] for s in scores]))
            for lv in LEVELS}  # fmt: skip
    hist = np.histogram(rank[:, i], bins=10, range=(0, 1))[0]
    expected = len(scores) / 10
    cell['rank_histogram'] = hist.tolist()
    cell['rank_chi2'] = float(np.sum((hist - expected) ** 2 / expected))  # 9 dof
    t = truth[:, i]
    if f == 'bending_scale':  # a factor, >= 1
      cell['median_error_factor'] = float(
        np.mean(np.exp(np.abs(np.log(median[:, i] / t))))
      )
      cell['centre_error_factor'] = float(
        np.mean(np.exp(np.abs(np.log(centre[i] / t))))
      )
    else:  # percent
      cell['median_error_pct'] = float(np.mean(100 * np.abs(median[:, i] - t) / t))
      cell['centre_error_pct'] = float(np.mean(100 * np.abs(centre[i] - t) / t))
    out[f] = cell
  return out


def _coverages(summary: dict) -> np.ndarray:
  """(levels, fields) interval coverage of a summary."""
  return np.array([[summary[f][f'interval_{lv}'] for f in FIELDS] for lv in LEVELS])


def analyse(config: Config, runs: list[dict]) -> dict:
  """Chooses the sharpness on the calibration pairs; reports the held-out pairs."""
  space = physsim.search_space(config.material)
  n_cal = int(round(config.calibration_share * config.pairs))
  split = lambda rows, held: [s for s in rows if (s['seq'] // 2 >= n_cal) == held]
  sweep = {}
  for form in bo.posterior.LIKELIHOODS:
    sweep[form] = {}
    for c in config.sharpness_grid:
      scores = posteriors(config, runs, form, c)
      sweep[form][c] = {
        'calibration': summarise(split(scores['video'], False), space),
        'held_out': {m: summarise(split(scores[m], True), space) for m in MODES},
      }
  levels = [lv / 100 for lv in LEVELS]
  best = {
    form: bo.posterior.choose_sharpness(
      {c: _coverages(v['calibration']) for c, v in sweep[form].items()
       if v['calibration']}, levels,
    ) if any(v['calibration'] for v in sweep[form].values()) else None
    for form in sweep
  }  # fmt: skip
  return {'sweep': sweep, 'best_sharpness': best, 'n_calibration_pairs': n_cal}


def run(config: Config, workdir: str) -> dict:
  """The whole study; writes ``calibration.json``, ``calibration.md`` and figures."""
  t0 = time.time()
  os.makedirs(workdir, exist_ok=True)
  runs = simulate_and_estimate(config, workdir)
  if not distributed.is_main():
    return {}
  analysis = analyse(config, runs)
  form, c = 'gibbs', analysis['best_sharpness']['gibbs']
  held = analysis['sweep'][form][c]['held_out']
  out = {
    'material': config.material,
    'n': held['video'].get('n', 0),
    'setting': f'{form} likelihood, sharpness {c:g}, {config.material} network '
    f'of {config.sequences} training sequences',
    'likelihood': form,
    'sharpness': c,
    'coverage': {
      f: {f'interval_{lv}': held['video'][f][f'interval_{lv}'] for lv in LEVELS}
      for f in FIELDS
    }
    if held['video']
    else {},  # fmt: skip
    'held_out': held,
    'analysis': analysis,
    'config': dataclasses.asdict(config),
    'seconds': time.time() - t0,
  }
  files.write_json(os.path.join(workdir, RESULT_FILE), out)
  text = table(out)
  files.write_text(os.path.join(workdir, 'calibration.md'), text + '\n')
  plot_ranks(held, os.path.join(workdir, 'calibration_ranks.png'))
  plot_sweep(analysis, os.path.join(workdir, 'calibration_sharpness.png'))
  print(text)
  return out


def _cell(s: dict, f: str) -> str:
  if not s:
    return '-'
  cov = f'{100 * s[f]["interval_50"]:.0f}% / {100 * s[f]["interval_90"]:.0f}%'
  err = (f'x{s[f]["median_error_factor"]:.2f} (x{s[f]["centre_error_factor"]:.2f})'
         if 'median_error_factor' in s[f]
         else f'{s[f]["median_error_pct"]:.1f}% ({s[f]["centre_error_pct"]:.1f}%)')  # fmt: skip
  return f'{cov} | {err} | {s[f]["rank_chi2"]:.1f}'


def table(out: dict) -> str:
  """Markdown: per mode and field, coverage of the 50% / 90% intervals, the
  median's error (range centre's), and the rank histogram's chi^2 (9 dof;
  above 21.7 rejects uniform ranks at 1%)."""
  lines = [
    f'Held-out simulated recordings: {out["n"]} ({out["setting"]})',
    '',
    '| mode | parameter | 50% / 90% intervals hold the truth | median error (range '
    'centre) | rank chi^2 |',
    '|---|---|---|---|---|',
  ]
  for mode, s in out['held_out'].items():
    for f in FIELDS:
      lines.append(f'| {mode} | {f} | {_cell(s, f)} |')
  best = out['analysis']['best_sharpness']
  lines += ['', 'sharpness chosen on the calibration pairs: '
            + ', '.join(f'{k} {v:g}' for k, v in best.items())]  # fmt: skip
  return '\n'.join(lines)


def plot_ranks(held: dict, path: str) -> None:
  """Rank histograms of the truth among posterior draws (uniform: calibrated)."""
  fig, axes = plt.subplots(len(MODES), len(FIELDS), figsize=(14, 2.4 * len(MODES)),
                           layout='constrained', squeeze=False)  # fmt: skip
  for r, mode in enumerate(MODES):
    for c, f in enumerate(FIELDS):
      ax = axes[r, c]
      s = held.get(mode, {})
      if not s:
        ax.axis('off')
        continue
      h = s[f]['rank_histogram']
      ax.bar(np.arange(10) / 10 + 0.05, h, width=0.09, color='C0')
      ax.axhline(s['n'] / 10, color='k', lw=1, ls='--')
      ax.set(xlim=(0, 1), title=f'{mode}: {f}', xlabel='rank of the truth')
      ax.title.set_fontsize(8)
  files.savefig(fig, path, dpi=80)
  plt.close(fig)


def plot_sweep(analysis: dict, path: str) -> None:
  """Coverage on the calibration pairs against the sharpness, per likelihood."""
  forms = list(analysis['sweep'])
  fig, axes = plt.subplots(1, len(forms), figsize=(6 * len(forms), 3.8),
                           layout='constrained', squeeze=False)  # fmt: skip
  for ax, form in zip(axes[0], forms, strict=True):
    cs = sorted(analysis['sweep'][form])
    for i, f in enumerate(FIELDS):
      for lv, ls in ((50, '--'), (90, '-')):
        y = [analysis['sweep'][form][c]['calibration'].get(f, {}).get(f'interval_{lv}', np.nan)
             for c in cs]  # fmt: skip
        ax.plot(cs, y, ls, color=f'C{i}', label=f'{f} {lv}%' if lv == 90 else None)
    for lv in (0.5, 0.9):
      ax.axhline(lv, color='k', lw=0.8)
    ax.axvline(analysis['best_sharpness'][form], color='r', lw=1)
    ax.set(xscale='log', xlabel='sharpness', ylabel='coverage (solid 90%, dashed 50%)',
           title=f'{form} likelihood, calibration pairs')  # fmt: skip
    ax.legend(fontsize=7)
  files.savefig(fig, path, dpi=80)
  plt.close(fig)
