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

An estimate of a user's recording carries the intake's alignment error
(``camera_sd_m`` / ``camera_sd_deg``: the camera placed in the simulator's
world to a few centimetres and degrees). A study whose estimates carry one
(``--camera_sd_m``, ``--camera_sd_deg``) tells each recording's estimate a
camera displaced from the true one by an error of that size
(``calibration_config.told_pose``: each recording its own, from the study's
seed), so its tables hold for estimates that carry such an error within a
factor of two (``carried_errors.covers``).

A network is one draw of its recipe: another seed trains another network,
whose distances are scaled and bent differently. So the study trains
``networks`` networks with the demo's recipe (seeds ``network_seed``,
``network_seed + 1``, ...) and estimates pair ``p`` with network
``p % networks``; the tables then hold for the recipe, not for one network.
With ``folds == networks`` each fold is one network's recordings, and the
cross-fitted coverage is that of a network the tables never saw.
``calibration.json`` records the recipe (``embedding.network_recipe``), and an
estimate applies the tables only with a network of that recipe. A distance
that embeds nothing (``estimate.distance='shape'``) needs no network: the
study then trains none, estimates every recording from its depth frames
alone, and its tables hold for that distance (``calibration_tables.calibration_file``).

The study then calibrates the intervals themselves: per mode and quantity,
the truths' ranks among the posterior draws give the CDF levels at which the
posterior must be read for its 50% and 90% intervals (and its median) to hold
the truth as often as they say (``bo.calibration``). The likelihood's one
constant (``sharpness``) is chosen as the value whose recalibrated intervals
score best (Gneiting & Raftery's interval score: narrow, but holding the
truth); every recording's posterior is formed again from its saved GP for
each candidate value, without new simulations (the searches ran with the
default value, which only steers where they simulated). The tables shipped
use every recording; the coverage reported is cross-fitted over ``folds``
folds of pairs, so each recording is read with a sharpness and tables chosen
without it.
``experiments/calibrate.py`` is its command line; ``--install`` ships the
tables with the package, where estimates with the calibrated settings apply
them. The shipped tables on recordings they never saw, nothing fitted:
``calibration_check``.

The study's parts, one concept each: its design (``calibration_config``), its
runs (``calibration_runs``: networks, recordings, estimates, packed runs),
each recording's scores (``calibration_scores``), the analysis
(``calibration_analysis``) and the report (``calibration_report``).
"""

from __future__ import annotations

import os
import time

from experiments.pipeline import distributed, files
from experiments.studies import calibration_analysis as _analysis
from experiments.studies import calibration_report as _report
from experiments.studies import calibration_rig
from experiments.studies import calibration_runs as _runs
from experiments.studies import calibration_scores as _scores
from experiments.studies.calibration_analysis import (
  analyse,
  coverage_of,
  recalibration,
  summarise,
)
from experiments.studies.calibration_config import (
  FIELDS,
  LENGTH_MODES,
  LEVELS,
  MODE_OF_READING,
  MODES,
  NETWORKS_FILE,
  PRESETS,
  RESULT_FILE,
  Config,
  camera_sd_of,
  check_config,
  first_seq,
  fold_of,
  length_sd_of,
  length_sd_range,
  network_dirs,
  network_of,
  network_seeds,
  study_configs,
  study_materials,
  told_pose,
  truths,
  uses_networks,
  with_intake_errors,
  with_reading,
)
from experiments.studies.calibration_report import plot_ranks, plot_sweep, result, table
from experiments.studies.calibration_runs import (
  PACKED_DIR,
  networks_record,
  pack_runs,
  packed_runs,
  recorded_networks,
  saved_runs,
  simulate_and_estimate,
)
from experiments.studies.calibration_scores import posteriors

# The study's API, importable from here as before the split.
__all__ = [
  'FIELDS', 'LENGTH_MODES', 'LEVELS', 'MODE_OF_READING', 'MODES', 'NETWORKS_FILE',
  'PACKED_DIR', 'PRESETS', 'RESULT_FILE', 'Config', 'analyse', 'camera_sd_of',
  'check_config',
  'coverage_of', 'first_seq', 'fold_of', 'length_sd_of', 'length_sd_range',
  'network_dirs', 'network_of', 'network_seeds', 'networks_record', 'pack_runs',
  'packed_runs', 'plot_ranks', 'plot_sweep', 'posteriors', 'recalibration',
  'recorded_networks', 'result', 'run', 'saved_runs', 'simulate_and_estimate',
  'with_intake_errors',
  'study_configs', 'study_materials', 'summarise', 'table', 'told_pose', 'truths',
  'uses_networks', 'with_reading',
]  # fmt: skip
# Parts the study's tests reach by their old names.
_QGRID = _scores.QGRID
_saved = _runs.saved_gp
_physical_with_ratio = _scores.physical_with_ratio
_confident_misses = _analysis.confident_misses
_network_lines = _report.network_lines


def run(config: Config, workdir: str, analyse_only: bool = False,
        simulate_only: bool = False) -> dict:  # fmt: skip
  """The whole study (or, with ``analyse_only``, its analysis of the
  estimates ``workdir`` already holds; with ``simulate_only``, the networks,
  recordings and estimates, packed for an analysis elsewhere: ``pack_runs``);
  writes ``calibration.json``, ``calibration.md`` and figures."""
  if analyse_only and simulate_only:
    raise ValueError('analyse_only and simulate_only leave nothing to do')
  if config.rig_runs and simulate_only:
    raise ValueError('--rig_runs reads estimates made already: drop --simulate_only')
  check_config(config)
  t0 = time.time()
  os.makedirs(workdir, exist_ok=True)
  if config.rig_runs:  # a user's rig's recordings, estimated already
    runs = calibration_rig.rig_runs(config.rig_runs)
  elif analyse_only:
    runs = saved_runs(workdir)
  else:
    runs = simulate_and_estimate(config, workdir)
  if not distributed.is_main():
    return {}
  if simulate_only:
    written = pack_runs(runs, workdir)
    print(f'{len(runs)} estimates packed in {len(written)} files under '
          f'{os.path.join(workdir, PACKED_DIR)}', flush=True)  # fmt: skip
    return {}
  analysis = analyse(config, runs)
  out = result(
    config, analysis, seconds=time.time() - t0, network=recorded_networks(workdir)
  )
  few = []
  if config.rig_runs:
    out, few = calibration_rig.shippable(out)
  files.write_json(os.path.join(workdir, RESULT_FILE), out)
  text = table(out)
  if few:
    text += (
      f'\n\nnot shipped (fewer than {calibration_rig.MIN_RECORDINGS} held out): '
      + ', '.join(few)
    )
  files.write_text(os.path.join(workdir, 'calibration.md'), text + '\n')
  plot_ranks(
    out['held_out_uncalibrated'], os.path.join(workdir, 'calibration_ranks.png')
  )
  plot_sweep(analysis, os.path.join(workdir, 'calibration_sharpness.png'))
  print(text)
  return out
