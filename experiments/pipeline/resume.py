"""What lets a search resume, and only its own: the workdir's ``run.json``.

A search's state file (``bo_state.npz``, ``posterior_state.npz``) knows only
the optimiser's settings, so ``check_run`` writes beside it what defines the
run (the settings that change what is searched, digests of the recording and
the camera, the network's folders) and refuses a workdir that holds another
run. A search that had finished before keeps the result it wrote, unless the
calibration it quoted has changed since (``earlier_result``).
"""

from __future__ import annotations

import hashlib
import json
import os

import numpy as np

from experiments.pipeline import embedding, files, layout
from experiments.pipeline.recording import read_json
from experiments.pipeline.searcher import Job

# Config fields that do not change what an estimate searches (the shared
# discrepancy: only how the joint reads the searches; where the camera error
# came from: only which tables hold).
_RESUMABLE_FIELDS = ('workers', 'calibration', 'shared_bias', 'camera_sd_from')  # fmt: skip


def _digest(a) -> str:
  return hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()


def check_run(job: Job, problem) -> None:
  """Writes what defines the run; refuses a workdir holding another run.

  ``bo_state.npz`` alone only knows the optimiser's settings, so without this
  a rerun with another recording, camera, model or material would silently
  continue the old search.
  """
  workdir, config, recording = job.workdir, job.config, job.recording
  d = problem.data
  runs = embedding.members(job.model_dir) if job.model_dir else []  # none: shape
  run = {
    'config': {k: v for k, v in config.flat().items() if k not in _RESUMABLE_FIELDS},
    'recording_sha1': _digest(np.asarray(recording.depth, np.float32)),
    'camera': {
      'intrinsics': problem.intr.to_dict(),
      'poses_sha1': _digest(np.asarray(d.poses.rotation, np.float32))
      + _digest(np.asarray(d.poses.position, np.float32)),
    },
    'model_dir': ','.join(os.path.abspath(d) for d in runs),
  }
  if recording.rgb is not None and problem.net.modality == 'rgb':
    run['recording_rgb_sha1'] = _digest(recording.rgb)
  run = json.loads(json.dumps(run))  # tuples -> lists, as read back
  path = os.path.join(workdir, layout.RUN_FILE)
  if os.path.exists(path):
    old = read_json(path)
    diff = sorted(
      k for k in set(run) | set(old) if k != 'config' and run.get(k) != old.get(k)
    )
    diff += sorted(
      f'config.{k}'
      for k in set(run['config']) | set(old.get('config', {}))
      if run['config'].get(k) != old.get('config', {}).get(k)
    )
    if diff:
      raise ValueError(
        f'{path}: the workdir holds an estimate with different {diff}; use a '
        'new workdir'
      )
    return
  files.write_json(path, run)


def earlier_result(job: Job) -> dict | None:
  """The ``estimate.json`` of a search in ``job.workdir`` that had finished
  before (its ``run.json`` matched: ``check_run``), which stands; None where
  it has none (it stopped before writing it: its files are written again) or
  where it quoted another calibration than its settings do now (tables
  installed or changed since: its intervals are read again at the new
  tables' levels from the search it kept)."""
  path = os.path.join(job.workdir, layout.ESTIMATE_FILE)
  if not os.path.isfile(path):
    return None
  result = read_json(path)
  if 'calibration' in result and job.setup is not None:
    now = json.loads(json.dumps(job.setup.calibration))
    if result['calibration'] != now:
      return None
  return result
