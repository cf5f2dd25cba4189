"""Calibration tables fitted on recordings a user's rig makes, taken in as a
user's are.

The study's own recordings (``calibration_runs``) are simulated at the
evaluation recipe's mesh and clock, from cameras it draws, with the
estimator's noise model, and handed to the search with a camera displaced as
the intake errs. A user's recording differs in all of that: a finer mesh,
30 fps for 3 s, a rig's depth noise, a camera on the user's side, and the
intake's own alignment in between. Estimates of such recordings came out
wider at the same error than the study's (docs/studies/calibration.md), so
tables fitted on the study's recordings over-cover them. Here the recordings
are the windy rig's (``benchmarks.windy_rig --pairs``: pairs drawn over the
prior as the study draws its own, each estimated by ``experiments.estimate``
through the intake), and each estimate's saved GP is read as the study reads
its own (``calibration_scores``), in every mode: the same analysis, on the
path users run.

A pair is recordings ``rec2j`` and ``rec2j+1`` of one workdir (one fabric,
two fan settings); a recording refused or failed is left out, and its mate
is then read alone.
"""

from __future__ import annotations

import dataclasses
import glob
import math
import os

import numpy as np

from experiments.pipeline import layout
from experiments.pipeline.recording import read_json
from experiments.studies import calibration_runs, told_cameras

# Where a windy-rig recording keeps its truth and its estimate (world_up).
_TRUTH = os.path.join('recording', 'truth.json')
_RECIPE = os.path.join('recording', 'recipe.json')
_ESTIMATE = 'est_world_up'
# A mode whose tables were fitted and checked on fewer recordings is not
# shipped (a rig's pairs are few: its joint modes read a handful); its
# estimates quote another calibration's tables for it.
MIN_RECORDINGS = 20
# The settings every rig estimate must share with the study's searches.
_SHARED = ('cloth_resolution', 'fps', 'frames', 'cameras', 'distance', 'likelihood',
           'sharpness', 'model_error', 'gusts', 'warmup', 'posterior_grid', 'q',
           'n_init', 'max_iter', 'sensor_noise')  # fmt: skip


def rig_folders(patterns: str) -> list[str]:
  """The windy-rig workdirs ``patterns`` names (comma-separated paths or
  globs), in order, each once.

  Raises:
    ValueError: a pattern that matches no folder.
  """
  out = []
  for pat in (p for p in patterns.split(',') if p):
    found = sorted(p for p in glob.glob(pat) if os.path.isdir(p))
    if not found:
      raise ValueError(f'--rig_runs: no folder matches {pat!r}')
    out += [f for f in found if f not in out]
  return out


def _recording(folder: str, k: int) -> dict | None:
  """Recording ``k`` of a windy-rig workdir, as the study's runs are (truth,
  fabric, its estimate's folder, the claim it carried), or None where it has
  no finished estimate (refused, failed, or still running)."""
  where = os.path.join(folder, f'rec{k:02d}')
  est = os.path.join(where, _ESTIMATE)
  if not (
    os.path.isfile(os.path.join(est, layout.ESTIMATE_FILE))
    and os.path.isfile(os.path.join(est, layout.POSTERIOR_FILE))
  ):
    return None
  result = read_json(os.path.join(est, layout.ESTIMATE_FILE))
  truth = read_json(os.path.join(where, _TRUTH))
  recipe = read_json(os.path.join(where, _RECIPE))
  if recipe.get('material') != result.get('material'):
    raise ValueError(
      f'{est}: estimated as {result.get("material")!r}, recorded as '
      f'{recipe.get("material")!r}'
    )
  align = result.get('alignment') or {}
  try:  # read now: a damaged file is named here, not deep in the analysis
    saved = calibration_runs.saved_gp({'workdir': est})
  except (OSError, ValueError, KeyError, EOFError) as e:
    path = os.path.join(est, layout.POSTERIOR_FILE)
    raise ValueError(f"{path}: not a finished estimate's posterior ({e})") from e
  return {
    'saved': saved,
    'truth': {f: float(truth[f]) for f in ('bending_scale', 'wind_speed', 'area_weight')},
    'material': result['material'], 'workdir': est,
    'claim': (float(align.get('camera_sd_m', 0.0)), float(align.get('camera_sd_deg', 0.0))),
    'config': result.get('config', {}),
  }  # fmt: skip


def rig_runs(patterns: str) -> list[dict]:
  """The finished estimates of the windy-rig workdirs ``patterns`` names, as
  ``calibration_runs.saved_runs`` returns the study's. ``seq`` numbers the
  pairs across folders: recordings ``rec2j`` and ``rec2j+1`` of one fabric
  (``--pairs``) are pair ``p``'s ``2 p`` and ``2 p + 1``; a recording whose
  neighbour is of another fabric (``--winds`` with ``--fabric_draws``: each
  its own) is a pair of its own, ``2 p`` alone. So the analysis joins only
  recordings of one fabric, and folds whole pairs.

  Raises:
    ValueError: no folder, or none holds a finished estimate.
  """
  runs, pair = [], 0
  for folder in rig_folders(patterns):
    names = [n for n in os.listdir(folder) if n.startswith('rec') and n[3:].isdigit()]
    count = max((int(n[3:]) for n in names), default=-1) + 1
    k = 0
    while k < count:
      group = [k, k + 1] if k % 2 == 0 and _one_fabric(folder, k, k + 1) else [k]
      for i, kk in enumerate(group):
        if (rec := _recording(folder, kk)) is not None:
          runs.append({'seq': 2 * pair + i, **rec})
      pair, k = pair + 1, k + len(group)
  if not runs:
    raise ValueError(f'--rig_runs={patterns}: no finished estimate in those folders')
  return runs


def _one_fabric(folder: str, a: int, b: int) -> bool:
  """Whether recordings ``a`` and ``b`` of a windy-rig workdir are of one
  fabric (its recipe's material, bending and area weight), as ``--pairs``
  draws them."""
  fabric = []
  for k in (a, b):
    path = os.path.join(folder, f'rec{k:02d}', _RECIPE)
    if not os.path.isfile(path):
      return False
    r = read_json(path)
    fabric.append(tuple(r.get(f) for f in ('material', 'bending_scale', 'area_weight')))
  return fabric[0] == fabric[1]


def claims_range(runs: list[dict]) -> tuple[float, float, float]:
  """(metres, degrees, spread): the intake claims ``runs``' estimates
  carried, as ``carried_errors.table_of`` reads a table's: each component's
  geometric centre of its smallest and largest claim, and the larger
  half-width in log of the two ranges. An intake's claimed tilt follows its
  claimed shift (both are one placement's error, ``intake_alignment``), so
  the shifts' range is the one that says which claims the recordings
  covered; the tilts' range, as wide in log, reaches past the tilts seen,
  where no claim of a shift in range falls. (The study's tables take the
  smaller, ``told_cameras.intake_range``: their claims were drawn, each
  component jittered on its own.)"""
  claims = np.array([r['claim'] for r in runs], np.float64)
  if np.any(claims <= 0):
    raise ValueError(
      'a rig estimate carried no camera error: run them through the intake'
    )
  return told_cameras.claims_box(claims, widest=True)


def with_rig_runs(config, runs: list[dict]):
  """The study ``config`` whose recordings are ``runs`` (``rig_runs``): its
  fabrics theirs (in the study's order), its estimates' camera error the
  range of their claims (``claims_range``) from the intake, as many pairs as
  they hold.

  Raises:
    ValueError: a rig estimate searched otherwise than the study's
      estimates would (another mesh, clock, search or likelihood): its
      tables would not be an estimate's.
  """
  est = config.estimate.flat()
  for r in runs:
    bad = [
      k for k in _SHARED if k in r['config'] and _differs(r['config'][k], est.get(k))
    ]
    if bad:
      raise ValueError(
        f'{r["workdir"]}: searched with ' + ', '.join(
          f'{k}={r["config"][k]} (the study: {est.get(k)})' for k in bad
        )
      )  # fmt: skip
  m, deg, spread = claims_range(runs)
  mats = {r['material'] for r in runs}
  order = [f for f in config.materials or (config.material,) if f in mats]
  order += sorted(mats - set(order))
  estimate = config.estimate.replace(
    camera_sd_m=m, camera_sd_deg=deg, camera_sd_from='intake'
  )
  return dataclasses.replace(
    config, materials=tuple(order), material=order[0], estimate=estimate,
    camera_sd_spread=spread, camera_errors=(), pairs=max(1, _pairs(runs, order)),
  )  # fmt: skip


def _pairs(runs: list[dict], mats: list[str]) -> int:
  """The most pairs one fabric has (the study's ``pairs`` per fabric)."""
  return max(len({r['seq'] // 2 for r in runs if r['material'] == m}) for m in mats)


def _differs(a, b) -> bool:
  if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
    return list(a or []) != list(b or [])
  if isinstance(a, (int, float)) and isinstance(b, (int, float)):
    return not math.isclose(float(a), float(b), rel_tol=1e-9)
  return a != b


def shippable(out: dict) -> tuple[dict, list[str]]:
  """Calibration ``out`` (``calibration_report.result``) without the tables
  of modes held out on fewer than ``MIN_RECORDINGS`` recordings, and those
  modes: their coverage stays in the report, their levels are not shipped."""
  rec = out['recalibration']
  few = [
    m for m in rec['modes']
    if out['held_out'].get(m, {}).get('n', 0) < MIN_RECORDINGS
  ]  # fmt: skip
  kept = {**rec, 'modes': {m: v for m, v in rec['modes'].items() if m not in few},
          'weights': {m: v for m, v in rec.get('weights', {}).items() if m not in few}}  # fmt: skip
  return {**out, 'recalibration': kept}, few
