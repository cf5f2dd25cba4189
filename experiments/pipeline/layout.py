"""Where an estimate's files lie in its workdir, and reading them back.

The bottom of the estimate's stages: every stage that writes or reads a run's
files takes their names from here, so that no stage imports a later one for
a file name. ``read_draws`` reads a finished estimate's posterior draws (the
planner and the export use them) and refuses a corrupt or incomplete file,
naming it.
"""

from __future__ import annotations

import json
import os
import zipfile

import numpy as np

import physsim

RUN_FILE = 'run.json'  # what defines the run (a resume must match it)
ESTIMATE_FILE = 'estimate.json'
POSTERIOR_FILE = 'posterior.npz'  # draws and the grid posterior/likelihood
POSTERIOR_STATE = 'posterior_state.npz'  # the posterior search's resumable state
BO_STATE = 'bo_state.npz'  # the minimiser's (``point='argmin'``)
TRACE_PNG = 'trace.png'
MONTAGE_PNG = 'montage.png'
POSTERIOR_PNG = 'posterior.png'
JOINT_FILE = 'joint.json'
# The joint's shared draws, as POSTERIOR_FILE keeps one recording's (what
# experiments.plan reads): recording 0's (b, v_0, w) unit draws and the box.
JOINT_POSTERIOR_FILE = 'joint_posterior.npz'


def recording_dir(workdir: str, k: int) -> str:
  """Where recording ``k`` of a joint estimate keeps its own search."""
  return os.path.join(workdir, f'recording_{k}')


def read_json(path: str) -> dict:
  """A JSON object from ``path``; ValueError naming the file if it is not
  one (unreadable, cut short, or another type)."""
  try:
    with open(path, encoding='utf-8') as f:
      out = json.load(f)
  except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
    raise ValueError(f'{path}: not a readable JSON file ({type(e).__name__})') from e
  if not isinstance(out, dict):
    raise ValueError(f'{path}: holds a {type(out).__name__}, not a JSON object')
  return out


def _read_npz(path: str, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
  """The arrays ``keys`` of ``path``; ValueError naming the file when it is
  not an .npz, lacks one of them, or holds objects (never unpickled)."""
  try:
    with np.load(path, allow_pickle=False) as z:
      missing = [k for k in keys if k not in z.files]
      if missing:
        raise ValueError(f'{path}: incomplete, no {missing} (rerun the estimate)')
      return {k: np.asarray(z[k]) for k in keys}
  except ValueError as e:  # an object array (never unpickled), a bad header
    if str(e).startswith(path):
      raise
    raise ValueError(f'{path}: not a readable .npz ({str(e)[:80]})') from e
  except (OSError, EOFError, zipfile.BadZipFile) as e:
    raise ValueError(f'{path}: not a readable .npz ({type(e).__name__})') from e


def read_draws(workdir: str) -> tuple[str, np.ndarray, np.ndarray]:
  """An estimate's fabric, its posterior draws as (S, 2) (log bending scale,
  log area weight) and their (S,) weights (equal: the draws are samples).
  A joint estimate's workdir gives its shared draws (``JOINT_POSTERIOR_FILE``
  beside ``JOINT_FILE``): what its recordings together say of the fabric.

  Raises:
    ValueError: no ``posterior.npz`` (an argmin estimate keeps none) nor a
      joint's; a file that is corrupt, incomplete, or holds draws that are not
      (S, 3) finite values with a (3, 2) box of positive bounds (named).
  """
  path, about = os.path.join(workdir, POSTERIOR_FILE), ESTIMATE_FILE
  joint = os.path.join(workdir, JOINT_POSTERIOR_FILE)
  if not os.path.exists(path) and os.path.exists(joint):
    path, about = joint, JOINT_FILE
  if not os.path.exists(path):
    raise ValueError(
      f'{path}: no posterior draws (run the estimate with a posterior; a joint '
      f"estimate's are its {JOINT_POSTERIOR_FILE})"
    )
  z = _read_npz(path, ('samples', 'bounds'))
  samples, bounds = z['samples'], z['bounds']
  if not (samples.dtype.kind == 'f' and bounds.dtype.kind == 'f'):
    raise ValueError(f'{path}: draws and bounds must be floating point')
  if samples.ndim != 2 or samples.shape[1] != 3 or bounds.shape != (3, 2):
    raise ValueError(f'{path}: need (S, 3) draws, got {samples.shape}')
  if not len(samples) or not np.isfinite(samples).all():
    raise ValueError(f'{path}: {len(samples)} draws, some not finite (or none)')
  if not (np.isfinite(bounds).all() and (bounds > 0).all()):
    raise ValueError(f'{path}: its search box {bounds.tolist()} is not positive')
  if not (bounds[:, 0] < bounds[:, 1]).all():
    raise ValueError(f'{path}: its search box {bounds.tolist()} is empty')
  material = 'gray_interlock'
  est = os.path.join(workdir, about)
  if os.path.exists(est):
    material = read_json(est).get('material', material)
    if not isinstance(material, str) or material not in physsim.FABRICS:
      raise ValueError(f'{est}: material {str(material)[:40]!r} is no known fabric')
  space = physsim.SearchSpace(*(tuple(float(v) for v in b) for b in bounds))
  p = physsim.params.from_unit(np.clip(samples.astype(np.float64), -1, 1), space)
  draws = np.stack([np.log(p.bending_scale), np.log(p.area_weight)], axis=1)
  return material, draws, np.ones(len(draws))
