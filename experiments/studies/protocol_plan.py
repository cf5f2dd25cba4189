"""What to record next (issue 39, item 4): the protocol study's candidates
ranked for one estimate.

From an estimate's posterior draws, each candidate's slopes and noise are
simulated at a few posterior points (``node_values``; cached as the study's,
``protocol_slopes.candidate_slopes``) and the candidates ranked by the
expected information gain about bending and area weight
(``rank_candidates``, ``bo.design.expected_gain``); ``recommendation`` says
the best in words a person can act on. ``experiments/plan.py`` is its command
line.
"""

from __future__ import annotations

import dataclasses
import os

import jax
import numpy as np

from bo import design
from experiments.pipeline import files, layout, progress
from experiments.studies import (
  protocol_bound,
  protocol_camera,
  protocol_candidates,
  protocol_config,
  protocol_slopes,
)
from experiments.studies.protocol_config import Config

PLAN_FILE = 'plan.json'
PLAN_CACHE_DIR = 'plan_slopes'
# the study's meshes: a swatch needs ~1.25 cm (or finer) to show bending at all
PLAN_CANDIDATES = (
  'sheet_100cm_2ms_r9', 'sheet_100cm_3.5ms_r9', 'sheet_100cm_5ms_r9',
  'swatch_10cm_2ms_r13', 'swatch_20cm_2ms_r17', 'swatch_30cm_2ms_r17',
  'swatch_20cm_still_r9', 'overhang_3cm_r9', 'overhang_5cm_r9',
)  # fmt: skip


def node_values(draws: np.ndarray, nodes: int) -> np.ndarray:
  """(K, 2) points where slopes are simulated: the posterior median of log
  area weight and K quantiles of log bending (its effect is the most
  nonlinear), kept where the finite differences stay inside the box."""
  q = (np.arange(nodes) + 0.5) / nodes
  b = np.quantile(draws[:, 0], q)
  w = np.full(nodes, np.median(draws[:, 1]))
  b = np.clip(b, np.log(0.1) + 0.41, np.log(10) - 0.41)  # +-2 steps of 0.2
  lo, hi = protocol_config.SPACE.area_weight
  w = np.clip(w, np.log(lo) + 0.11, np.log(hi) - 0.11)
  return np.stack([b, w], axis=1)


def rank_candidates(draws, weights, rows_per_node: dict[str, list[dict]], nodes,
                    reading: float, material: str) -> list[dict]:  # fmt: skip
  """Expected information gain about (log bending, log area weight) of each
  candidate from the current posterior draws (``bo.design.expected_gain``),
  each draw using the slopes of its nearest node; a new fan setting's wind is
  a nuisance with the box's prior, or a reading's (``reading`` > 0).

  Returns:
    One dict per candidate, the most informative first: ``candidate``,
    ``eig_nats``, and the posterior standard deviations of log bending and
    log area weight now and after (Laplace, at the draws' covariance).
  """
  prior = protocol_bound.priors(material, reading or 0.02)
  wind_sd = prior['reading'] if reading > 0 else prior['log_wind']
  near = design.nearest(draws, nodes)
  _, cov = design.weighted_cov(draws, weights)
  out = []
  for name, rows in rows_per_node.items():
    infos = np.stack([
      design.fisher(np.array(r['slopes']), np.array(r['noise_cov'])) for r in rows
    ])[near]  # fmt: skip
    q = [wind_sd] if rows[0]['wind'] > 0 else []
    gain = design.expected_gain(draws, weights, infos, nuisance_sd=q, keep=[0, 1])
    s = np.zeros((2 + len(q),) * 2)
    s[:2, :2] = cov
    s[2:, 2:] = np.diag(np.square(q))
    mean_info = np.einsum('s,sij->ij', weights / weights.sum(), infos)
    after = np.sqrt(np.diag(design.posterior_cov(s, mean_info)))[:2]
    out.append({
      'candidate': name, 'eig_nats': gain,
      'sd_log_bending': [float(np.sqrt(cov[0, 0])), float(after[0])],
      'sd_log_area_weight': [float(np.sqrt(cov[1, 1])), float(after[1])],
    })  # fmt: skip
  return sorted(out, key=lambda r: -r['eig_nats'])


def describe(name: str, clip: float) -> str:
  """A candidate in words a person can act on."""
  c = protocol_candidates.parse(name)
  distance = protocol_camera.camera_distance(c.size)
  if c.overhang:
    return (
      f'the fabric flat on a table, {100 * c.size:.0f} cm of it over the edge, '
      f'still air, the camera {distance:.2f} m in front of the edge '
      '20-40 degrees above the table, a few still frames (python -m '
      'experiments.overhang --depth reads it)'
    )
  fan = f'the fan at {c.wind:g} m/s' if c.wind > 0 else 'no fan'
  pins = 'its two top corners' if c.pins == 2 else 'one top corner'
  return (
    f'a {100 * c.size:.0f} cm square pinned at {pins}, {fan}, the camera '
    f'{distance:.2f} m away, {clip:g} s'
  )


# What experiments.plan may ask, checked before anything is read or simulated:
# each candidate and node is up to a minute of MuJoCo C on two cores.
PLAN_LIMITS = {'candidates': (1, 32), 'nodes': (1, 16), 'draws': (3, 64)}
PLAN_CLIP_S = (0.25, 10.0)
PLAN_READING = (0.0, 1.0)


def check_plan(candidates, nodes: int, reading: float, config: Config) -> None:
  """Refuses what ``plan`` cannot do sensibly, before anything is allocated:
  counts outside ``PLAN_LIMITS`` (fewer than 3 gust histories give no noise
  covariance, so any candidate looks informative), a clip outside
  ``PLAN_CLIP_S``, a reading outside ``PLAN_READING``, a candidate that is
  not one.

  Raises:
    ValueError: naming the flag and its value.
  """
  counts = {'candidates': len(candidates), 'nodes': nodes, 'draws': config.draws}
  for name, value in counts.items():
    lo, hi = PLAN_LIMITS[name]
    if isinstance(value, bool) or not lo <= value <= hi:
      what = f'{value} given' if name == 'candidates' else str(value)
      raise ValueError(f'--{name}={what}: need {lo} to {hi}')
  lo, hi = PLAN_CLIP_S
  if not lo <= config.clip <= hi:
    raise ValueError(f'--clip={config.clip:g}: need {lo:g} to {hi:g} s')
  lo, hi = PLAN_READING
  if not lo <= reading <= hi:
    raise ValueError(f'--reading={reading:g}: need {lo:g} to {hi:g} (relative sd)')
  twice = sorted({n for n in candidates if list(candidates).count(n) > 1})
  if twice:
    raise ValueError(f'--candidates: {twice[0][:64]} listed twice')
  for name in candidates:
    if len(name) > 64:
      raise ValueError(f'--candidates: a name of {len(name)} characters is none')
    try:
      protocol_candidates.parse(name)
    except ValueError as e:
      raise ValueError(f'--candidates: {e}') from None


def plan(workdir: str, candidates=PLAN_CANDIDATES, nodes: int = 1,
         reading: float = 0.0, config: Config | None = None, *,
         show_progress: bool = True) -> dict:  # fmt: skip
  """Ranks ``candidates`` for the estimate in ``workdir`` (``layout.read_draws``);
  slopes simulated at ``nodes`` posterior points with ``config``'s settings,
  cached in ``<workdir>/plan_slopes/``, with a progress bar and its time left
  (``show_progress``); writes ``plan.json``.

  Raises:
    ValueError: settings ``check_plan`` refuses, or an estimate's files that
      are missing or unreadable (named).
  """
  config = config or Config()
  check_plan(candidates, nodes, reading, config)
  material, draws, weights = layout.read_draws(workdir)
  config = dataclasses.replace(config, material=material)
  points = node_values(draws, nodes)
  cache = os.path.join(
    workdir,
    PLAN_CACHE_DIR,
    f'clip{config.clip:g}_draws{config.draws}_seed{config.seed}',
  )
  key = jax.random.key(config.seed)
  cands = {name: protocol_candidates.parse(name) for name in candidates}
  jobs = [
    (name, k, float(np.exp(b)), float(np.exp(w)))
    for name in candidates
    for k, (b, w) in enumerate(points)
  ]
  cached = [
    os.path.exists(protocol_slopes.slope_path(cands[name], b, w, config, cache))
    for name, _, b, w in jobs
  ]  # fmt: skip
  rows = {name: [] for name in candidates}
  with progress.Bar(len(jobs), 'plan: slopes', 'sim', disable=not show_progress) as bar:
    bar.skip(sum(cached))  # read back, not timed
    for (name, k, bending, area_weight), done in zip(jobs, cached, strict=True):
      rows[name].append(
        protocol_slopes.candidate_slopes(
          cands[name], bending, area_weight, config, cache, jax.random.fold_in(key, k)
        )
      )
      if not done:
        bar.done(1)
  ranked = rank_candidates(draws, weights, rows, points, reading, material)
  best = ranked[0]
  line = recommendation(best, config.clip)
  result = {'material': material, 'nodes': np.exp(points).tolist(),
            'reading': reading, 'ranked': ranked, 'recommendation': line}  # fmt: skip
  files.write_json(os.path.join(workdir, PLAN_FILE), result)
  return result


def recommendation(best: dict, clip: float) -> str:
  """The one line: what to record next and what it should give."""
  nb = best['sd_log_bending'][0] / best['sd_log_bending'][1]
  nw = best['sd_log_area_weight'][0] / best['sd_log_area_weight'][1]
  if best['eig_nats'] < 0.05:
    return ('Next recording: none of the candidates narrows bending or area weight '
            f'much (best {best["eig_nats"]:.2f} nats); weigh the fabric instead.')  # fmt: skip
  return (
    f'Next recording: {describe(best["candidate"], clip)} '
    f'(expected gain {best["eig_nats"]:.2f} nats: bending x{nb:.2f}, '
    f'area weight x{nw:.2f} narrower; a Fisher bound).'
  )


def plan_table(result: dict) -> str:
  """``plan``'s ranking as a markdown table: each candidate's expected gain
  and the posterior sds it would leave."""
  lines = ['| candidate | EIG (nats) | bending sd (log) now -> after | '
           'area weight sd (log) now -> after |', '|---|---:|---:|---:|']  # fmt: skip
  for r in result['ranked']:
    b, w = r['sd_log_bending'], r['sd_log_area_weight']
    lines.append(f'| {r["candidate"]} | {r["eig_nats"]:.3f} | {b[0]:.3f} -> {b[1]:.3f} '
                 f'| {w[0]:.3f} -> {w[1]:.3f} |')  # fmt: skip
  return '\n'.join(lines)
