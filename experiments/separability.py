"""Can a sheet's motion tell wind speed from area weight? A network-free bound.

A sheet's static shape depends on wind speed v and area weight w only through
the load ratio rho v^2 / (w g). Only the dynamics (how fast it flaps, how the
flapping runs down the sheet, how the top edge sags) could separate the two.
This simulates every fabric over a grid of (v, w), with several gust histories
per point, and measures ``physsim.motion`` statistics of each world. Then, per
fabric:

* how much of each statistic the load ratio explains, and what knowing the
  wind adds (``experiments.landscape.ratio_r2``);
* the Cramer-Rao bound for one recording: each statistic's seed-mean is fitted
  by a quadratic in (log v, log w), its gradient there is the sensitivity J;
  the gust noise is the covariance S of the statistics between seeds at the
  same point. The Fisher information J^T S^-1 J bounds the error of any
  unbiased estimate of (log v, log w) from these statistics: the 1-sigma
  errors of wind, area weight and load ratio in percent, with every statistic
  and with each one left out (which statistic does the separating);
* the same bound with the search box as a prior (log-uniform ranges, taken as
  Gaussian with the same spread): what one recording can add to the range.

It bounds what these statistics can give, not the whole video (though our
networks retrieve area weight at chance too: ``model.retrieval``); local
linearity and Gaussian gust noise are assumed. Area weights reach a quarter
beyond each fabric's search range, so that slopes are measured over more than
the noise; the bounds are medians over the grid points inside the range.

  python -m experiments.separability --workdir=out/separability          # GPU: 1,120 worlds
  python -m experiments.separability --workdir=/tmp/sep --preset=smoke   # CPU, a minute

Writes ``separability.json``, ``separability.md``, ``separability_stats.png``
and ``separability_bounds.png``; each fabric's simulations are saved as they
finish, so a rerun resumes.
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import physsim  # noqa: E402
from experiments import cli, files  # noqa: E402
from experiments.landscape import ratio_r2  # noqa: E402
from physsim import motion  # noqa: E402

STATS = (
  'mean_deflection_m',
  'sag_m',
  'centre_rms_m',
  'centre_dominant_hz',
  'flutter_fraction',
  'wave_slowness_s_per_m',
)
# Area weights beyond the paper's ranges, so the grid may leave them.
_SPACE = physsim.SearchSpace(area_weight=(0.05, 0.6))
_BOX = physsim.SearchSpace()  # the estimate's wind range


@dataclasses.dataclass(frozen=True)
class Config:
  fabrics: tuple[str, ...] = tuple(physsim.FABRICS)
  winds: tuple[float, ...] = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0)
  weights: int = 5  # log-spaced from the range's low end / 1.25 to its high end x 1.25
  seeds: tuple[int, ...] = (0, 1, 2, 3)  # gust histories, common to all grid points
  bending: float = 1.0
  gusts: float = 0.2
  resolution: int = 25
  frames: int = 60
  fps: float = 20.0
  warmup: float = 1.0
  backend: str = 'auto'


PRESETS = {
  'default': Config(),
  'smoke': Config(
    fabrics=('red_violet',),
    winds=(2.0, 3.0, 4.0),
    weights=3,
    seeds=(0, 1, 2),
    resolution=6,
    frames=24,
    warmup=0.3,
  ),
}


def weight_grid(config: Config, fabric: str) -> np.ndarray:
  lo, hi = physsim.fabric(fabric).area_weight_range
  return np.geomspace(lo / 1.25, hi * 1.25, config.weights)


def simulate_fabric(config: Config, fabric: str) -> dict:
  """Every wind x area weight x gust seed of one fabric as one batch."""
  mesh = physsim.square(config.resolution)
  model = physsim.build(mesh, fabric)
  v, w, s = np.meshgrid(
    config.winds, weight_grid(config, fabric), config.seeds, indexing='ij'
  )
  v, w, s = v.ravel(), w.ravel(), s.ravel()
  t0 = time.time()
  out = physsim.simulate(
    model,
    physsim.params.make(config.bending, v, w),
    frames=config.frames,
    fps=config.fps,
    warmup=config.warmup,
    wind=physsim.Wind(gust_intensity=config.gusts),
    key=jax.vmap(jax.random.key)(jnp.asarray(s)),  # a seed's gusts at every point
    backend=physsim.resolve_backend(config.backend),
    space=_SPACE,
  )
  stats = motion.batch_stats(mesh, out.positions, out.valid, config.fps)
  rows = [
    {
      'wind_speed': float(v[i]),
      'area_weight': float(w[i]),
      'seed': int(s[i]),
      'valid': st['valid'],
      **{k: st[k] for k in STATS if k in st},
    }
    for i, st in enumerate(stats)
  ]
  return {'rows': rows, 'seconds': time.time() - t0}


# ------------------------------------------------------------------ analysis


def _quadratic(a, b):
  """Design matrix of a full quadratic in two variables, and its gradient."""
  one, zero = np.ones_like(a), np.zeros_like(a)
  x = np.stack([one, a, b, a * a, a * b, b * b], 1)
  da = np.stack([zero, one, zero, 2 * a, b, zero], 1)
  db = np.stack([zero, zero, one, zero, a, 2 * b], 1)
  return x, da, db


def fisher_bounds(log_v, log_w, point, Y, prior_sd=None) -> dict:
  """Cramer-Rao bounds on (log v, log w) from statistics at grid points.

  Args:
    log_v, log_w: (N,) each world's log wind speed and log area weight.
    point: (N,) integer id of each world's grid point (worlds of one point are
      gust seeds of the same parameters).
    Y: (N, K) the worlds' statistics, all finite.
    prior_sd: optional (2,) standard deviations of a prior on (log v, log w)
      (inf: flat); its information adds to the statistics' (the Bayesian,
      van Trees form of the bound).

  Returns:
    ``{'points': (P, 2) log v and log w of each point, 'sigma': (P, 3) the
    1-sigma bounds on log v, log w and log load ratio (2 log v - log w),
    'fit_r2': (K,) share of the seed-means' variance the quadratic explains,
    'noise_cov': (K, K)}``.

  Raises:
    ValueError: too few seeds or points to estimate the noise and the fit.
  """
  ids, inv = np.unique(point, return_inverse=True)
  P, (N, K) = len(ids), Y.shape
  if N - P < 2 * K or P < 6:
    raise ValueError(f'need more seeds or points: {N} worlds at {P} points, {K} stats')
  counts = np.bincount(inv, minlength=P)
  means = np.stack([np.bincount(inv, Y[:, k], P) / counts for k in range(K)], 1)
  dev = Y - means[inv]
  noise = dev.T @ dev / (N - P)  # pooled within-point covariance: the gust noise
  # A statistic that never varies between seeds (a quantised frequency at a few
  # points) would claim infinite information; floor it at a millionth of its spread.
  noise += np.diag(1e-6 * Y.var(0) + 1e-300)
  pv = np.bincount(inv, log_v, P) / counts
  pw = np.bincount(inv, log_w, P) / counts
  x, da, db = _quadratic(pv, pw)
  coef = np.linalg.lstsq(x, means, rcond=None)[0]  # (6, K)
  resid = means - x @ coef
  fit_r2 = 1.0 - resid.var(0) / np.maximum(means.var(0), 1e-300)
  J = np.stack([da @ coef, db @ coef], 2)  # (P, K, 2)
  info = np.einsum('pka,kl,plb->pab', J, np.linalg.inv(noise), J)
  if prior_sd is not None:
    info = info + np.diag(1.0 / np.square(np.asarray(prior_sd, np.float64)))
  a = np.array([2.0, -1.0])  # log ratio = 2 log v - log w + const
  sigma = np.full((P, 3), np.inf)  # where the statistics cannot tell v from w
  for p in range(P):
    with np.errstate(all='ignore'):
      cov = np.linalg.pinv(info[p], hermitian=True)
      var = np.array([cov[0, 0], cov[1, 1], a @ cov @ a])
    if np.linalg.matrix_rank(info[p], hermitian=True) == 2 and np.all(var > 0):
      sigma[p] = np.sqrt(var)
  return {
    'points': np.stack([pv, pw], 1),
    'sigma': sigma,
    'fit_r2': fit_r2,
    'noise_cov': noise,
  }


def _percent(log_sigma: np.ndarray) -> np.ndarray:
  """A 1-sigma error in log units as the percent error it means."""
  return 100.0 * np.expm1(log_sigma)


def analyse_fabric(config: Config, fabric: str, rows: list[dict]) -> dict:
  """R^2 per statistic and the bounds, all statistics and each left out."""
  ok = [r for r in rows if r['valid'] and all(np.isfinite(r[k]) for k in STATS)]
  v = np.array([r['wind_speed'] for r in ok])
  w = np.array([r['area_weight'] for r in ok])
  Y = np.array([[r[k] for k in STATS] for r in ok])
  varies = [
    j for j in range(len(STATS)) if np.ptp(Y[:, j]) > 0
  ]  # constants say nothing
  point = np.unique(np.stack([v, w], 1), axis=0, return_inverse=True)[1].ravel()
  lo, hi = physsim.fabric(fabric).area_weight_range
  # The search box as a prior: log-uniform over each range has sd = width / sqrt(12).
  box_sd = np.log([_BOX.wind_speed[1] / _BOX.wind_speed[0], hi / lo]) / np.sqrt(12.0)

  def bounds(cols, prior_sd=None) -> dict:
    cols = [c for c in cols if c in varies]
    b = fisher_bounds(np.log(v), np.log(w), point, Y[:, cols], prior_sd)
    inside = (np.exp(b['points'][:, 1]) >= lo) & (np.exp(b['points'][:, 1]) <= hi)
    med = np.median(b['sigma'][inside], axis=0)
    return {
      'wind_pct': float(_percent(med[0])),
      'area_weight_pct': float(_percent(med[1])),
      'load_ratio_pct': float(_percent(med[2])),
      'fit_r2': dict(zip([STATS[c] for c in cols], b['fit_r2'].tolist(), strict=True)),
    }

  every = list(range(len(STATS)))
  return {
    'worlds': len(rows),
    'used': len(ok),
    'range_half_width_pct': 100.0 * (hi - lo) / (hi + lo),
    'r2': {k: ratio_r2(Y[:, j], v, w) for j, k in enumerate(STATS)},
    'bounds': bounds(every),
    'bounds_with_box': bounds(every, box_sd),
    'box_sd_pct': {
      'wind': float(_percent(box_sd[0])),
      'area_weight': float(_percent(box_sd[1])),
    },
    'without': {k: bounds([c for c in every if c != j]) for j, k in enumerate(STATS)},
  }


def run(config: Config, workdir: str) -> dict:
  """Simulates (or resumes) every fabric, then analyses and plots."""
  os.makedirs(workdir, exist_ok=True)
  path = os.path.join(workdir, 'separability.json')
  done = files.resume(path, config).get('fabrics', {})
  for fabric in config.fabrics:
    if fabric in done:
      continue
    n = len(config.winds) * config.weights * len(config.seeds)
    print(f'{fabric}: simulating {n} worlds ...', flush=True)
    done[fabric] = simulate_fabric(config, fabric)
    files.write_json(path, {'config': dataclasses.asdict(config), 'fabrics': done})
  analysis = {f: analyse_fabric(config, f, done[f]['rows']) for f in config.fabrics}
  result = {'config': dataclasses.asdict(config), 'fabrics': done, 'analysis': analysis}
  files.write_json(path, result)
  text = table(analysis)
  files.write_text(os.path.join(workdir, 'separability.md'), text + '\n')
  plot_stats(config, done, os.path.join(workdir, 'separability_stats.png'))
  plot_bounds(analysis, os.path.join(workdir, 'separability_bounds.png'))
  print(text)
  return result


# ------------------------------------------------------------------- report


def table(analysis: dict) -> str:
  """Bounds per fabric, with and without the search box as a prior, and what
  leaving each statistic out costs."""
  lines = [
    '1-sigma bounds from one recording, % (median over grid points inside the '
    'range); from the statistics alone, and with the search box as a prior '
    '(its sd alone in brackets):',
    '',
    '| fabric | wind | area weight | load ratio | with the box: wind | area weight '
    '| area weight % without: ' + ' / '.join(STATS) + ' |',
    '|---|---:|---:|---:|---:|---:|---|',
  ]
  for f, a in analysis.items():
    b, p, box = a['bounds'], a['bounds_with_box'], a['box_sd_pct']
    left = ' / '.join(f'{a["without"][k]["area_weight_pct"]:.0f}' for k in STATS)
    lines.append(
      f'| {f} | {b["wind_pct"]:.1f} | {b["area_weight_pct"]:.1f} | '
      f'{b["load_ratio_pct"]:.1f} | {p["wind_pct"]:.1f} ({box["wind"]:.0f}) | '
      f'{p["area_weight_pct"]:.1f} ({box["area_weight"]:.1f}) | {left} |'
    )
  lines += [
    '',
    'Share of each statistic explained by the load ratio alone / with the wind too '
    '(R^2 over worlds, mean over fabrics):',
    '',
    '| statistic | ratio alone | ratio and wind |',
    '|---|---:|---:|',
  ]
  for k in STATS:
    r = [a['r2'][k] for a in analysis.values()]
    lines.append(
      f'| {k} | {np.nanmean([x["r2_ratio"] for x in r]):.3f} | '
      f'{np.nanmean([x["r2_ratio_and_wind"] for x in r]):.3f} |'
    )
  return '\n'.join(lines)


def plot_stats(config: Config, done: dict, path: str) -> None:
  """Each statistic's seed mean against the load ratio, coloured by area
  weight relative to the fabric's range centre; error bars span the seeds."""
  fabrics = list(config.fabrics)[:2]
  fig, axes = plt.subplots(
    len(fabrics), len(STATS), figsize=(3.3 * len(STATS), 3.0 * len(fabrics)),
    squeeze=False, layout='constrained',
  )  # fmt: skip
  cmap = plt.get_cmap('coolwarm')
  for i, fabric in enumerate(fabrics):
    rows = [r for r in done[fabric]['rows'] if r['valid']]
    centre = np.mean(physsim.fabric(fabric).area_weight_range)
    weights = sorted({r['area_weight'] for r in rows})
    for j, k in enumerate(STATS):
      ax = axes[i, j]
      for n, wt in enumerate(weights):
        colour = cmap(n / max(len(weights) - 1, 1))
        winds = sorted({r['wind_speed'] for r in rows if r['area_weight'] == wt})
        vals = [
          [r[k] for r in rows if r['area_weight'] == wt and r['wind_speed'] == ws]
          for ws in winds
        ]
        x = physsim.load_ratio(np.array(winds), wt)
        m = np.array([np.nanmean(a) for a in vals])
        e = np.array([np.nanstd(a) for a in vals])
        ax.errorbar(x, m, e, fmt='o-', ms=3, lw=1, color=colour, capsize=2,
                    label=f'w x{wt / centre:.2f}')  # fmt: skip
      ax.set(xscale='log', title=k if i == 0 else None)
      ax.set_xlabel('$\\rho v^2 / (w g)$' if i == len(fabrics) - 1 else None)
      ax.grid(alpha=0.3)
    axes[i, 0].set_ylabel(fabric)
  axes[0, 0].legend(fontsize=6, title='area weight / centre', title_fontsize=6)
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def plot_bounds(analysis: dict, path: str) -> None:
  """1-sigma bounds per fabric, from the statistics alone and with the search
  box as a prior, against the issue's targets."""
  names = list(analysis)
  x = np.arange(len(names))
  fig, axes = plt.subplots(1, 2, figsize=(1.3 * len(names) + 4, 4.0), sharey=True)
  for ax, key, title in (
    (axes[0], 'bounds', 'from the motion statistics alone'),
    (axes[1], 'bounds_with_box', 'with the search box as a prior'),
  ):
    for off, k, label in (
      (-0.25, 'wind_pct', 'wind speed'),
      (0.0, 'area_weight_pct', 'area weight'),
      (0.25, 'load_ratio_pct', 'load ratio'),
    ):
      ax.bar(x + off, [analysis[n][key][k] for n in names], 0.25, label=label)
    ax.axhline(5, color='r', ls='--', lw=1, label='area-weight target 5%')
    ax.axhline(10, color='g', ls=':', lw=1, label='wind target 10%')
    ax.set_xticks(x, [n.replace('_', '\n') for n in names], fontsize=7)
    ax.set(yscale='log', title=title)
    ax.grid(alpha=0.3, axis='y')
  axes[1].plot(x, [analysis[n]['box_sd_pct']['area_weight'] for n in names], 'k_',
               ms=16, mew=2, label='area-weight box alone (sd)')  # fmt: skip
  axes[0].set_ylabel('1-sigma error from one recording (%)')
  axes[1].legend(fontsize=7)
  fig.suptitle('Cramer-Rao bounds on wind and area weight', fontsize=10)
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


if __name__ == '__main__':
  cli.run_script(PRESETS, run, 'out/separability')
