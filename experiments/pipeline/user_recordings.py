"""A user's recordings, taken in and estimated (what ``experiments.estimate`` runs).

Each recording (a ``takes.Take``: its path, camera file and own set-up) gets
its settings (the shared ones with its cloth size, hem, up axis and wind
reading), its intake where it is not one of this project's own sequences
(``intake.take_in``: clip, background, alignment), the alignment's own error
carried into its posterior, and then one estimate: ``estimation.estimate`` for a
single recording, ``estimation.estimate_joint`` for several (one bending and area
weight, one wind each). Before any intake writes, no workdir may hold another
recording's run.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import NamedTuple

from experiments.pipeline import (
  calibration_tables,
  carried_errors,
  estimation,
  files,
  intake,
  intake_files,
  intake_frames,
  intake_record,
  joint,
  layout,
  reading_floor,
  setup,
  takes,
)
from experiments.pipeline import recording as recording_lib


def take_settings(ik: intake.IntakeConfig, config, take: takes.Take):
  """(intake settings, estimate settings) of one recording: the shared ones
  with the recording's own cloth size, hem, up axis and wind reading.

  Raises:
    ValueError: settings the recording's own values make invalid (named).
  """
  if take.world_up:
    ik = dataclasses.replace(ik, world_up=take.world_up)
  if take.cloth_size:
    config = config.replace(cloth_size=take.cloth_size)
  if take.hem_mass:
    config = config.replace(hem_mass=take.hem_mass)
  if take.wind is not None:
    config = config.replace(wind_speed=take.wind[0], wind_speed_sd=take.wind[1])
  config.check()
  return ik, config


def own_settings(config) -> dict:
  """A recording's own settings in a joint estimate (``joint.PER_RECORDING``
  that its config writes: a config without a hem writes none)."""
  flat = config.flat()
  return {k: flat[k] for k in joint.PER_RECORDING if k in flat}


# At most this factor an intake's claimed camera error is raised to the
# lowest a shipped calibration's tables cover (``calibrated_camera``).
RAISE = 2.0


def calibrated_camera(config) -> tuple[float, float]:
  """The camera error (metres, degrees) an estimate with ``config`` carries
  so that a shipped calibration's tables cover it: its own where one does
  or none would; else each component raised, by at most ``RAISE``, to the
  lowest that the nearest such tables hold. Carrying more error than the
  intake claims widens the posterior a little (wider is acceptable); a
  claim below every table's range would print the intervals as indicative."""
  own = carried_errors.camera_of(config.flat())
  raised = []
  for path in calibration_tables.shipped_calibrations(config.scoring.distance):
    cal = calibration_tables.read_calibration(path)
    m, deg, spread = carried_errors.table_of(cal)
    if m <= 0.0 or deg <= 0.0:
      continue  # exact cameras' tables: no error raised reaches them
    low = (carried_errors.spread_range(m, spread)[0],
           carried_errors.spread_range(deg, spread)[0])  # fmt: skip
    up = tuple(max(o, lo) for o, lo in zip(own, low, strict=True))
    if any(u > RAISE * o for u, o in zip(up, own, strict=True)):
      continue
    moved = config.replace(camera_sd_m=up[0], camera_sd_deg=up[1])
    if not calibration_tables.differing_fields(moved, cal):
      raised.append(up)
  if not raised or own in raised:
    return own
  return min(raised, key=lambda up: carried_errors.camera_gap(own, up))


def with_alignment_error(config, intakes: list, carry: bool = True):
  """``config`` with the intakes' own alignment error as its camera error
  (the largest of them; ``camera_sd_from='intake'``, so tables of cameras
  displaced as the intake errs hold) where ``carry`` and the user gave none, raised to a
  calibration's range where it lies just below it (``calibrated_camera``);
  and the line that says so, or None."""
  sds = [ik.alignment_sd for ik in intakes if ik is not None and any(ik.alignment_sd)]
  if not (carry and sds) or config.scoring.camera_sd_m or config.scoring.camera_sd_deg:
    return config, None
  claimed = max(s[0] for s in sds), max(s[1] for s in sds)
  config = config.replace(
    camera_sd_m=claimed[0], camera_sd_deg=claimed[1], camera_sd_from='intake'
  )
  m, deg = calibrated_camera(config)
  config = config.replace(camera_sd_m=m, camera_sd_deg=deg)
  config.check()
  line = (
    f"the posterior carries the alignment's own error: the camera placed to "
    f'{100 * m:.1f} cm and {deg:g} degrees (1 sd; --camera_sd_m and '
    '--camera_sd_deg set it, --noalignment_sd trusts the placement exactly)'
  )
  if (m, deg) != claimed:
    line += (
      f'; the alignment claimed {100 * claimed[0]:.1f} cm and {claimed[1]:g} '
      "degrees, raised to the calibration's lowest so that its measured "
      'coverage applies'
    )
  return config, line


def alignment_record(intakes: list, config) -> dict | None:
  """What estimate.json says of the recordings' alignment, or None (none
  taken in)."""
  taken = [ik for ik in intakes if ik is not None]
  if not taken:
    return None
  guesses = [intake_record.guess_note(ik) for ik in taken if ik.up_is_guess]
  return {
    'up_from': [ik.up_from for ik in taken],
    'up_is_guess': bool(guesses),
    'intake_alignment_sd': [
      {'m': ik.alignment_sd[0], 'deg': ik.alignment_sd[1]} for ik in taken
    ],
    'camera_sd_m': config.scoring.camera_sd_m,
    'camera_sd_deg': config.scoring.camera_sd_deg,
    'warnings': guesses + [w for ik in taken for w in ik.warnings],
  }


def needs_intake(take: takes.Take) -> bool:
  """Everything but this project's own simulated sequences without a camera
  file is taken in."""
  return bool(take.camera_json) or not intake_frames.is_sequence(take.path)


def intake_dir(workdir: str, i: int, n: int) -> str:
  """Where recording ``i`` of ``n``'s intake goes."""
  return workdir if n == 1 else f'{workdir}/intake_{i}'


def guess_refused(path: str) -> ValueError:
  """The refusal of a recording whose up is a guess from the cloth's plane."""
  return ValueError(
    f"{path}: up is a guess from the cloth's own plane (no floor in view), "
    'which a cloth swung by the wind tilts, and the camera and the answer '
    "with it; give --world_up=AXIS (the camera file's world axis that points "
    'up), "gravity" in the camera file, or --up; or --allow_guessed_up to '
    'estimate anyway with a 20-degree tilt uncertainty'
  )


def check_workdirs(
  recorded: list[takes.Take], workdir: str, all_taken_in: bool
) -> None:
  """Refuses (before any intake writes) an intake workdir that holds another
  recording's run; ``all_taken_in``: every recording will be (an intake
  only), else those ``needs_intake`` names."""
  n = len(recorded)
  for i, take in enumerate(recorded):
    if all_taken_in or needs_intake(take):
      intake_files.check_workdir(
        intake_dir(workdir, i, n), take.path, take.camera_json, layout.RUN_FILE
      )


def take_in(take: takes.Take, ik: intake.IntakeConfig, config, workdir: str):
  """One recording taken in with its own settings (``take_settings``); its
  summary printed and its files written."""
  ik, config = take_settings(ik, config, take)
  out = intake.take_in(
    take.path, ik, take.camera_json, config.simulation, workdir=workdir
  )
  print(intake_record.summary(out))
  intake_files.write(out, workdir, config.simulation)
  return out


class Prepared(NamedTuple):
  """The recordings ready to estimate.

  Attributes:
    recordings: each ``recording.Recording``.
    configs: each one's estimate settings (its own set-up, its alignment error).
    intakes: each one's intake, or None (a project sequence read as it is).
    lines: what the user should read before the answer (each alignment
      error carried into a posterior, readings carried less precise).
    readings: the readings' uncertainties carried in place of the given
      ones (``carried_readings``), by flat name; empty: as given.
    given: those readings' uncertainties as given, by the same names.
  """

  @property
  def record(self) -> dict | None:
    """What the estimate's JSON says of the alignment (``alignment_record``)."""
    return alignment_record(self.intakes, self.configs[0])

  recordings: list
  configs: list
  intakes: list
  lines: list[str]
  readings: dict
  given: dict


def prepare(
  recorded: list[takes.Take],
  ik: intake.IntakeConfig,
  config,
  network: setup.Network,
  workdir: str,
  *,
  carry_alignment: bool = True,
  allow_guessed_up: bool = False,
) -> Prepared:
  """Takes every recording in (or reads a project sequence as it is), each
  with its own settings, at the network's frame size.

  Raises:
    ValueError: a recording an RGB network cannot read, one whose up is a
      guess (unless ``allow_guessed_up``), or any intake's refusal (named).
  """
  net = network.embedding
  n = len(recorded)
  recs, intakes, configs, lines = [], [], [], []
  for i, take in enumerate(recorded):
    _, own = take_settings(ik, config, take)
    if needs_intake(take):
      if net.modality == 'rgb':
        raise ValueError(
          f'{take.path}: an RGB network needs a dataset sequence with colour '
          'frames; the intake reads depth only'
        )
      taken = take_in(take, ik, config, intake_dir(workdir, i, n))
      if taken.up_is_guess and not allow_guessed_up:
        raise guess_refused(take.path)
      intakes.append(taken)
      recs.append(
        intake_files.to_recording(
          taken, own.simulation.fps, net.image_size, own.simulation.frames
        )
      )
    else:
      intakes.append(None)
      recs.append(
        recording_lib.load_recording(
          take.path,
          fps=own.simulation.fps,
          size=net.image_size,
          frames=own.simulation.frames,
          rgb=net.modality == 'rgb',
        )  # fmt: skip
      )
      intake_frames.check_clip(take.path, len(recs[-1].depth), own.simulation)
    # each recording carries its own intake's alignment error
    own, line = with_alignment_error(own, intakes[-1:], carry_alignment)
    configs.append(own)
    if line:
      lines.append(f'{take.path}: {line}' if n > 1 else line)
  raised, line = carried_readings(recorded, configs, network)
  given = {k: getattr(configs[0].measured, k) for k in raised}
  configs = [c.replace(**raised) for c in configs]
  return Prepared(
    recs, configs, intakes, [*lines, *filter(None, [line])], raised, given
  )


def carried_readings(
  recorded: list[takes.Take], configs: list, network: setup.Network
) -> tuple[dict, str | None]:
  """The readings' uncertainties the estimate carries in place of those
  given, and the line that says so (``reading_floor.carried``): raised to
  the lowest a shipped calibration was measured with where only that keeps
  its coverage from this estimate (one recording's tables, or a joint's
  protocol check: its fabric readings only, each recording keeping its own
  wind reading)."""
  if len(configs) == 1:
    names = reading_floor.READINGS
    covered = lambda r: _measured(setup.estimate_note(configs[0].replace(**r), network))  # noqa: E731
  else:
    names, fans = reading_floor.SHARED, takes.fans(recorded)
    covered = lambda r: _measured(  # noqa: E731
      joint.joint_note([c.replace(**r) for c in configs], network, fans)
    )
  lows = reading_floor.floors(configs[0].scoring.distance)
  return reading_floor.carried(configs[0].measured, lows, covered, names)


def _measured(note: dict | None) -> bool:
  """Whether a calibration note quotes measured coverage (not indicative)."""
  return bool(note) and note.get('matches', True)


def estimate(
  recorded: list[takes.Take],
  prepared: Prepared,
  config,
  model: str,
  workdir: str,
  pictures: list[Callable] | None = None,
  **kw,
) -> dict:
  """The estimate of the prepared recordings: one recording's
  (``estimate.json``), or several's jointly (``joint.json``), each file with
  the recordings' alignment record (``alignment_record``) and the readings
  carried less precise than given (``carried_readings``: each one's given
  and carried sd). ``kw``: the search's (``allow_other_material``, ``nets``)."""
  record = prepared.record
  if len(recorded) > 1:
    winds = [t.wind or (0.0, 0.0) for t in recorded]
    result = estimation.estimate_joint(
      config.replace(**prepared.readings), prepared.recordings, model, workdir,
      winds if any(t.wind for t in recorded) else None,
      overrides=[own_settings(c) for c in prepared.configs],
      fans=takes.fans(recorded), pictures=pictures, **kw,
    )  # fmt: skip
    path = os.path.join(workdir, layout.JOINT_FILE)
  else:
    result = estimation.estimate(
      prepared.configs[0], prepared.recordings[0], model, workdir,
      pictures=pictures, **kw,
    )  # fmt: skip
    path = os.path.join(workdir, layout.ESTIMATE_FILE)
  carried = {
    k: {'given': prepared.given[k], 'carried': v} for k, v in prepared.readings.items()
  }
  _add_records(path, alignment=record, readings_carried=carried or None)
  return result


def _add_records(path: str, **records) -> None:
  """Adds ``records`` (those not None) to the result JSON the search wrote
  at ``path``."""
  records = {k: v for k, v in records.items() if v is not None}
  if not records or not os.path.isfile(path):
    return
  data = recording_lib.read_json(path)
  data.update(records)
  files.write_json(path, data)
