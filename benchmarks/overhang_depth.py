"""A fabric's bending read from depth recordings of an overhang, and the
protocol set it completes: measured on set-ups the reader was not fitted to.

Issue 39: the 1 m sheet in a fan measures the wind and, with an anemometer,
the area weight, but not the bending; a strip over a table's edge measures
the bending length c = (D / (w g))^(1/3). Here each set-up is a world the
reader (``physsim.overhang_depth``) does not know: a fabric and truth drawn
from its search box, a strip 2.5-5 cm wide, 0.3-1.5 mm thick, its
cross-section curled by -1 to 1.5 mm, leaving the edge up to 5 degrees
askew, slid 2.5-3.5 bending lengths over (``--setups=peirce``: 1.6-2.6, Peirce's
two bending lengths, the protocol before 2026-11-29) a table 0.7-0.8 m
high with a 1.8-4 cm top board, the length the user reads off the strip off
by a ruler's 1 mm; a Kinect-class camera (640 x 480, 58 degrees,
``physsim.sensor``'s noise, holes at depth jumps, dropouts) 0.35-0.55 m away,
20-40 degrees above the table, up to 25 degrees to the side, rolled up to 5,
five frames. The strip hangs as the heavy elastica (the physics of a real
strip; the estimator's own cloth simulator is not used, and its strip is
softer than its nominal D: BENCHMARKS.md, ``benchmarks.overhang_mesh``).
``--renderer=mujoco`` renders the frames with MuJoCo's own OpenGL renderer
(EGL, offscreen; square pixels, 45 degrees vertical) instead of the
project's ray-caster, the table a box: the reader must not lean on the
ray-caster's conventions.

Its tables are sharp-edged; the reading on real tables (rounded edges 0-3
mm, thin boards, flying pixels, depth-scale bias, the envelope's corners) is
checked by ``benchmarks.overhang_check``, whose ``--tune`` set now keeps the
reader's law. Two seeds here: ``--seed=0`` prints the law that fits its
set-ups (the Student's t whose 25, 50, 75 and 90% intervals hold c closest
to as often as they say) and ``--seed=1`` checks it. With ``--packed`` (the runs of
a calibration check, ``experiments.calibrate --check``, e.g. the 56
recordings of the mismatched physics) each of its sheet recordings gets an
overhang recording of its own fabric and truth, and the sheet's posterior
(its saved GP, the shipped likelihood) with a 2% anemometer reading and the
overhang's bending length gives the protocol set's joint estimate: bending,
area weight and wind against the truth, and how often the intervals hold.

  python -m benchmarks.overhang_depth --seed=0 --sets=40 --out=$OUT/od_seed0
  python -m benchmarks.overhang_depth --seed=1 \
      --packed=out/chk_mm_packed/packed --out=$OUT/od_seed1
  MUJOCO_GL=egl python -m benchmarks.overhang_depth --seed=1 --renderer=mujoco \
      --packed=out/chk_mm_packed/packed --out=$OUT/od_seed1_mujoco

Its parts are in ``experiments.studies``: the set-ups in ``overhang_setups``,
the law their readings are scored under in ``overhang_law``, the protocol
sets' joint estimate in ``overhang_joint``, what a run writes and prints in
``overhang_report``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time

import jax
import numpy as np

import physsim
from experiments.pipeline import calibration_tables, cli, files, measurements
from experiments.studies import overhang_joint, overhang_report, overhang_setups
from experiments.studies.overhang_law import with_law
from physsim import overhang_depth


@dataclasses.dataclass(frozen=True)
class Args:
  """The set-ups and what to combine them with.

  Attributes:
    seed: of the set-ups (0 fits the error law, others check it).
    sets: set-ups without ``packed`` (with it: one per packed recording).
    packed: a folder of packed runs (``runs-*.npz``) of sheet recordings.
    floor: the reader's relative floor on its t law's scale (negative: its
      ``FLOOR``).
    dof: that law's degrees of freedom (0: its ``DOF``).
    grid: the posterior grid (bending, wind, area weight) of the packed runs.
    likelihood: the packed runs' likelihood form.
    sharpness: and its sharpness (the shipped paper-size table's).
    renderer: 'raycaster' (``physsim.render``) or 'mujoco' (MuJoCo's OpenGL).
    setups: the ranges set-ups are drawn from (``overhang_setups.SETUPS``):
      'protocol' as
      README asks, 'wide' as a user reading it loosely might film.
    calibration: the calibration file whose tables the protocol sets are also
      read with, as an estimate prints them ('': the shipped paper-size
      shape calibration).
    readings: an earlier run's ``overhang_depth.json`` (or ``summary.json``)
      whose set-ups and readings to reuse (same seed and truths, matched by
      the bending length, in any order), rendering nothing: the readings
      read again under another law (``floor``, ``dof``), the protocol sets
      with new calibration tables or new searches.
    out: output folder (JSON, PNG).
  """

  seed: int = 0
  sets: int = 40
  packed: str = ''
  floor: float = -1.0
  dof: float = 0.0
  grid: tuple[int, ...] = (12, 64, 24)
  likelihood: str = 'gibbs'
  sharpness: float = 0.5
  renderer: str = cli.choice('raycaster', ('raycaster', 'mujoco'))
  setups: str = cli.choice('protocol', tuple(overhang_setups.SETUPS))
  calibration: str = ''
  readings: str = ''
  out: str = 'out/overhang_depth'


PRESETS = {'default': Args()}


def earlier_rows(path: str, args: Args, n: int) -> list[dict]:
  """The set-ups and readings of an earlier run (``--readings``).

  Raises:
    ValueError: its seed, renderer, set-up ranges or number of set-ups
      differs.
  """
  old = physsim.dataset.read_json(path)
  for name in ('seed', 'renderer', 'setups'):
    theirs = old['args'].get(name, getattr(Args(), name))  # older runs: the default
    if theirs != getattr(args, name):
      raise ValueError(
        f'--readings={path}: made with --{name}={theirs}, not {getattr(args, name)}'
      )
  if len(old['rows']) != n:
    raise ValueError(f'--readings={path}: {len(old["rows"])} set-ups, not {n}')
  return old['rows']


def _law(args: Args) -> tuple[float, float]:
  """The (floor, dof) of the law the readings are scored under: the flags',
  else the reader's own (``overhang_depth.FLOOR``, ``DOF``).

  Raises:
    ValueError: naming the flag: a dof the t law has no sd for, or a floor
      outside [0, 1).
  """
  floor = overhang_depth.FLOOR if args.floor < 0 else args.floor
  dof = args.dof or overhang_depth.DOF
  measurements.check_dof(dof, 'dof')
  if not (math.isfinite(floor) and 0 <= floor < 1):
    raise ValueError(f'--floor={args.floor}: a relative floor in [0, 1)')
  return floor, dof


def _reread(path: str, earlier: list[dict], unused: list[int], i: int, c: float,
            floor: float, dof: float) -> dict:  # fmt: skip
  """Set-up ``i``'s reading from an earlier run (``--readings``) under the
  law: matched by its truth ``c`` among the ``unused`` rows (runs packed by
  another number of processes come in another order; a pair's two
  recordings share one truth, each its own reading), which it takes.

  Raises:
    ValueError: naming the file: no set-up of that truth, or one without
      the reader's fit.
  """
  mine = [k for k in unused if math.isclose(earlier[k]['c'], c, rel_tol=1e-6)]
  if not mine:
    raise ValueError(f"--readings={path}: no set-up of run {i}'s truth (c = {c:.6g} m)")
  unused.remove(mine[0])
  try:
    return with_law(earlier[mine[0]], floor, dof)
  except ValueError as e:
    raise ValueError(f'--readings={path}: set-up {i}: {e}') from None


def _write(args: Args, rows: list[dict], sets: list[dict], example: dict | None,
           floor: float, dof: float) -> None:  # fmt: skip
  """The run's figures, its full results and compact summary (JSON), and
  its table printed."""
  overhang_report.plot(rows, example, os.path.join(args.out, 'overhang_depth.png'))
  if sets:
    overhang_report.plot_sets(sets, os.path.join(args.out, 'protocol_sets.png'))
  for r in rows:
    r.pop('profile', None)
  out = {
    'args': dataclasses.asdict(args), 'floor': floor, 'dof': dof,
    'summary': overhang_report.summary(rows, sets, dof), 'rows': rows, 'sets': sets,
  }  # fmt: skip
  files.write_json(os.path.join(args.out, 'overhang_depth.json'), out)
  files.write_json(os.path.join(args.out, 'summary.json'), overhang_report.compact(out))
  print(overhang_report.table(out))


def main(args: Args) -> None:
  """Draws, renders and reads the set-ups (or reads an earlier run's readings
  again), with each packed run's protocol set where ``packed`` is given, and
  writes what they say."""
  floor, dof = _law(args)
  rng = np.random.default_rng([args.seed, 39])
  key = jax.random.key(args.seed)
  runs = overhang_joint.packed_runs(args.packed) if args.packed else []
  n = len(runs) or args.sets
  earlier = earlier_rows(args.readings, args, n) if args.readings else None
  unused = list(range(n))
  tables = overhang_joint.shipped_tables(
    args.calibration or calibration_tables.shipped_calibration('shape', 'paper')
  ) if runs else {}  # fmt: skip
  rows, sets = [], []
  example = None
  os.makedirs(args.out, exist_ok=True)
  t0 = time.time()
  for i in range(n):
    c = overhang_setups.bending_length_of(i, runs[i] if runs else None, rng)
    # drawn on a re-read too, so that the next truth's draw follows it
    setup = overhang_setups.draw_setup(rng, c, args.setups)
    if earlier is not None:
      row = _reread(args.readings, earlier, unused, i, c, floor, dof)
    else:
      row = overhang_setups.read_setup(
        setup, jax.random.fold_in(key, i), floor, dof, args.renderer
      )
    rows.append(row)
    if example is None and 'c_hat' in row and 'profile' in row:
      example = row
    if runs:
      joint = overhang_joint.joint_estimate(runs[i], row, args, args.seed, tables)
      sets.append({'seq': runs[i]['seq'], 'material': runs[i]['material'],
                   'truth': runs[i]['truth'], 'joint': joint})  # fmt: skip
    msg = (
      row.get('refused')
      or f'c {100 * c:.2f} cm, error {100 * row["error"]:+.1f}%, z {row["z"]:+.2f}'
    )
    print(f'[{i + 1}/{n}] {time.time() - t0:.0f} s: {msg}', flush=True)
  _write(args, rows, sets, example, floor, dof)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
