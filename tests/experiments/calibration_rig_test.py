"""Tables fitted on a user's rig's recordings (issue 77): the windy rig's
pairs are drawn as the study draws its own, its finished estimates are read
as the study's runs, and the tables they make are the ones an intake's
estimate quotes."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

import bo
import physsim
from benchmarks import windy_rig
from experiments import calibrate, estimate
from experiments.pipeline import calibration_tables, carried_errors, layout
from experiments.studies import calibration, calibration_rig

PAPER = calibration.PRESETS['paper']
MATS = ('gray_interlock', 'black_denim')


def test_drawn_pairs_share_a_fabric_and_draw_their_own_winds_over_the_prior():
  args = windy_rig.Args(
    pairs=3, fabric_draws=5, materials=','.join(MATS), recipe='mismatched'
  )
  recs = windy_rig.recordings(args)
  assert [n for n, _ in recs] == [f'rec{k:02d}' for k in range(6)]
  assert [r.seed for _, r in recs] == [recs[0][1].seed + k for k in range(6)]
  for j in range(3):
    (_, a), (_, b) = recs[2 * j], recs[2 * j + 1]
    assert a.material == b.material == MATS[j % 2]
    assert (a.bending_scale, a.area_weight) == (b.bending_scale, b.area_weight)
    assert a.wind_speed != b.wind_speed
    space = physsim.search_space(a.material)
    for r in (a, b):
      for f in ('bending_scale', 'wind_speed', 'area_weight'):
        lo, hi = getattr(space, f)
        assert lo <= getattr(r, f) <= hi, (f, getattr(r, f))


@pytest.mark.parametrize(
  'args, named',
  [(dict(pairs=2), '--fabric_draws'), (dict(pairs=2, fabric_draws=1, materials='silk'), "'silk'")],
)  # fmt: skip
def test_drawn_pairs_refuse_what_they_cannot_draw(args, named):
  with pytest.raises(ValueError, match=named):
    windy_rig.recordings(windy_rig.Args(**args))


def _saved_gp(truth: dict, material: str) -> dict:
  """A GP whose log discrepancy is least at the truth (on the study's grid)."""
  pts = np.asarray(
    bo.posterior.grid_points(tuple(PAPER.estimate.search.posterior_grid))
  )
  p = physsim.Params(**{k: np.float64(v) for k, v in truth.items()})
  u = np.asarray(physsim.to_unit(p, physsim.search_space(material)), np.float64)
  d2 = np.sum((pts - u.reshape(1, 3)) ** 2 * np.array([0.05, 4.0, 0.2]), axis=1)
  return {
    'gp_mean': np.log(1e-3 + d2), 'gp_var': np.full(len(pts), 0.01),
    'floor': np.float64(math.log(1e-3)), 'noise_sd': np.float64(0.3),
  }  # fmt: skip


def _rig_recording(root, k: int, material: str, truth: dict, claim, **config):
  """A windy-rig recording ``rec<k>`` with a finished estimate's files (none
  where ``claim`` is None: refused)."""
  where = root / f'rec{k:02d}'
  (where / 'recording').mkdir(parents=True)
  (where / 'recording' / 'truth.json').write_text(json.dumps(truth))
  recipe = {'material': material, **truth}
  (where / 'recording' / 'recipe.json').write_text(json.dumps(recipe))
  if claim is None:
    return
  est = where / 'est_world_up'
  est.mkdir()
  flat = {**PAPER.estimate.flat(), 'camera_sd_from': 'intake', **config}
  (est / layout.ESTIMATE_FILE).write_text(json.dumps({
    'material': material, 'config': flat,
    'alignment': {'camera_sd_m': claim[0], 'camera_sd_deg': claim[1]},
  }))  # fmt: skip
  np.savez(est / layout.POSTERIOR_FILE, **_saved_gp(truth, material))


def _truth(rng, material, fabric=None) -> dict:
  p = physsim.from_unit(rng.uniform(-1, 1, 3), physsim.search_space(material))
  out = {
    f: float(getattr(p, f)) for f in ('bending_scale', 'wind_speed', 'area_weight')
  }
  return {**out, **(fabric or {})}


@pytest.fixture
def rig_dirs(tmp_path):
  """Three rig workdirs: two of pairs (``--pairs``; the first's rec01
  refused, so its rec00 is read alone), one of two recordings each of its own
  fabric (``--winds`` with ``--fabric_draws``); claims (1 cm, 1 deg) to
  (4 cm, 2 deg)."""
  rng = np.random.default_rng(0)
  claims = iter([(0.01, 1.0), None, (0.02, 1.5), (0.03, 1.2), (0.04, 2.0), (0.02, 1.1),
                 (0.015, 1.1), (0.025, 1.6)])  # fmt: skip
  for name, mat, paired in (('rig_a', MATS[0], True), ('rig_b', MATS[1], True),
                            ('rig_c', MATS[0], False)):  # fmt: skip
    fabric = None
    for k in range(4 if name == 'rig_a' else 2):
      t = _truth(rng, mat, fabric=fabric if k % 2 and paired else None)
      fabric = {f: t[f] for f in ('bending_scale', 'area_weight')}
      _rig_recording(tmp_path / name, k, mat, t, next(claims))
  return tmp_path


def test_rig_runs_number_pairs_across_folders_and_skip_unfinished(rig_dirs):
  runs = calibration_rig.rig_runs(f'{rig_dirs}/rig_*')
  assert [r['seq'] for r in runs] == [0, 2, 3, 4, 5, 6, 8]
  assert [r['material'] for r in runs] == [MATS[0]] * 3 + [MATS[1]] * 2 + [MATS[0]] * 2
  by = {r['seq']: r['truth'] for r in runs}
  for s in (2, 4):  # pairs: one fabric, two winds
    assert by[s]['bending_scale'] == by[s + 1]['bending_scale']
    assert by[s]['wind_speed'] != by[s + 1]['wind_speed']
  assert by[6]['bending_scale'] != by[8]['bending_scale']  # each its own


def test_the_claims_range_holds_every_claim_worked_by_hand(rig_dirs):
  m, deg, spread = calibration_rig.claims_range(
    calibration_rig.rig_runs(f'{rig_dirs}/rig_*')
  )
  # metres 1-4 cm: centre 2 cm; degrees 1-2: centre sqrt(2); the wider
  # log half-range, the shifts': log(4) / 2
  assert m == pytest.approx(0.02, abs=1e-6)
  assert deg == pytest.approx(math.sqrt(2), abs=1e-5)
  assert spread == pytest.approx(math.log(4) / 2, abs=1e-4)


def test_a_rig_searched_otherwise_is_refused_naming_the_folder_and_setting(tmp_path):
  rng = np.random.default_rng(1)
  _rig_recording(tmp_path / 'rig', 0, MATS[0], _truth(rng, MATS[0]), (0.02, 1.5),
                 cloth_resolution=33)  # fmt: skip
  runs = calibration_rig.rig_runs(str(tmp_path / 'rig'))
  with pytest.raises(ValueError, match=r'rig/rec00/est_world_up.*cloth_resolution=33'):
    calibration_rig.with_rig_runs(PAPER, runs)


def test_no_folder_or_no_estimate_is_refused(tmp_path):
  with pytest.raises(ValueError, match='no folder matches'):
    calibration_rig.rig_runs(str(tmp_path / 'nowhere*'))
  (tmp_path / 'rig' / 'rec00').mkdir(parents=True)
  with pytest.raises(ValueError, match='no finished estimate'):
    calibration_rig.rig_runs(str(tmp_path / 'rig'))


def test_a_damaged_posterior_is_refused_naming_it(rig_dirs):
  path = rig_dirs / 'rig_b' / 'rec01' / 'est_world_up' / layout.POSTERIOR_FILE
  path.write_bytes(b'')
  with pytest.raises(ValueError, match=rf'{path}: not a finished estimate'):
    calibration_rig.rig_runs(f'{rig_dirs}/rig_*')


def test_the_study_fits_every_mode_on_the_rigs_recordings(rig_dirs, monkeypatch):
  """The analysis reads the rig's runs as its own: every recording in the
  video's tables, the joint pair only where both of a pair finished, and the
  setting says whose recordings they were."""
  monkeypatch.setattr(calibration_rig, 'MIN_RECORDINGS', 5)
  config = dataclasses.replace(
    PAPER, centred_levels=True, rig_runs=f'{rig_dirs}/rig_*', folds=2
  )
  runs = calibration_rig.rig_runs(config.rig_runs)
  config = calibration_rig.with_rig_runs(config, runs)
  assert config.materials == MATS and config.pairs == 4  # rig_a's and rig_c's
  assert config.estimate.scoring.camera_sd_from == 'intake'
  out = calibration.run(config, str(rig_dirs / 'work'), analyse_only=True)
  assert out['n'] == 7 and out['recalibration']['n_calibration_recordings'] == 7
  assert out['held_out_uncalibrated']['joint pair']['n'] == 4  # rec00 of rig_a alone
  # a mode held out on fewer than MIN_RECORDINGS is reported, not shipped
  assert set(out['recalibration']['modes']) == set(calibration.MODES) - {
    'joint pair',
    'joint pair, known winds',
  }
  assert (
    'not shipped (fewer than 5 held out): joint pair, joint pair, known winds'
    in (rig_dirs / 'work' / 'calibration.md').read_text()
  )
  assert (
    "from a user's rig" in out['setting'] and '1-4 cm / 0.71-2.8 deg' in out['setting']
  )
  assert carried_errors.table_recordings(out) == 'rig'
  assert 'Rig recordings: 7' in (rig_dirs / 'work' / 'calibration.md').read_text()


def test_rig_tables_ship_beside_the_others_and_an_intake_estimate_quotes_them(
  tmp_path, monkeypatch
):
  base = str(tmp_path / 'calibration_shape_paper.json')
  sim = carried_errors.camera_path(base, (0.02, 1.6), 0.7, 'intake')
  mine = carried_errors.camera_path(base, (0.02, 1.6), 0.7, 'intake', 'rig')
  assert mine.endswith('_camera_intake_rig_0.99-4cm_0.79-3.2deg.json')
  shipped = calibration_tables.read_calibration(
    calibration_tables.shipped_calibration('shape', 'paper', (0.03, 2.5), 1.25)
  )
  for path, rig_runs in ((sim, ''), (mine, 'out/rig_*')):
    cal = json.loads(json.dumps(shipped))
    cal['config'].update(rig_runs=rig_runs, camera_sd_spread=0.7)
    cal['config']['estimate'].update(
      camera_sd_m=0.02, camera_sd_deg=1.6, camera_sd_from='intake'
    )
    open(path, 'w').write(json.dumps(cal))
  assert carried_errors.camera_paths(base) == sorted([sim, mine])
  monkeypatch.setattr(calibration_tables, 'shipped_calibrations', lambda _: [sim, mine])
  config = estimate.Args().search.replace(camera_sd_m=0.02, camera_sd_deg=1.5)
  intake = config.replace(camera_sd_from='intake')
  assert calibration_tables.calibration_file(intake) == mine
  # a joint estimate: the rig's tables lack its mode, the study's have it
  cal = json.loads(open(mine).read())
  del cal['recalibration']['modes']['joint pair']
  open(mine, 'w').write(json.dumps(cal))
  assert calibration_tables.calibration_file(intake, 'joint pair') == sim
  assert calibration_tables.calibration_file(intake, 'video') == mine
  # a user's own claim: the rig's cameras erred as the intake does, not as it may
  cal = calibration_tables.read_calibration(mine)
  assert 'camera_sd_from' in calibration_tables.differing_fields(config, cal)


def test_the_command_line_sets_the_rigs_settings_and_refuses_a_check(rig_dirs):
  study = dataclasses.replace(PAPER, rig_runs=f'{rig_dirs}/rig_*')
  args = calibrate.resolved(calibrate.Args(study=study))
  assert args.study.materials == MATS and args.study.camera_sd_spread > 0
  with pytest.raises(ValueError, match='drop --check'):
    calibrate.resolved(calibrate.Args(study=study, check=True))
