"""Can a sheet's motion tell wind speed from area weight, or show bending? A bound.

A sheet's static shape depends on wind speed v and area weight w only through
the load ratio rho v^2 / (w g). Only the dynamics (how fast it flaps, how the
flapping runs down the sheet, how the top edge sags) could separate the two.
This simulates every fabric over a grid of (v, w) (or, with ``vary=
'bending_scale'``, of wind and bending at the range's mean area weight), with
several gust histories per point, and measures ``physsim.motion`` statistics
of each world. Then, per fabric:

* how much of each statistic the load ratio explains, and what knowing the
  wind adds (bending: the wind, and what the bending adds);
* the Cramer-Rao bound for one recording: each statistic's seed-mean is fitted
  by a quadratic in (log v, log w), its gradient there is the sensitivity J;
  the gust noise is the covariance S of the statistics between seeds at the
  same point. The Fisher information J^T S^-1 J bounds the error of any
  unbiased estimate of (log v, log w) from these statistics: the 1-sigma
  errors of wind, area weight and load ratio in percent (bending: a factor),
  with every statistic and with each one left out (which one separates);
* the same bound with the search box as a prior (log-uniform ranges, taken as
  Gaussian with the same spread): what one recording can add to the range.

It bounds what these statistics can give, not the whole video (though our
networks retrieve area weight and bending at chance too: ``model.retrieval``);
local linearity and Gaussian gust noise are assumed. Area weights reach a
quarter beyond each fabric's search range, so that slopes are measured over
more than the noise; the bounds are medians over the grid points inside the
range. The bending study holds area weight known, so its bound is optimistic.

``experiments/separability.py`` is its command line (presets: default, 1,120
worlds on a GPU; bending; smoke, a minute on a CPU).

Writes ``separability.{json,md}``, ``separability_stats.png`` and
``separability_bounds.png`` (bending: ``separability_bending*``); each
fabric's simulations are saved as they finish, so a rerun resumes.
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
from experiments.pipeline import cli, files  # noqa: E402
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
  """A sweep of wind and one other parameter (``vary``) per fabric.

  Attributes:
    fabrics: fabric names (physsim.FABRICS).
    winds: wind speeds, m/s.
    weights: area weights per fabric, log-spaced from its range's low end /
      1.25 to its high end x 1.25.
    seeds: gust histories, common to all grid points.
    bending: bending scale while area weight varies.
    vary: 'area_weight' (grid of weights values; bending at bending) or
      'bending_scale' (grid bendings; area weight at its range's centre).
    bendings: bending scales while bending varies.
    gusts: RMS relative gust intensity.
    resolution: cloth vertices per side.
    frames: frames per simulation.
    fps: frame rate, Hz.
    warmup: simulated seconds before the first frame.
    backend: simulator: 'auto' (MuJoCo Warp a frame at a time on a GPU, else MuJoCo C), 'warp', 'mjx' or 'c' (physsim.rollout).
  """

  fabrics: tuple[str, ...] = tuple(physsim.FABRICS)
  winds: tuple[float, ...] = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0)
  weights: int = 5
  seeds: tuple[int, ...] = (0, 1, 2, 3)
  bending: float = 1.0
  vary: str = cli.choice('area_weight', ('area_weight', 'bending_scale'))
  bendings: tuple[float, ...] = (0.1, 0.316, 1.0, 3.16, 10.0)
  gusts: float = 0.2
  resolution: int = 25
  frames: int = 60
  fps: float = 20.0
  warmup: float = 1.0
  backend: str = cli.choice('auto', physsim.BACKENDS)


_SMOKE = Config(
  fabrics=('red_violet',),
  winds=(2.0, 3.0, 4.0),
  weights=3,
  bendings=(0.1, 1.0, 10.0),
  seeds=(0, 1, 2),
  resolution=6,
  frames=24,
  warmup=0.3,
)
PRESETS = {
  'default': Config(),
  'bending': Config(vary='bending_scale'),
  'smoke': _SMOKE,
  'smoke_bending': dataclasses.replace(_SMOKE, vary='bending_scale'),
}
_VARY = ('area_weight', 'bending_scale')


def second_grid(config: Config, fabric: str) -> np.ndarray:
  """The values of ``config.vary`` swept for one fabric."""
  if config.vary == 'bending_scale':
    return np.asarray(config.bendings, np.float64)
  lo, hi = physsim.fabric(fabric).area_weight_range
  return np.geomspace(lo / 1.25, hi * 1.25, config.weights)


def box(config: Config, fabric: str) -> tuple[float, float]:
  """The estimate's search range of ``config.vary`` for one fabric."""
  if config.vary == 'bending_scale':
    return _BOX.bending_scale
  return physsim.fabric(fabric).area_weight_range


def simulate_fabric(config: Config, fabric: str) -> dict:
  """Every wind x second parameter x gust seed of one fabric as one batch."""
  if config.vary not in _VARY:
    raise ValueError(f'vary={config.vary!r}: choose one of {_VARY}')
  mesh = physsim.square(config.resolution)
  model = physsim.build(mesh, fabric)
  v, x, s = np.meshgrid(
    config.winds, second_grid(config, fabric), config.seeds, indexing='ij'
  )
  v, x, s = v.ravel(), x.ravel(), s.ravel()
  if config.vary == 'bending_scale':
    b, w = x, np.full_like(x, np.mean(physsim.fabric(fabric).area_weight_range))
  else:
    b, w = np.full_like(x, config.bending), x
  t0 = time.time()
  out = physsim.simulate(
    model,
    physsim.params.make(b, v, w),
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
      'bending_scale': float(b[i]),
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


def fisher_bounds(log_v, log_w, point, Y, prior_sd=None, combo=(2.0, -1.0)) -> dict:
  """Cramer-Rao bounds on (log v, log w) from statistics at grid points.

  Args:
    log_v, log_w: (N,) each world's log wind speed and log area weight (or
      any second parameter: log bending scale).
    point: (N,) integer id of each world's grid point (worlds of one point are
      gust seeds of the same parameters).
    Y: (N, K) the worlds' statistics, all finite.
    prior_sd: optional (2,) standard deviations of a prior on (log v, log w)
      (inf: flat); its information adds to the statistics' (the Bayesian,
      van Trees form of the bound).
    combo: (2,) coefficients of the combination bounded third; the default
      is log load ratio, 2 log v - log w + const.

  Returns:
    ``{'points': (P, 2) log v and log w of each point, 'sigma': (P, 3) the
    1-sigma bounds on log v, log w and the combination,
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
  a = np.asarray(combo, np.float64)
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


def nested_r2(y, base, added) -> dict:
  """R^2 of ``y`` on a cubic in ``base``, then also a quadratic in ``added``."""
  ok = np.isfinite(y)
  y, base, added = y[ok], base[ok], added[ok]
  first = np.stack([base**k for k in range(4)], 1)
  both = np.concatenate([first, np.stack([added, added**2], 1)], 1)
  tss = np.sum((y - y.mean()) ** 2) if y.size else 0.0

  def r2(a):
    if y.size <= a.shape[1] or tss <= 0:
      return float('nan')
    coef = np.linalg.lstsq(a, y, rcond=None)[0]
    return float(1.0 - np.sum((y - a @ coef) ** 2) / tss)

  return {'r2_base': r2(first), 'r2_added': r2(both)}


def _shown(config: Config, log_sigma: np.ndarray) -> dict:
  """Bounds (log units: wind, second parameter[, load ratio]) as reported:
  percent for wind, area weight and load ratio; a factor for bending."""
  if config.vary == 'bending_scale':
    return {
      'wind_pct': float(_percent(log_sigma[0])),
      'bending_factor': float(np.exp(log_sigma[1])),
    }
  out = {
    'wind_pct': float(_percent(log_sigma[0])),
    'area_weight_pct': float(_percent(log_sigma[1])),
  }
  if len(log_sigma) > 2:
    out['load_ratio_pct'] = float(_percent(log_sigma[2]))
  return out


def analyse_fabric(config: Config, fabric: str, rows: list[dict]) -> dict:
  """R^2 per statistic and the bounds, all statistics and each left out.

  R^2 (``r2_base`` then ``r2_added``): for area weight, a cubic in the log load
  ratio, then also the wind; for bending, a cubic in log wind, then also the
  bending."""
  ok = [r for r in rows if r['valid'] and all(np.isfinite(r[k]) for k in STATS)]
  v = np.array([r['wind_speed'] for r in ok])
  x = np.array([r.get(config.vary, config.bending) for r in ok])
  Y = np.array([[r[k] for k in STATS] for r in ok])
  varies = [
    j for j in range(len(STATS)) if np.ptp(Y[:, j]) > 0
  ]  # constants say nothing
  point = np.unique(np.stack([v, x], 1), axis=0, return_inverse=True)[1].ravel()
  lo, hi = box(config, fabric)
  # The search box as a prior: log-uniform over each range has sd = width / sqrt(12).
  box_sd = np.log([_BOX.wind_speed[1] / _BOX.wind_speed[0], hi / lo]) / np.sqrt(12.0)

  def bounds(cols, prior_sd=None) -> dict:
    cols = [c for c in cols if c in varies]
    b = fisher_bounds(np.log(v), np.log(x), point, Y[:, cols], prior_sd)
    x_at = np.exp(b['points'][:, 1])
    inside = (x_at >= lo * (1 - 1e-9)) & (x_at <= hi * (1 + 1e-9))
    return {
      **_shown(config, np.median(b['sigma'][inside], axis=0)),
      'fit_r2': dict(zip([STATS[c] for c in cols], b['fit_r2'].tolist(), strict=True)),
    }

  if config.vary == 'bending_scale':
    base, added = np.log(v), np.log(x)
  else:
    base, added = np.log(physsim.load_ratio(v, x)), np.log(v)
  every = list(range(len(STATS)))
  return {
    'varied': config.vary,
    'worlds': len(rows),
    'used': len(ok),
    'range_half_width_pct': 100.0 * (hi - lo) / (hi + lo),
    'r2': {k: nested_r2(Y[:, j], base, added) for j, k in enumerate(STATS)},
    'bounds': bounds(every),
    'bounds_with_box': bounds(every, box_sd),
    'box_sd': _shown(config, box_sd),
    'without': {k: bounds([c for c in every if c != j]) for j, k in enumerate(STATS)},
  }


def _stem(config: Config) -> str:
  return 'separability' if config.vary == 'area_weight' else 'separability_bending'


def run(config: Config, workdir: str) -> dict:
  """Simulates (or resumes) every fabric, then analyses and plots. Outputs are
  named ``separability*`` (area weight) or ``separability_bending*``."""
  if config.vary not in _VARY:
    raise ValueError(f'vary={config.vary!r}: choose one of {_VARY}')
  os.makedirs(workdir, exist_ok=True)
  stem = os.path.join(workdir, _stem(config))
  path = stem + '.json'
  done = files.resume(path, config).get('fabrics', {})
  for fabric in config.fabrics:
    if fabric in done:
      continue
    n = len(config.winds) * len(second_grid(config, fabric)) * len(config.seeds)
    print(f'{fabric}: simulating {n} worlds ...', flush=True)
    done[fabric] = simulate_fabric(config, fabric)
    files.write_json(path, {'config': dataclasses.asdict(config), 'fabrics': done})
  analysis = {f: analyse_fabric(config, f, done[f]['rows']) for f in config.fabrics}
  result = {'config': dataclasses.asdict(config), 'fabrics': done, 'analysis': analysis}
  files.write_json(path, result)
  text = table(config, analysis)
  files.write_text(stem + '.md', text + '\n')
  plot_stats(config, done, stem + '_stats.png')
  plot_bounds(config, analysis, stem + '_bounds.png')
  print(text)
  return result


# ------------------------------------------------------------------- report

# (key in a bounds dict, column or legend label, format)
_SHOWN = {
  'area_weight': (
    ('wind_pct', 'wind %', '{:.1f}'),
    ('area_weight_pct', 'area weight %', '{:.1f}'),
    ('load_ratio_pct', 'load ratio %', '{:.1f}'),
  ),
  'bending_scale': (
    ('wind_pct', 'wind %', '{:.1f}'),
    ('bending_factor', 'bending factor', 'x{:.2f}'),
  ),
}
_R2_LABELS = {
  'area_weight': ('the load ratio alone', 'with the wind too'),
  'bending_scale': ('the wind alone', 'with the bending too'),
}


def table(config: Config, analysis: dict) -> str:
  """Bounds per fabric, with and without the search box as a prior (its own
  spread in brackets), what leaving each statistic out costs the second
  parameter's bound, and the R^2 of each statistic."""
  shown = _SHOWN[config.vary]
  key2, label2, fmt2 = shown[1]
  head = ' | '.join(label for _, label, _ in shown)
  lines = [
    '1-sigma bounds from one recording (median over grid points inside the '
    'range); from the statistics alone, and with the search box as a prior '
    '(its own spread in brackets):',
    '',
    f'| fabric | {head} | with the box: wind % | {label2} '
    f'| {label2} without: ' + ' / '.join(STATS) + ' |',
    '|---|' + '---:|' * (len(shown) + 2) + '---|',
  ]
  for f, a in analysis.items():
    b, p, box_sd = a['bounds'], a['bounds_with_box'], a['box_sd']
    cells = [fmt.format(b[k]) for k, _, fmt in shown]
    cells.append(f'{p["wind_pct"]:.1f} ({box_sd["wind_pct"]:.0f})')
    cells.append(f'{fmt2.format(p[key2])} ({fmt2.format(box_sd[key2])})')
    cells.append(' / '.join(fmt2.format(a['without'][k][key2]) for k in STATS))
    lines.append(f'| {f} | ' + ' | '.join(cells) + ' |')
  first, second = _R2_LABELS[config.vary]
  lines += [
    '',
    f'Share of each statistic explained by {first} / {second} '
    '(R^2 over worlds, mean over fabrics):',
    '',
    f'| statistic | {first} | {second} |',
    '|---|---:|---:|',
  ]
  for k in STATS:
    r = [a['r2'][k] for a in analysis.values()]
    lines.append(
      f'| {k} | {np.nanmean([x["r2_base"] for x in r]):.3f} | '
      f'{np.nanmean([x["r2_added"] for x in r]):.3f} |'
    )
  return '\n'.join(lines)


def plot_stats(config: Config, done: dict, path: str) -> None:
  """Each statistic's seed mean against the load ratio (area weight) or the
  wind (bending), one line per value of the second parameter; error bars
  span the seeds."""
  fabrics = list(config.fabrics)[:2]
  fig, axes = plt.subplots(
    len(fabrics), len(STATS), figsize=(3.3 * len(STATS), 3.0 * len(fabrics)),
    squeeze=False, layout='constrained',
  )  # fmt: skip
  cmap = plt.get_cmap('coolwarm')
  bending = config.vary == 'bending_scale'
  for i, fabric in enumerate(fabrics):
    rows = [r for r in done[fabric]['rows'] if r['valid']]
    centre = np.mean(physsim.fabric(fabric).area_weight_range)
    values = sorted({r.get(config.vary, config.bending) for r in rows})
    for j, k in enumerate(STATS):
      ax = axes[i, j]
      for n, val in enumerate(values):
        sel = [r for r in rows if r.get(config.vary, config.bending) == val]
        winds = sorted({r['wind_speed'] for r in sel})
        vals = [[r[k] for r in sel if r['wind_speed'] == ws] for ws in winds]
        x = np.array(winds) if bending else physsim.load_ratio(np.array(winds), val)
        label = f'x{val:g}' if bending else f'w x{val / centre:.2f}'
        ax.errorbar(
          x, [np.nanmean(a) for a in vals], [np.nanstd(a) for a in vals],
          fmt='o-', ms=3, lw=1, capsize=2, label=label,
          color=cmap(n / max(len(values) - 1, 1)),
        )  # fmt: skip
      ax.set(xscale='log', title=k if i == 0 else None)
      if i == len(fabrics) - 1:
        ax.set_xlabel('wind speed (m/s)' if bending else '$\\rho v^2 / (w g)$')
      ax.grid(alpha=0.3)
    axes[i, 0].set_ylabel(fabric)
  title = 'bending scale' if bending else 'area weight / centre'
  axes[0, 0].legend(fontsize=6, title=title, title_fontsize=6)
  files.savefig(fig, path, dpi=90)
  plt.close(fig)


def plot_bounds(config: Config, analysis: dict, path: str) -> None:
  """1-sigma bounds per fabric, from the statistics alone and with the search
  box as a prior, against the issue's targets (bending as a factor - 1, %)."""
  names = list(analysis)
  x = np.arange(len(names))
  shown = _SHOWN[config.vary]
  width = 0.8 / len(shown)

  def pct(key, value):
    return 100.0 * (value - 1.0) if key == 'bending_factor' else value

  fig, axes = plt.subplots(1, 2, figsize=(1.3 * len(names) + 4, 4.0), sharey=True)
  for ax, which, title in (
    (axes[0], 'bounds', 'from the motion statistics alone'),
    (axes[1], 'bounds_with_box', 'with the search box as a prior'),
  ):
    for n, (key, label, _) in enumerate(shown):
      values = [pct(key, analysis[f][which][key]) for f in names]
      ax.bar(x + (n - (len(shown) - 1) / 2) * width, values, width, label=label)
    if config.vary == 'bending_scale':
      ax.axhline(50, color='r', ls='--', lw=1, label='bending target x1.5')
    else:
      ax.axhline(5, color='r', ls='--', lw=1, label='area-weight target 5%')
    ax.axhline(10, color='g', ls=':', lw=1, label='wind target 10%')
    ax.set_xticks(x, [f.replace('_', '\n') for f in names], fontsize=7)
    ax.set(yscale='log', title=title)
    ax.grid(alpha=0.3, axis='y')
  key2 = shown[1][0]
  axes[1].plot(x, [pct(key2, analysis[f]['box_sd'][key2]) for f in names], 'k_',
               ms=16, mew=2, label='the range alone (sd)')  # fmt: skip
  unit = '\n(bending: factor - 1)' if config.vary == 'bending_scale' else ''
  axes[0].set_ylabel(f'1-sigma error of one recording, %{unit}')
  axes[1].legend(fontsize=7)
  second = 'bending' if config.vary == 'bending_scale' else 'area weight'
  fig.suptitle(f'Cramer-Rao bounds on wind and {second}', fontsize=10)
  fig.tight_layout()
  files.savefig(fig, path, dpi=90)
  plt.close(fig)
