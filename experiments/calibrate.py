r"""Simulation-based calibration of the estimate's credible intervals.

  python -m experiments.calibrate --workdir=out/calibration            # GPU: 200 recordings
  python -m experiments.calibrate --workdir=/tmp/cal --preset=smoke    # CPU, minutes
  python -m experiments.calibrate --workdir=out/cal_paper --preset=paper  # GPU: every
      # fabric at the estimate's own size, shape distance, one lockstep
  python -m experiments.calibrate --workdir=out/calibration --install  # ship its coverage
      # (the shipped file's checks are kept where their modes' tables did not change)
  python -m experiments.calibrate --workdir=out/calibration --analyse_only  # no simulation
  python -m experiments.calibrate --workdir=out/calibration --analyse_only --install \
      --install_modes='bending length;known wind, bending length'  # those modes'
      # tables only: the others, and their checks, stay as shipped
  python -m experiments.calibrate --workdir=/tmp/cal --simulate_only   # GPU; then copy
      # /tmp/cal/packed/ to out/calibration/packed/ and --analyse_only there
  python -m experiments.calibrate --workdir=out/check --check --seed=1 \
      --pairs=30 --network_seed=5 --networks=2  # the shipped tables on new
                                          # recordings and networks it never saw
  python -m experiments.calibrate --workdir=out/check_mm --check --preset=paper \
      --physics=mismatched --seed=1 --pairs=4 --install  # GPU: the paper tables
      # on recordings of another physics, recorded where estimates quote it
  python -m experiments.calibrate --workdir=out/cal_cam4 --preset=paper \
      --camera_sd_m=0.04 --camera_sd_deg=3 --install  # GPU: tables for
      # estimates that carry the intake's alignment error (4 cm / 3 deg, 1 sd)
  python -m experiments.calibrate --workdir=out/cal_camr --preset=paper \
      --camera_sd_m=0.03 --camera_sd_deg=2.5 --camera_sd_spread=1.25 --install
      # GPU: each recording its own error, 0.86-10.5 cm / 0.72-8.7 deg: the
      # intake's range in one set of tables
  python -m experiments.calibrate --workdir=out/cal_cami --preset=paper --pairs=5 \
      --camera_errors=benchmarks/results/alignment_error/claim_default.json,\
benchmarks/results/alignment_error/claim_mismatched.json --physics=mismatched \
      --centred_levels --install
      # GPU: each recording of another physics, its camera off as a measured
      # intake erred, its estimate carrying that intake's claim; the tables
      # correct the width alone: the shipped tables of the intake's own claims
  python -m experiments.calibrate --preset=paper --physics=mismatched \
      --centred_levels --rig_runs='out/rig_tables/s*' --workdir=out/cal_rig --install
      # no simulation: tables fitted on a user's rig's recordings taken in
      # through the intake (benchmarks.windy_rig --pairs), shipped as
      # ..._camera_intake_rig_...json, which an intake's estimate quotes first

What it measures: ``experiments.studies.calibration``. With ``--install`` the
held-out coverage is copied into the package (``experiments/pipeline/
calibration.json``), where every estimate's report quotes it. With
``--check`` nothing is fitted: new recordings (another seed) are estimated
with the estimate's defaults and the shipped tables (``--network_seed``:
with another network too), and the study reports
how often their intervals held the truth (``calibration_check.check``).
With ``--camera_sd_m`` / ``--camera_sd_deg`` the estimates carry a camera
error, as an estimate of a user's recording carries the intake's alignment
error, and each recording's camera is displaced from the pose its estimate
is told by an error of that size (``calibration_config.told_pose``);
``--install`` ships such tables beside the exact cameras' own
(``carried_errors.camera_path``), where estimates carrying an error within a
factor of two of theirs quote them; with ``--camera_sd_spread`` each
recording carries its own error, drawn over a range about that one, and the
tables hold anywhere in the range. With ``--camera_errors`` (the intake's
measured errors, ``benchmarks.alignment_error``) each recording's camera is
off as one measured intake actually erred and its estimate carries that
intake's claim; ``--install`` ships them as ``..._camera_intake_...json``,
where only estimates carrying the intake's own claim quote them
(``Scoring.camera_sd_from``). Those shipped were measured on recordings of
another physics and checked through the intake on a third
(docs/studies/calibration.md). With ``--centred_levels`` the tables correct
the intervals' width only (``bo.calibration.centred_levels``): tables of
one mismatch otherwise move every estimate's point by that mismatch's bias.
"""

from __future__ import annotations

import dataclasses
import os
import shutil

from absl import logging

import bo
import physsim
from experiments.pipeline import calibration_tables, cli, distributed, files
from experiments.studies import calibration, calibration_check, calibration_rig


@dataclasses.dataclass(frozen=True)
class Args:
  """The calibration study from the command line.

  Attributes:
    workdir: network, recordings, estimates and results (resumed).
    install: copy the held-out coverage into the package, where estimates
      quote it (the checks the file held are kept where the tables of every
      mode they checked are unchanged, else dropped and named); with ``--check``, record the check (the workdir's
      ``check.json``: made now, or by an earlier check with
      ``--analyse_only``) in the calibration file it checked, where estimates
      quote it beside the calibration's own coverage.
    install_modes: with ``--install``, the modes (``calibration.MODES``,
      separated by ';') whose tables to install; the file's other tables and
      the checks of them stay ('': install the whole refit). With
      ``--check``: the modes whose coverage to record into the file's
      earlier check of the same recordings (the others keep what it
      measured of their unchanged tables).
    analyse_only: analyse the estimates the workdir holds (or those packed
      in its ``packed/``), simulating nothing (e.g. searches run on a GPU
      machine, analysis elsewhere).
    simulate_only: make the networks, recordings and estimates, and pack
      what the analysis reads into ``<workdir>/packed/`` (a few files):
      copy that folder to analyse elsewhere with ``--analyse_only``.
    check: check the shipped calibration on new recordings (``--seed``
      other than its own) instead of calibrating; nothing is fitted.
    study: what is simulated and estimated.
  """

  workdir: str = 'out/calibration'
  install: bool = False
  install_modes: str = ''
  analyse_only: bool = False
  simulate_only: bool = False
  check: bool = False
  study: calibration.Config = calibration.Config()


PRESETS = {k: Args(study=v) for k, v in calibration.PRESETS.items()}


def resolved(args: Args) -> Args:
  """``args`` with the study's camera errors set from the intakes' files or
  the rig's recordings (``with_intake_errors``, ``with_rig_runs``).

  Raises:
    ValueError: a likelihood the calibration cannot re-read, or the rig's
      recordings beside a check or measured intake errors.
  """
  args = dataclasses.replace(args, study=calibration.with_intake_errors(args.study))
  if args.study.estimate.scoring.likelihood not in bo.posterior.DISCREPANCY_LIKELIHOODS:
    raise ValueError(
      f'--likelihood={args.study.estimate.scoring.likelihood}: the calibration re-reads '
      f'likelihoods of one discrepancy ({", ".join(bo.posterior.DISCREPANCY_LIKELIHOODS)})'
    )
  if not args.study.rig_runs:
    return args
  if args.check or args.study.camera_errors:
    raise ValueError(
      '--rig_runs fits tables on their own claims: drop --check and --camera_errors'
    )
  runs = calibration_rig.rig_runs(args.study.rig_runs)
  return dataclasses.replace(
    args, study=calibration_rig.with_rig_runs(args.study, runs)
  )


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  args = resolved(args)
  modes = tuple(m.strip() for m in args.install_modes.split(';') if m.strip())
  unknown = [m for m in modes if m not in calibration.MODES]
  if unknown or (modes and not args.install):
    raise ValueError(
      f'--install_modes={args.install_modes!r}: '
      + (
        f'no mode {unknown}; one or more of {list(calibration.MODES)}, separated by ";"'
        if unknown
        else "installs a refit's tables (or a check of them): give it with --install"
      )
    )
  if args.check:
    if args.simulate_only:
      raise ValueError('--check analyses what it simulates: drop --simulate_only')
    done = os.path.join(args.workdir, calibration_check.CHECK_FILE)
    if not (args.install and args.analyse_only and os.path.isfile(done)):
      calibration_check.check(args.study, args.workdir, analyse_only=args.analyse_only)
    if args.install and distributed.is_main():
      dest = calibration_check.checked_file(args.study)
      calibration_tables.record_check(
        dest, calibration_check.check_record(physsim.dataset.read_json(done)), modes
      )
      print(f'check recorded in {dest}')
    return
  calibration.run(
    args.study, args.workdir, analyse_only=args.analyse_only,
    simulate_only=args.simulate_only,
  )  # fmt: skip
  if args.install and distributed.is_main():
    scoring = args.study.estimate.scoring
    dest = calibration_tables.shipped_calibration(
      scoring.distance, args.study.size, (scoring.camera_sd_m, scoring.camera_sd_deg),
      args.study.camera_sd_spread, scoring.camera_sd_from,
      'rig' if args.study.rig_runs else '',
    )  # fmt: skip
    src = f'{args.workdir}/{calibration.RESULT_FILE}'
    new = physsim.dataset.read_json(src)
    old = physsim.dataset.read_json(dest) if os.path.isfile(dest) else {}
    if modes:  # those modes' tables; what the checks measured of the others
      if not old:
        raise ValueError(f'--install_modes: no file at {dest} to install them into')
      new = calibration_tables.with_modes_of(old, new, modes)
      (keep, moved), drop = calibration_tables.trimmed_checks(old, new), []
      fabrics = calibration_tables.trimmed_checks(old, new, 'fabric_checks')[0]
      if moved:
        print(f'the checks keep their other modes; check {", ".join(moved)} again '
              '(--check ... --install --install_modes=...)')  # fmt: skip
    else:
      keep, drop = calibration_tables.still_valid_checks(old, new)
      fabrics = calibration_tables.still_valid_checks(old, new, 'fabric_checks')[0]
    if keep or modes:  # checks of tables this refit left as they were
      new['checks'] = keep
      new.pop('fabric_checks', None)
      if pools := calibration_tables.pools_of(
        fabrics, keep
      ):  # by fabric, of checks kept
        new['fabric_checks'] = pools
      files.write_json(dest, new)
    else:
      files.write_atomic(
        dest, lambda tmp: shutil.copyfile(src, tmp)
      )  # never half-copied
    print(f'installed as {dest}')
    for c in keep:
      print(f'  kept the check on {c["n"]} recordings of {c["physics"]} physics '
            f'(seed {c["seed"]}, searched {c.get("searched", "video")}): '
            + ('its modes of the tables left as they were' if modes
               else 'its tables are unchanged'))  # fmt: skip
    for c in drop:
      print(f'  dropped the check on {c["n"]} recordings of {c["physics"]} physics '
            f'(seed {c["seed"]}, searched {c.get("searched", "video")}): its tables '
            'changed; check them again (--check ... --install)')  # fmt: skip


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
