"""Which recordings measure the fabric, not only the wind? A Fisher-bound study.

Issue 39, item 2. A candidate recording is a piece of the fabric (the 1 m
sheet, or a 10-30 cm swatch) pinned at its two top corners (or one) in front of
a fan at one setting (or none), filmed by a depth camera; or the fabric flat on
a table with a few centimetres of it over the edge, in still air, filmed from
the side (an overhang: the textile cantilever test). What the camera sees
is approximated from the simulated vertices by a few statistics, each divided
by the cloth's size (``protocol_camera.summaries``): where the cloth hangs on
average over the clip (its centroid out of plane and up), where its free
bottom edge hangs, how curved it is (the mean norm of the grid Laplacian,
times the size), and how much it moves (the centroid's standard deviation
over the clip).

Per candidate and truth (bending scale, area weight, wind), with MuJoCo C on
the CPU:

* the slopes J of the statistics with respect to (log bending, log area
  weight, log wind) by central finite differences in steady wind; a
  recording without wind has no wind parameter;
* their noise covariance R: the spread over ``draws`` gust histories
  (gust intensity ``gusts``), pulled half-way to its diagonal
  (``bo.design.shrink``: a 6 x 6 covariance from a few draws), plus a depth
  sensor and set-up term (``protocol_camera.sensor_sd``): a Kinect-class
  camera (sigma(z) = 1.5 mm at 1 m, growing as z^2; 640 x 480 px, 58 deg
  horizontal field of view) placed so the cloth fills 60% of the frame's
  width, but no nearer than its 0.5 m minimum range; ``setup_mm`` of set-up
  repeatability on every position and a ``curvature_floor`` on the curvature.

A set of recordings of one fabric shares bending and area weight; each fan
setting has its own wind. With the search box as a Gaussian prior in log
space (the box's variance, ``bo.design.log_box_sd``), the Fisher information
of the set gives the Cramer-Rao posterior widths of log bending and log area
weight, reported as the prior's 90% width over the posterior's ("narrowing"),
in three modes: the video alone, every wind read by an anemometer to 2%, and
the area weight weighed to 2% (a kitchen scale and a ruler).

The bound is on simulated statistics with the estimator's own simulator: a
lower bound on the width, which real recordings (another simulator, a camera,
model error) can only widen. ``experiments/protocol.py`` is its command line.

This module runs the study (``run``); its parts, each a module of
``experiments.studies``:

* ``protocol_candidates``: a candidate recording, its name and its mesh;
* ``protocol_camera``: the statistics a depth camera reads of it, and their
  sensor noise;
* ``protocol_config``: the study's settings, presets and candidate sets;
* ``protocol_slopes``: one candidate's slopes and noise at one truth,
  simulated and cached;
* ``protocol_bound``: a set's narrowing (and bias under another physics);
* ``protocol_elastica``: the simulated overhangs against the heavy elastica;
* ``protocol_report`` and ``protocol_figures``: the JSON, table and figure;
* ``protocol_plan``: what to record next for one estimate
  (``experiments/plan.py``).
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax
import numpy as np

import physsim
from experiments.studies import (
  protocol_bound,
  protocol_camera,
  protocol_candidates,
  protocol_config,
  protocol_elastica,
  protocol_figures,
  protocol_report,
  protocol_slopes,
)
from experiments.studies.protocol_config import Config

CACHE_DIR = 'slopes'


def _check(config: Config) -> list[float]:
  """The truths' bending scales; a ValueError naming a setting the study
  cannot run with, before any simulation."""
  bendings = protocol_config.floats('bendings', config.bendings)
  if config.draws < 3 or not config.clip > 0:
    raise ValueError(
      f'need --draws >= 3 and --clip > 0, got {config.draws}, {config.clip}'
    )
  if not (np.isfinite(config.drag_sd) and config.drag_sd >= 0):
    raise ValueError(f'--drag_sd={config.drag_sd}: need a number >= 0 (0: trusted)')
  protocol_bound.stat_index(config.stats)  # an unknown name refused here
  return bendings


def _simulate(jobs, area_weight: float, config: Config, cache: str) -> dict:
  """Each job's (candidate, bending) slopes at ``area_weight``
  (``protocol_slopes.candidate_slopes``, cached under ``cache``), keyed by
  (name, bending), each job's gust histories its own; a line per job."""
  key = jax.random.key(config.seed)
  t0 = time.time()
  slopes = {}
  for i, (c, b) in enumerate(jobs):
    row = protocol_slopes.candidate_slopes(
      c, b, area_weight, config, cache, jax.random.fold_in(key, i)
    )
    slopes[(c.name, b)] = row
    print(f'[{i + 1}/{len(jobs)}] {c.name} at bending {b:g}: '
          f'{row.get("seconds", 0):.0f} s ({time.time() - t0:.0f} s so far)', flush=True)  # fmt: skip
  return slopes


def _set_table(sets, bendings, slopes, prior, config: Config) -> list[dict]:
  """Each set's narrowing at each truth, in every mode."""
  table = []
  for label, members in sets.items():
    names, shared = zip(*map(protocol_config.shares_wind, members), strict=True)
    for b in bendings:
      rows = [slopes[(n, b)] for n in names]
      entry = {'set': label, 'members': members, 'bending_truth': b}
      for mode in protocol_bound.MODES:
        entry[mode] = protocol_bound.set_narrowing(
          rows, prior, mode, shared, config.drag_sd, config.stats
        )
      table.append(entry)
  return table


def _convergence(conv, bending, slopes, prior, config: Config) -> list[dict]:
  """Each finer mesh ``conv`` beside every listed candidate of its size and
  wind at one truth: each one's narrowing alone in every mode, its slopes in
  log bending and its statistics' noise sds."""
  out = []
  for c in conv:
    coarse = [
      n for n in config.candidates if n.rsplit('_r', 1)[0] == c.name.rsplit('_r', 1)[0]
    ]
    for n in coarse:
      pair = {}
      for name in (n, c.name):
        r = slopes[(name, bending)]
        pair[name] = {
          mode: protocol_bound.set_narrowing([r], prior, mode, stats=config.stats)
          for mode in protocol_bound.MODES
        } | {'slope_log_bending': [s[0] for s in r['slopes']],
             'noise_sd': np.sqrt(np.diag(r['noise_cov'])).tolist()}  # fmt: skip
      out.append(pair)
  return out


def run(config: Config, workdir: str) -> dict:
  """Simulates every candidate at every truth, evaluates the sets, writes
  ``protocol.json`` and ``protocol.png`` to ``workdir``; returns the result."""
  bendings = _check(config)
  cands = [protocol_candidates.parse(n) for n in config.candidates]
  conv = [protocol_candidates.parse(n) for n in config.convergence]
  sets = protocol_config.parse_sets(config.sets, list(config.candidates))
  space = physsim.search_space(config.material)
  w = config.area_weight or float(space.center().area_weight)
  jobs = [(c, b) for b in bendings for c in cands] + [(c, bendings[0]) for c in conv]
  t0 = time.time()
  slopes = _simulate(jobs, w, config, os.path.join(workdir, CACHE_DIR))
  prior = protocol_bound.priors(config.material, config.reading)
  overhangs = [
    r for r in slopes.values() if protocol_candidates.parse(r['candidate']).overhang
  ]
  result = {
    'material': config.material, 'area_weight': w, 'bendings': bendings,
    'priors_sd_log': prior, 'stats': list(config.stats or protocol_camera.STATS),
    'table': _set_table(sets, bendings, slopes, prior, config),
    'convergence': _convergence(conv, bendings[0], slopes, prior, config),
    'overhang_vs_elastica': protocol_elastica.against_elastica(
      overhangs, config.material
    ),
    'camera_distance_m': {
      c.name: protocol_camera.camera_distance(c.size) for c in cands
    },
    'slopes': [slopes[k] for k in slopes],
    'seconds': time.time() - t0,
    # each candidate's own simulation time, summed: the run's from scratch
    'simulation_seconds': float(sum(r.get('seconds', 0.0) for r in slopes.values())),
    'config': dataclasses.asdict(config),
  }  # fmt: skip
  protocol_report.write(result, workdir)
  protocol_figures.plot(result, os.path.join(workdir, protocol_report.FIGURE_FILE))
  return result
