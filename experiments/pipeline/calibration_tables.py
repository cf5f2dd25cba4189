"""The shipped calibration tables, and the one an estimate's settings match.

Coverage of the posterior's intervals was measured on held-out simulated
recordings (``experiments/calibrate.py``) and ships with the package. An
estimate's settings, network and mode (video alone, with readings, a joint)
pick the table its intervals are read with (``calibration_note``: its
recalibrated levels and the coverage it quotes), or say what differs. Part
of resolving an estimate's settings (``setup``), before the search.
"""

from __future__ import annotations

import functools
import json
import os

import numpy as np

import physsim
from experiments.pipeline import carried_errors, embedding, files

# Coverage of the posterior's intervals measured on held-out simulated
# recordings, shipped with the package (``experiments/calibrate.py --install``):
# the default distance's (its networks' recipe) and the shape distance's (no
# network), at the demo's size; and the shape distance's at the estimate's own
# (paper) size, every fabric.
_HERE = os.path.dirname(__file__)
CALIBRATION_FILE = os.path.join(_HERE, 'calibration.json')
SHAPE_CALIBRATION_FILE = os.path.join(_HERE, 'calibration_shape.json')
SHAPE_PAPER_CALIBRATION_FILE = os.path.join(_HERE, 'calibration_shape_paper.json')
# none shipped yet: the study trains demo-size networks only
PAPER_CALIBRATION_FILE = os.path.join(_HERE, 'calibration_paper.json')


SIZES = ('demo', 'paper')


def shipped_calibration(
  distance: str,
  size: str = 'demo',
  camera: tuple[float, float] = (0.0, 0.0),
  spread: float = 0.0,
  source: str = 'given',
  recordings: str = '',
) -> str:
  """Where the calibration of estimates with ``distance`` at the study's
  ``size`` is shipped (and ``--install`` puts it): the shape distance's own
  files, every other distance's the default ones (whose networks they
  record); tables measured with a camera error (``camera``: metres,
  degrees; ``spread``: drawn per recording over a range about it;
  ``source``: 'intake' where the cameras were displaced as the intake errs;
  ``recordings``: 'rig', a user's rig's) beside them (``carried_errors.camera_path``)."""
  if size not in SIZES:
    raise ValueError(f'no calibration size {size!r}: one of {SIZES}')
  shape = distance == 'shape'
  if size == 'demo':
    base = SHAPE_CALIBRATION_FILE if shape else CALIBRATION_FILE
  else:
    base = SHAPE_PAPER_CALIBRATION_FILE if shape else PAPER_CALIBRATION_FILE
  return carried_errors.camera_path(base, camera, spread, source, recordings)


def shipped_calibrations(distance: str) -> list[str]:
  """The files shipped for ``distance`` (every size and camera error), those
  present only."""
  own = [shipped_calibration(distance, size) for size in SIZES]
  own += [p for base in own for p in carried_errors.camera_paths(base)]
  return [p for p in own if os.path.isfile(p)]


def calibration_file(config=None, mode: str | None = None) -> str:
  """The calibration an estimate with ``config`` quotes: its own
  (``config.scoring.calibration``), else of those shipped for its distance the
  one whose settings differ from it least (then whose readings' range holds
  its readings, then one with tables of its ``mode``, then one of a user's rig's recordings where its error came from
  the intake, then the one whose recordings' camera errors were most like
  its own: ``carried_errors.recordings_gap``), else (none shipped
  for it) the default one, whose note then names what differs."""
  scoring = getattr(config, 'scoring', None)
  if given := getattr(scoring, 'calibration', ''):
    return given
  own = shipped_calibrations(getattr(scoring, 'distance', ''))
  if not own:
    return CALIBRATION_FILE
  if config is None or len(own) == 1:
    return own[0]
  flat = config.flat()
  mine, source = carried_errors.camera_of(flat), carried_errors.source_of(flat)
  return min(own, key=lambda p: (
    len(differing_fields(config, cal := read_calibration(p))),
    _lacks(cal, mode),  # no tables of this estimate's mode
    len(_reading_gaps(config, cal)),
    carried_errors.table_source(cal) != source,  # displaced as this error errs
    carried_errors.table_recordings(cal) != 'rig',  # taken in as a user's are
    carried_errors.recordings_gap(carried_errors.table_of(cal), mine),
  ))  # fmt: skip


def _lacks(cal: dict, mode: str | None) -> bool:
  """Whether calibration ``cal`` has tables but none of ``mode``."""
  rec = cal.get('recalibration')
  return bool(mode and rec and 'modes' in rec and mode not in rec['modes'])


def _reading_gaps(config, cal: dict) -> list[str]:
  """The readings of ``config``'s single-recording mode that calibration
  ``cal``'s tables were not drawn over (``carried_errors.reading_differences``;
  none where it has no tables or the readings no mode)."""
  rec, measured = cal.get('recalibration'), getattr(config, 'measured', None)
  mode = calibration_mode(measured) if rec and measured is not None else None
  if mode is None:
    return []
  return carried_errors.reading_differences(measured, rec, mode)


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, mtime_ns: int, size: int) -> dict:
  with open(path) as f:
    return json.load(f)


def still_valid_checks(
  old: dict, new: dict, key: str = 'checks'
) -> tuple[list[dict], list[dict]]:
  """The checks of calibration ``old`` that hold for ``new`` too (same
  setting and likelihood, and for every mode a check covers the same tables:
  CDF levels and weights), and those that do not: a refit that only adds
  modes keeps its checks, one that moves any table must be checked again.
  ``key``: ``'fabric_checks'`` for the per-fabric pools (``record_fabric_checks``)."""
  same_setting = all(
    old.get(k) == new.get(k) for k in ('setting', 'likelihood', 'sharpness')
  )
  keep, drop = [], []
  for c in old.get(key, []):
    ok = same_setting and all(_same_tables(old, new, m) for m in c.get('coverage', {}))
    (keep if ok else drop).append(c)
  return keep, drop


def _same_tables(old: dict, new: dict, mode: str) -> bool:
  """Whether calibrations ``old`` and ``new`` read ``mode`` with the same
  tables (CDF levels and weights)."""

  def tables(cal):
    rec = cal.get('recalibration') or {}
    return (rec.get('modes', {}).get(mode), rec.get('weights', {}).get(mode))

  return tables(old) == tables(new)


# What a bending-length mode's tables depend on beyond the mode's own
# entries: the readings its recordings were given (``recalibration``'s keys).
_LENGTH_KEYS = ('length_sd', 'length_sd_spread', 'length_sd_range', 'length_dof')


def with_modes_of(old: dict, new: dict, modes: tuple[str, ...]) -> dict:
  """Calibration ``old`` with ``modes``' tables (levels, weights, held-out
  coverage, and the readings those modes simulate) taken from ``new``, a
  refit of the same setting: one mode fitted again, e.g. after its simulated
  readings changed, leaves every other mode's tables, and their checks
  (``still_valid_checks``), as they were. The modes refitted are named in
  ``recalibration.refitted``.

  Raises:
    ValueError: another setting or likelihood, or a mode ``new`` lacks.
  """
  for k in ('setting', 'likelihood', 'sharpness'):
    if old.get(k) != new.get(k):
      raise ValueError(
        f'the refit has another {k} ({new.get(k)!r}; the shipped file: {old.get(k)!r}): '
        'install it whole'
      )
  rec_new = new.get('recalibration') or {}
  missing = [m for m in modes if m not in rec_new.get('modes', {})]
  if missing:
    raise ValueError(f'the refit has no tables for {missing}')
  out = json.loads(json.dumps(old))  # a deep copy
  rec = out['recalibration']
  for m in modes:
    rec['modes'][m] = rec_new['modes'][m]
    rec.setdefault('weights', {})[m] = rec_new.get('weights', {}).get(m, {})
    for part in ('held_out', 'held_out_uncalibrated'):
      if m in new.get(part, {}):
        out.setdefault(part, {})[m] = new[part][m]
    for k in _LENGTH_KEYS if 'bending_length' in carried_errors.readings_of(m) else ():
      if k in rec_new:
        rec[k] = rec_new[k]
  rec['refitted'] = sorted(set(rec.get('refitted', [])) | set(modes))
  return out


def trimmed_checks(
  old: dict, new: dict, key: str = 'checks'
) -> tuple[list[dict], list[str]]:
  """The checks of calibration ``old`` with the coverage of every mode whose
  tables ``new`` changed taken out (a check left with none is dropped), and
  those modes: ``calibrate --install --install_modes`` keeps what a check
  measured of the tables it did not refit, for ``--check --install_modes``
  to add the refitted modes' coverage back. ``key`` as ``still_valid_checks``'s."""
  out, moved = [], set()
  for c in old.get(key, []):
    cov = {m: v for m, v in c.get('coverage', {}).items() if _same_tables(old, new, m)}
    moved |= set(c.get('coverage', {})) - set(cov)
    if cov:
      out.append({**c, 'coverage': cov})
  return out, sorted(moved)


def record_check(path: str, check: dict, modes: tuple[str, ...] = ()) -> dict:
  """Keeps ``check`` (``calibration_check.check_record``: the calibration's tables
  on recordings they never saw) in the calibration file at ``path``, where
  every estimate that applies those tables quotes it; a check of the same
  physics, seed and searches (steered by the same reading) is replaced.
  With ``modes``, only those modes' coverage replaces the same check's
  (``calibrate --install_modes``: the modes refitted; the others' tables, and
  what the earlier check measured of them, are as they were), and the
  record names them (``rechecked``). Written whole (temporary file, then
  rename).

  Raises:
    ValueError: the check was of another calibration (its setting differs);
      with ``modes``, no earlier check of the same recordings to add them
      to, or a mode the check did not read.
  """
  cal = physsim.dataset.read_json(path)
  if check.get('setting') != cal.get('setting'):
    raise ValueError(
      f'{path}: the check was of {check.get("setting")!r}, this file holds '
      f'{cal.get("setting")!r}'
    )
  key = lambda c: (c['physics'], c['seed'], c.get('searched', 'video'))
  same = lambda c: key(c) == key(check)
  if modes:
    earlier = [c for c in cal.get('checks', []) if same(c) and c['n'] == check['n']]
    missing = [m for m in modes if m not in check['coverage']]
    if not earlier or missing:
      raise ValueError(
        f'{path}: ' + (f'the check did not read {missing}' if missing else
        f'no earlier check of these {check["n"]} recordings ({", ".join(map(str, key(check)))}) '
        'to add modes to: record the whole check')
      )  # fmt: skip
    merged = json.loads(json.dumps(earlier[0]))
    for m in modes:
      merged['coverage'][m] = check['coverage'][m]
    merged['rechecked'] = sorted(set(merged.get('rechecked', [])) | set(modes))
    check = merged
  cal['checks'] = [c for c in cal.get('checks', []) if not same(c)] + [check]
  files.write_json(path, cal)
  return cal


def record_fabric_checks(path: str, pooled: dict, mode: str = 'video') -> dict:
  """Keeps a pool of checks' coverage fabric by fabric
  (``benchmarks.pooled_check``'s ``checks``: ``mode``'s ``by_material``,
  counts added over several seeds) in the calibration file at ``path``,
  where an estimate of one of those fabrics in ``mode`` quotes its own
  fabric's beside the pooled checks (``quoted_checks``). One seed's 8
  recordings of a fabric say little; four seeds' 32 can show a fabric whose
  intervals hold less often than the rest's. The pool must be of the very
  checks the file keeps of that physics in that mode (the same seeds and
  recordings), so that the two numbers an estimate prints are of one set of
  recordings; a pool of the same physics and mode is replaced. Written whole
  (temporary file, then rename).

  Raises:
    ValueError: the pool was of another calibration, has no ``mode`` by
      fabric, or its seeds or recordings are not the file's checks'.
  """
  cal = physsim.dataset.read_json(path)
  if pooled.get('calibration') != cal.get('setting'):
    raise ValueError(
      f'{path}: the pool was of {pooled.get("calibration")!r}, this file holds '
      f'{cal.get("setting")!r}'
    )
  by = pooled.get('modes', {}).get(mode, {}).get('by_material')
  if not by:
    raise ValueError(f'{path}: the pool has no {mode!r} coverage by fabric')
  physics = pooled['physics']
  mine = [c for c in cal.get('checks', [])
          if c['physics'] == physics and c.get('searched', 'video') == mode
          and mode in c['coverage']]  # fmt: skip
  theirs = (sorted(c['seed'] for c in mine), sum(c['n'] for c in mine))
  if theirs != (sorted(pooled['seeds']), pooled['n']):
    raise ValueError(
      f'{path}: the pool is of seeds {sorted(pooled["seeds"])} ({pooled["n"]} '
      f'recordings), the file keeps checks of {physics} physics searched in {mode!r} '
      f'of seeds {theirs[0]} ({theirs[1]}): record those checks first'
    )
  cells = {
    m: {
      'n': int(r['n']),
      **{
        q: {
          k: r[q][f'held_{lv}'][part]
          for lv in (50, 90)
          for k, part in ((f'interval_{lv}', 'held'), (f'interval_{lv}_ci', 'ci'))
        }
        for q in r
        if q != 'n'
      },
    }
    for m, r in by.items()
  }
  record = {
    'physics': physics, 'seeds': sorted(pooled['seeds']), 'n': pooled['n'],
    'searched': mode, 'setting': cal['setting'], 'coverage': {mode: cells},
  }  # fmt: skip
  same = lambda c: (c['physics'], c['searched']) == (physics, mode)
  cal['fabric_checks'] = [c for c in cal.get('fabric_checks', []) if not same(c)] + [
    record
  ]
  files.write_json(path, cal)
  return cal


def pools_of(pools: list[dict], checks: list[dict]) -> list[dict]:
  """The per-fabric pools (``record_fabric_checks``) every one of whose
  checks is among ``checks``: a pool outlives its checks in no file."""
  have = {(c['physics'], c['seed'], c.get('searched', 'video')) for c in checks}
  return [p for p in pools
          if all((p['physics'], s, p['searched']) in have for s in p['seeds'])]  # fmt: skip


def fabric_check(cal: dict, quoted: dict, mode: str, material: str) -> dict | None:
  """How often ``material``'s own intervals held among a quoted check's
  recordings (``quoted_checks``' entry ``quoted``), where the file keeps a
  pool of exactly those checks by fabric (``record_fabric_checks``):
  ``{'material', 'n', 'coverage', 'short'}``, ``short`` naming each quantity
  whose 90% intervals held the truth less often than promised beyond the
  luck of the draw (the 95% binomial interval of its coverage below 90%)."""
  recordings = lambda c: (c['physics'], c['seeds'], c['n'])
  for c in cal.get('fabric_checks', []):
    if recordings(c) != recordings(quoted):
      continue
    cells = c['coverage'].get(mode, {}).get(material)
    if cells:
      cov = {q: v for q, v in cells.items() if q != 'n'}
      short = [q for q, v in cov.items() if v['interval_90_ci'][1] < 0.9]
      return {'material': material, 'n': cells['n'], 'coverage': cov, 'short': short}
  return None


def pooled_cells(cells: list[dict], ns: list[int]) -> dict:
  """Checks' cells of one mode (``{quantity: {key: number}}``, one per check
  of ``ns[i]`` recordings) as one: each number the recordings' mean, over the
  quantities every check has (entries that are not a quantity's cells are
  left out; a coverage pooled so is the exact count over all recordings, as a
  fraction)."""
  total = sum(ns)
  return {
    f: {
      k: sum(c[f][k] * n for c, n in zip(cells, ns, strict=True)) / total
      for k, v in cells[0][f].items()
      if isinstance(v, (int, float)) and not isinstance(v, bool)
    }
    for f in cells[0]
    if isinstance(cells[0][f], dict) and all(f in c for c in cells)
  }


def quoted_checks(cal: dict, mode: str) -> list[dict]:
  """What an estimate in ``mode`` quotes of calibration ``cal``'s checks: per
  physics, the checks whose searches ran in this mode (steered by its
  reading, as this estimate's are) where there are any, else those of the
  video's searches, pooled over their seeds (``n`` added up, each coverage
  the recordings' mean): one seed's 56 recordings know a 50% coverage to
  +-7 points, four seeds' to +-3.5."""
  groups: dict[str, dict[bool, list[dict]]] = {}
  for c in cal.get('checks', []):
    if mode in c['coverage']:
      steered = c.get('searched', 'video') == mode
      groups.setdefault(c['physics'], {}).setdefault(steered, []).append(c)
  out = []
  for physics, by in groups.items():
    group = by.get(True) or by[False]
    ns = [c['n'] for c in group]
    out.append({
      'physics': physics, 'n': sum(ns), 'seeds': sorted(c['seed'] for c in group),
      'coverage': pooled_cells([c['coverage'][mode] for c in group], ns),
    })  # fmt: skip
  return out


def read_calibration(path: str) -> dict:
  """A calibration file, read once per version of it (not to be changed)."""
  st = os.stat(path)
  return _read_cached(path, st.st_mtime_ns, st.st_size)


# Estimate settings that change what a score means, or how well the search
# pins the posterior down; coverage measured with other values does not carry
# over.
_CALIBRATED_FIELDS = (
  'likelihood', 'sharpness', 'model_error', 'material', 'garment', 'cloth_resolution',
  'cloth_size', 'hem_mass', 'frames',
  'fps', 'distance', 'camera_sd_m', 'camera_sd_deg', 'warmup', 'gusts',
  'sensor_noise', 'q', 'n_init', 'max_iter', 'posterior_grid',
)  # fmt: skip


def differing_fields(config, cal: dict) -> list[str]:
  """The likelihood's settings (``_CALIBRATED_FIELDS``) in which an estimate
  with ``config`` differs from calibration ``cal``'s searches; a study of
  several fabrics (``'materials'``) holds for each of them, and one whose
  estimates carried a camera error for errors within the range its
  recordings' were drawn over, or within a factor of two of the one they all
  had (``carried_errors.covers``)."""
  calibrated = dict(cal.get('config', {}).get('estimate', {}))
  calibrated.update(
    likelihood=cal.get('likelihood', 'gibbs'), sharpness=cal['sharpness']
  )
  if 'distance' in calibrated:  # files from before the camera's error was a setting
    calibrated.setdefault('camera_sd_m', 0.0)
    calibrated.setdefault('camera_sd_deg', 0.0)
  if 'cloth_resolution' in calibrated:  # files from before the size was a setting
    calibrated.setdefault('cloth_size', 1.0)
    calibrated.setdefault('hem_mass', 0.0)  # ... or a hem could be added
  if 'sharpness' in calibrated:  # ... and before the model error was
    calibrated.setdefault('model_error', 0.0)
  mine = {'hem_mass': 0.0, **config.flat()}  # flat() leaves out no hem
  if 'materials' in cal:
    calibrated['material'] = (
      mine['material'] if mine['material'] in cal['materials'] else cal['materials']
    )
  spread = carried_errors.table_of(cal)[2]
  differs = [n for n in _CALIBRATED_FIELDS if n in calibrated and not (
    carried_errors.covers(float(calibrated[n]), float(mine[n]), spread)
    if n in carried_errors.CAMERA_FIELDS else _same(mine[n], calibrated[n])
  )]  # fmt: skip
  source = carried_errors.table_source(cal)
  if not carried_errors.source_holds(source, carried_errors.source_of(mine)):
    differs.append('camera_sd_from')
  return differs


def _camera_worded(config, cal: dict, names: list[str]) -> list[str]:
  """``differing_fields``' ``names``, the camera error's as one entry in
  words: the error ``config`` carries and those that ``cal`` and the tables
  shipped for its distance were measured at; a camera error that did not
  come from the intake, against tables of the intake's own errors, in words
  too."""
  if 'camera_sd_from' in names:
    names = [n for n in names if n != 'camera_sd_from'] + [
      'camera error given (these tables displaced cameras as the intake errs '
      'against its own claim, and hold for its claims alone)'
    ]
  if not set(names) & set(carried_errors.CAMERA_FIELDS):
    return names
  shipped = shipped_calibrations(config.scoring.distance)
  levels = [carried_errors.table_of(c) for c in (cal, *map(read_calibration, shipped))]
  mine = carried_errors.camera_of(config.flat())
  return [n for n in names if n not in carried_errors.CAMERA_FIELDS] + [
    carried_errors.camera_difference(mine, levels)
  ]


def calibration_mode(measured, joint: bool = False) -> str | None:
  """The calibration study's mode (``experiments.studies.calibration.MODES``)
  an estimate with these readings falls in: the video alone, with a measured
  wind, with a measured area weight, with a bending length read from an
  overhang (and a measured wind), a joint pair, or a joint pair with a wind
  reading at each recording (``measured`` is then one recording's); None
  where none fits (an area weight with another reading, a joint estimate with
  an area weight or a bending length)."""
  wind, weight = measured.wind_speed_sd > 0, measured.area_weight_sd > 0
  length = getattr(measured, 'bending_length_sd', 0.0) > 0
  if joint:
    return (
      None if weight or length else 'joint pair, known winds' if wind else 'joint pair'
    )
  if weight and (wind or length):
    return None
  if length:
    # a depth camera's reading (its t law) or a ruler's (Gaussian)
    ruler = '' if getattr(measured, 'bending_length_dof', 0.0) else ' (ruler)'
    return ('known wind, bending length' if wind else 'bending length') + ruler
  return 'known wind' if wind else 'known area weight' if weight else 'video'


def _same(mine, theirs) -> bool:
  if isinstance(mine, float):
    return bool(np.isclose(mine, theirs))
  if isinstance(mine, tuple):
    return tuple(mine) == tuple(theirs)
  return mine == type(mine)(theirs)


def calibration_note(config=None, *, joint: bool = False, recordings: int = 1,
                     network: dict | None = None, accuracy: float | None = None,
                     uncalibrated: tuple[str, ...] = ()):  # fmt: skip
  """What the held-out simulations showed about the intervals, for an
  estimate with ``config`` (``calibration_file``); None when no calibration
  has been run.

  Where every setting that changes the likelihood (``_CALIBRATED_FIELDS``),
  the mode (what was measured, a reading's uncertainty within a factor of two
  of the calibrated one, a joint estimate of two recordings) and the
  network's recipe (``network``: ``embedding.network_recipe`` of the
  estimate's network; the calibration's networks were all made so) match,
  the note carries the mode's recalibrated CDF levels (``'levels'``, which
  the estimate applies) and the coverage they had on recordings held out
  from them; else it says what differs (``'matches': False``). A network of
  the recipe whose held-out triplet accuracy (``accuracy``) is below every
  calibration network's is noted (``'weaker_network'``): how often a weaker
  network's intervals hold the truth was not measured, and the two weakest
  checked so far held it less often. ``uncalibrated``: what the caller
  knows no calibration measured (recordings sharing a fan setting), each
  named among the differences.
  """
  mode = None if config is None else calibration_mode(config.measured, joint)
  path = calibration_file(config, mode)
  if not os.path.isfile(path):
    return None
  cal = read_calibration(path)
  head = {k: cal[k] for k in ('n', 'setting', 'likelihood', 'sharpness') if k in cal}
  head['networks'] = len(cal.get('network', {}).get('seeds', [0]))
  if config is None:
    return {'matches': True, **head, 'coverage': cal['coverage']}
  differs = _differences(config, cal, mode, joint, recordings, network, uncalibrated)
  if differs:
    return {'matches': False, 'differs': differs, **head}
  rec = cal.get('recalibration')
  if not rec or mode not in rec['modes']:  # a calibration without tables
    return {'matches': True, **head, 'coverage': cal['coverage']}
  return _recalibrated(cal, head, mode, config.simulation.material, accuracy)


def _differences(config, cal: dict, mode: str | None, joint: bool, recordings: int,
                 network: dict | None, uncalibrated: tuple[str, ...]) -> list[str]:  # fmt: skip
  """What keeps calibration ``cal``'s tables from an estimate with ``config``
  in ``mode`` (``calibration_note``'s arguments), each in words; empty where
  they apply."""
  differs = _camera_worded(config, cal, differing_fields(config, cal))
  differs += list(uncalibrated)
  if getattr(config.measured, 'air_free', False):
    differs.append("air coefficient free (the tables hold it at ArcSim's 1)")
  if joint and recordings != 2:
    differs.append(f'joint estimate of {recordings} recordings (calibrated: 2)')
  elif mode is None:
    differs.append(
      'bending-length reading in a joint estimate (not calibrated)'
      if config.measured.bending_length_sd > 0 and joint
      else 'combination of measurements'
    )
  theirs = cal.get('network', {}).get('recipe')
  if network is not None and theirs is not None:
    d = embedding.recipe_differences(network, theirs)
    if d:
      differs.append(f'network recipe ({", ".join(d)})')
  rec = cal.get('recalibration')
  if rec and mode is not None and mode not in rec['modes']:
    differs.append(f'{mode} (not in this calibration)')
  if rec:
    differs += carried_errors.reading_differences(config.measured, rec, mode)
  return differs


def _weaker_network(cal: dict, accuracy: float | None) -> dict | None:
  """``accuracy`` and the calibration networks' range where the estimate's
  network is weaker than every one of them (its coverage was not measured);
  else None."""
  calibrated_acc = [a for a in cal.get('network', {}).get('triplet_accuracy', [])
                    if a is not None]  # fmt: skip
  return (
    {'accuracy': accuracy, 'calibrated': [min(calibrated_acc), max(calibrated_acc)]}
    if accuracy is not None and calibrated_acc and accuracy < min(calibrated_acc)
    else None
  )


def _recalibrated(cal: dict, head: dict, mode: str, material: str,
                  accuracy: float | None) -> dict:  # fmt: skip
  """The note of an estimate the tables of ``mode`` cover: its recalibrated
  levels and weights, the coverage they had held out, the readings they
  were drawn with, and the checks on other physics (with ``material``'s own)."""
  rec = cal['recalibration']
  held = cal['held_out'][mode]
  levels = np.asarray(rec['modes'][mode])  # (len(PROBS), fields)
  weaker = _weaker_network(cal, accuracy)
  checks = quoted_checks(cal, mode)
  for c in checks:
    if mine := fabric_check(cal, c, mode, material):
      c['this_fabric'] = mine
  return {
    'matches': True, **head, 'mode': mode, 'recalibrated': True,
    **({'weaker_network': weaker} if weaker else {}),
    **({'checks': checks} if checks else {}),
    'n_calibration_recordings': rec['n_calibration_recordings'],
    # the readings its recordings were given, simulated to this relative error
    'readings': {
      name: carried_errors.pct_range(rec, name)
      for name in carried_errors.readings_of(mode)
    },
    'levels': {f: levels[:, i].tolist() for i, f in enumerate(rec['fields'])},
    'weights': rec.get('weights', {}).get(mode, {}),
    'coverage': {
      f: {k: held[f][k] for k in ('interval_50', 'interval_90')} for f in rec['fields']
    },
  }  # fmt: skip
