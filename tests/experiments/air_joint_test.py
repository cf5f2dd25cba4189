"""The air coefficient end to end (issue 76): three fan settings of one fabric
whose air coefficient is half an ArcSim sheet's, simulated by the estimator's
own simulator at a tiny mesh (its wind's density halved), each with a 2%
anemometer reading, a 1% scale and a 3% bending length: a joint estimate with
the air coefficient free reads it back."""

from __future__ import annotations

import numpy as np
import pytest

import physsim
from experiments.pipeline import estimation, objective, report
from experiments.pipeline import recording as recording_lib
from tests.experiments import estimate_fixtures as fx

pytestmark = pytest.mark.slow  # a joint of three searches

C_TRUE = 0.5


def test_a_joint_of_three_fan_settings_reads_the_fabrics_air(tmp_path):
  winds = (2.0, 3.0, 4.0)
  truths = [dict(fx.TRUTH, wind_speed=v) for v in winds]
  space = physsim.search_space('gray_interlock')
  b, w = fx.TRUTH['bending_scale'], fx.TRUTH['area_weight']
  length = float(physsim.params.bending_length(b, w, space.rigidity))
  config = objective.PRESETS['smoke'].replace(
    backend='c', distance='shape', air_coefficient='free',
    area_weight=w, area_weight_sd=0.01 * w,
    bending_length=length, bending_length_sd=0.03 * length,
  )  # fmt: skip
  recs = [
    recording_lib.load_recording(
      fx.write_recording(str(tmp_path / f'r{k}'), t, air=C_TRUE),
      fps=config.simulation.fps,
      size=(fx.SIZE, fx.SIZE),
      frames=config.simulation.frames,
    )  # fmt: skip
    for k, t in enumerate(truths)
  ]
  readings = [(v, 0.02 * v) for v in winds]
  with pytest.raises(ValueError, match='air_coefficient=free'):
    estimation.estimate_joint(config, recs, '', str(tmp_path / 'x'))
  out = estimation.estimate_joint(config, recs, '', str(tmp_path / 'j'), readings)
  air = out['air_coefficient']
  print(report.joint_table(out))
  lo, hi = air['interval_90']
  assert lo <= C_TRUE <= hi, air
  assert air['narrowing_90'] > 1.5, air  # the readings and the video told of it
  assert np.exp(abs(np.log(air['median'] / C_TRUE))) < 1.3, air
  for k, v in enumerate(winds):  # each true wind, from the reading and c
    lo, hi = out['recordings'][k]['wind_speed']['interval_90']
    assert lo <= v <= hi, (k, lo, hi)
  table = report.joint_table(out)
  assert 'air coefficient (x ArcSim), shared' in table
