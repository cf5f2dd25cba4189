"""The pictures of one finished search: its trace and its montage.

``plot_trace`` is the paper's Figure 3 (the distance and each parameter per
iteration); ``plot_montage`` puts the recording beside a simulation at the
estimate, on one depth colour scale with frame times. ``results`` draws both
beside ``estimate.json`` (the posterior's own figure: ``posterior.plot``). The
trace reads in the table's units where it is given them (issue 76:
``units.in_units``), as ``posterior.png`` does, else in the search's scales.
"""

from __future__ import annotations

import numpy as np

import physsim
from experiments.pipeline import files
from experiments.pipeline.posterior_figure import LABELS


def iterations_of(n_evals: int, n_init: int, q: int) -> np.ndarray:
  """(n_evals,) the iteration each evaluation belongs to (0: initial design),
  as the console counts them."""
  it = np.zeros(n_evals, np.int64)
  it[n_init:] = 1 + np.arange(max(n_evals - n_init, 0)) // q
  return it


# What each distance's trace calls its score (a shape distance uses no network).
DISTANCE_WORDS = {
  'shape': ("distance of the sheet's mean shape (m$^2$)", 'shape distance'),
  'energy': ('physics similarity distance (PSD)', 'PSD'),
  'centroid': ('physics similarity distance (centroid)', 'PSD'),
  'energy+shape': ('PSD and shape distance, geometric mean', 'distance'),
}


def plot_trace(X_unit, Y, iteration, space, truth, path: str,
               distance: str = 'energy',
               units: tuple[dict, dict] | None = None) -> None:  # fmt: skip
  """The distance and each parameter per iteration (the paper's Figure 3),
  saved to ``path`` (PNG): ``trace_figure``'s."""
  fig = trace_figure(X_unit, Y, iteration, space, truth, distance, units)
  files.savefig(fig, path, dpi=90)
  files.pyplot().close(fig)


def trace_figure(X_unit, Y, iteration, space, truth, distance: str = 'energy',
                 units: tuple[dict, dict] | None = None):  # fmt: skip
  """``plot_trace``'s figure (matplotlib), not saved: the distance per
  iteration, then each parameter's evaluated values coloured by it.

  Args:
    X_unit: (n, 3) evaluated unit-cube points, in order.
    Y: (n,) their distances (NaN: blew up).
    iteration: (n,) the iteration of each (``iterations_of``).
    space: the search space (axis limits).
    truth: true parameters (the search's scales) or None.
    distance: the estimate's distance (``DISTANCE_WORDS``), for the labels.
    units: ``(names, factors)`` from the search's scales to the units a
      person reads (``units.in_units`` of the fabric: bending rigidity in
      uN m, area weight in g/m^2, as the table and ``posterior.png``); None:
      the search's own (``posterior_figure.LABELS``).
  """
  names, k = units or (LABELS, dict.fromkeys(physsim.Params._fields, 1.0))
  long_name, short_name = DISTANCE_WORDS.get(distance, DISTANCE_WORDS['energy'])
  X = np.asarray(physsim.from_unit(X_unit, space))  # (3, n)
  Y = np.asarray(Y, np.float64)
  ok = np.isfinite(Y)
  jitter = (np.random.default_rng(0).random(len(Y)) - 0.5) * 0.3
  xs = iteration + jitter
  plt = files.pyplot()
  fig, axes = plt.subplots(1, 4, figsize=(17, 3.8), layout='constrained')
  _distance_panel(axes[0], xs, Y, iteration, long_name)
  colour = np.log10(np.where(ok, Y, np.nan))
  for i, (ax, name) in enumerate(zip(axes[1:], physsim.Params._fields, strict=True)):
    sc = ax.scatter(xs, k[name] * X[i], c=colour, s=14, cmap='viridis')
    ax.set(xlabel='iteration (0 = initial design)', ylabel=names[name],
           ylim=k[name] * np.asarray(space.bounds()[i]))  # fmt: skip
    if name == 'bending_scale':
      ax.set_yscale('log')
    if truth is not None:
      ax.axhline(k[name] * truth[name], color='r', lw=1, label='truth')
      ax.legend(fontsize=8, loc='upper left', bbox_to_anchor=(0, -0.18), frameon=False)
  fig.colorbar(
    sc, ax=axes[1:], label=f'log$_{{10}}$ {short_name} (dark: low)', shrink=0.9
  )
  return fig


def _distance_panel(ax, xs, Y, iteration, label: str) -> None:
  """The first panel: each candidate's distance at its (jittered) iteration
  ``xs``, the best so far at each iteration's end, and those that blew up."""
  ok = np.isfinite(Y)
  best = np.fmin.accumulate(np.where(ok, Y, np.inf))
  last_of = {
    int(i): j for j, i in enumerate(iteration)
  }  # last evaluation per iteration
  its = np.array(sorted(last_of))
  ax.plot(xs[ok], Y[ok], '.', color='0.55', label='candidate')
  ax.plot(its, best[[last_of[i] for i in its]], '-o', ms=3, color='k',
          label='best so far')  # fmt: skip
  if (~ok).any():
    ax.plot(xs[~ok], np.full((~ok).sum(), np.nanmax(Y) if ok.any() else 1), 'x',
            color='r', label='blew up')  # fmt: skip
  ax.set(xlabel='iteration (0 = initial design)', ylabel=label, yscale='log')
  ax.legend(fontsize=8)


def plot_montage(
  recorded: np.ndarray, simulated: np.ndarray, fps: float, path: str, n: int = 6,
  sim_label: str = 'simulation at the estimate',
) -> None:  # fmt: skip
  """Rows: the recording and a simulation, ``n`` frames each at the same times,
  depth on one colour scale (white: no return) or colour frames.

  Args:
    recorded: (T, H, W) depth in metres or (T, H, W, 3) uint8 colour.
    simulated: the same for the simulation.
    fps: frame rate of both (for the frame times).
    path: PNG path.
    n: frames shown.
    sim_label: the second row's label.
  """
  idx = np.unique(np.linspace(0, min(len(recorded), len(simulated)) - 1, n).astype(int))
  colour = recorded.ndim == 4
  both = np.concatenate([np.ravel(recorded[idx]), np.ravel(simulated[idx])])
  valid = both[both > 0]
  lo, hi = np.quantile(valid, [0.01, 0.99]) if valid.size else (0.0, 1.0)
  plt = files.pyplot()
  cmap = plt.get_cmap('viridis').with_extremes(bad='white')
  fig, axes = plt.subplots(2, len(idx), figsize=(2.1 * len(idx) + 1.2, 4.6),
                           squeeze=False, layout='constrained')  # fmt: skip
  im = None
  for r, (frames, name) in enumerate(((recorded, 'recording'), (simulated, sim_label))):
    for c, t in enumerate(idx):
      ax = axes[r, c]
      if colour:
        ax.imshow(frames[t])
      else:
        im = ax.imshow(np.ma.masked_equal(frames[t], 0.0), cmap=cmap, vmin=lo, vmax=hi)
      ax.set(xticks=[], yticks=[])
      if r == 0:
        ax.set_title(f't = {t / fps:.2f} s', fontsize=9)
      if c == 0:
        ax.set_ylabel(name, fontsize=9)
  if im is not None:
    fig.colorbar(im, ax=axes, shrink=0.8, label='depth (m); white: no return')
  files.savefig(fig, path, dpi=80)
  plt.close(fig)
