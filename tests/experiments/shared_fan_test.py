"""A sheet and its hemmed twin at one fan setting: one wind for both in the
joint posterior (against enumeration, and on a toy whose answer is known),
the hem simulated as a known mass along the free edge, read from a
protocol file, and every inconsistent set-up refused in one line."""

from __future__ import annotations

import itertools
import json

import jax
import numpy as np
import pytest
from jax.scipy.special import logsumexp

from experiments.pipeline import (
  calibration_tables,
  joint,
  objective,
  simulation,
  table_notes,
  takes,
)
from experiments.pipeline import posterior as posterior_lib

GRID = (2, 3, 2)  # bending, wind, area weight cells


def _enumerated(log_liks, log_prior, fans):
  """p(b, w | data) with one wind per fan label, by enumerating every cell
  combination of (b, w, v_label...)."""
  nb, nv, nw = GRID
  ll = [x.reshape(GRID) for x in log_liks]
  lp = log_prior.reshape(GRID)
  labels = list(dict.fromkeys(fans))
  log_v = lp - np.asarray(logsumexp(lp, axis=1))[:, None, :]  # p(v | b, w)
  log_bw = np.asarray(logsumexp(lp, axis=1))
  post = np.zeros((nb, nw))
  wind = {g: np.zeros(nv) for g in labels}
  terms = {}
  for b, w in itertools.product(range(nb), range(nw)):
    for vs in itertools.product(range(nv), repeat=len(labels)):
      t = log_bw[b, w] + sum(log_v[b, v, w] for v in vs)
      t += sum(ll[k][b, vs[labels.index(f)], w] for k, f in enumerate(fans))
      terms[(b, w, vs)] = t
  z = float(logsumexp(np.array(list(terms.values()))))
  for (b, w, vs), t in terms.items():
    p = np.exp(t - z)
    post[b, w] += p
    for g, v in zip(labels, vs, strict=True):
      wind[g][v] += p
  return post, wind


def test_recordings_of_one_fan_setting_share_one_wind_as_enumeration_says():
  rng = np.random.default_rng(4)
  g = int(np.prod(GRID))
  log_liks = [rng.normal(0, 1.5, g) for _ in range(3)]
  prior = np.log(rng.uniform(0.5, 1.5, g))
  fans = ['low', 'low', 'high']
  post, wind = _enumerated(log_liks, prior, fans)
  out = posterior_lib.joint(
    log_liks, GRID, prior, jax.random.key(2), n=60_000, fans=fans
  )
  np.testing.assert_allclose(np.exp(out['log_post_bw']), post, rtol=1e-5)  # float32
  a, b, c = out['samples']
  cell = lambda d: np.floor((d + 1.0) / 2.0 * np.array(GRID)).astype(int)
  # one wind for the two of 'low': the same draws, cell for cell
  np.testing.assert_array_equal(cell(a), cell(b))
  for draws, label in ((a, 'low'), (c, 'high')):
    for v in range(GRID[1]):
      want, got = wind[label][v], np.mean(cell(draws)[:, 1] == v)
      assert abs(got - want) < 5 * np.sqrt(want * (1 - want) / 60_000) + 1e-9
  # with no label shared, the same as one wind each (the draws to the bit)
  own = posterior_lib.joint(log_liks, GRID, prior, jax.random.key(2), n=1000)
  mine = posterior_lib.joint(
    log_liks, GRID, prior, jax.random.key(2), n=1000, fans=['x', 'y', 'z']
  )
  for p, q in zip(own['samples'], mine['samples'], strict=True):
    np.testing.assert_array_equal(p, q)


def _ridge_pair(nv: int, nw: int, true_cell: int):
  """Two recordings' log likelihoods on a (1, nv, nw) grid of wind 1-4 m/s
  and area weight 0.1-0.4 kg/m^2, each reading only a load ratio to 2%:
  log v^2/w, and with 0.3 kg/m^2 of known mass added, log v^2/(w + 0.3); the
  truth at wind cell 150 and area-weight cell ``true_cell``. Returns them
  (raveled) and the (nw,) area weights."""
  v = np.linspace(1, 4, nv)[None, :, None]
  w = np.linspace(0.1, 0.4, nw)[None, None, :]
  w_true, v_true = w[0, 0, true_cell], v[0, 150, 0]
  ridge = lambda extra: (
    -0.5
    * ((np.log(v**2 / (w + extra)) - np.log(v_true**2 / (w_true + extra))) / 0.02) ** 2
  )
  return [ridge(0.0).ravel(), ridge(0.3).ravel()], w[0, 0]


def test_a_shared_wind_weighs_the_cloth_that_two_winds_cannot():
  """Two recordings each measuring only a load ratio (a ridge in wind and
  area weight: log v^2/w to 2%), one with 0.3 kg/m^2 of known mass added
  (v^2/(w + 0.3): another slope): with a wind each, every area weight has
  winds that fit both and its posterior stays near the prior's (the ridges'
  own Jacobian tilts it); with one wind, the ridges cross at the true cell."""
  nb, nv, nw = 1, 300, 12
  lls, _ = _ridge_pair(nv, nw, 7)
  prior = np.zeros(nb * nv * nw)
  apart = posterior_lib.joint(lls, (nb, nv, nw), prior, jax.random.key(0), n=10)
  shared = posterior_lib.joint(
    lls, (nb, nv, nw), prior, jax.random.key(0), n=10, fans=['a', 'a']
  )
  p_apart = np.exp(apart['log_post_bw'][0])
  p_shared = np.exp(shared['log_post_bw'][0])
  assert p_apart.max() < 1.5 / nw and p_apart.min() > 0.5 / nw
  assert np.argmax(p_shared) == 7 and p_shared[6:9].sum() > 0.95


def test_a_fan_setting_has_one_prior_and_one_label_per_recording():
  g = int(np.prod(GRID))
  lls = [np.zeros(g)] * 2
  base = np.zeros(g)
  read = (base.reshape(GRID) + np.array([0.0, -1.0, -4.0])[None, :, None]).ravel()
  with pytest.raises(ValueError, match="share fan setting 'a' but not its prior"):
    posterior_lib.joint(lls, GRID, [base, read], jax.random.key(0), n=4, fans='aa')
  with pytest.raises(ValueError, match='3 fan settings for 2 recordings'):
    posterior_lib.joint(lls, GRID, base, jax.random.key(0), n=4, fans='abc')
  with pytest.raises(ValueError, match=r"fan setting 'a': its recordings were read"):
    joint.check_fans(['a', 'a'], [(2.0, 0.05), (0.0, 0.0)], 2)
  with pytest.raises(ValueError, match='1 fan settings for 2 recordings'):
    joint.check_fans(['a'], None, 2)
  joint.check_fans(['a', 'a'], [(2.0, 0.05), (2.0, 0.05)], 2)  # one reading, twice


def test_the_hem_is_a_known_mass_along_the_free_edge_of_the_simulated_cloth():
  sim = simulation.Simulation(cloth_resolution=6, hem_mass=0.3)
  cloth = simulation.cloth(sim)
  extra = cloth.extra_mass
  assert extra.sum() == pytest.approx(0.3, rel=1e-12)
  edge = np.nonzero(extra)[0]
  # the row farthest from the pins, every vertex of it alike
  pinned_y = cloth.mesh.vertices[cloth.mesh.pinned][:, 1].mean()
  far = np.abs(cloth.mesh.vertices[:, 1] - pinned_y)
  assert len(edge) == 6 and np.allclose(far[edge], far.max())
  assert np.allclose(extra[edge], 0.05)
  plain = simulation.cloth(simulation.Simulation(cloth_resolution=6))
  w = 0.2
  np.testing.assert_allclose(
    cloth.body_masses(w).sum() - plain.body_masses(w).sum(), 0.3, rtol=1e-9
  )
  config = objective.EstimateConfig.preset('smoke')
  hemmed = config.replace(hem_mass=0.3)
  hemmed.check()
  with pytest.raises(ValueError, match='hem_mass'):
    config.replace(hem_mass=2.0).check()
  with pytest.raises(ValueError, match='hem_mass'):
    config.replace(hem_mass=float('nan')).check()
  with pytest.raises(ValueError, match="garment 'tshirt' has none"):
    config.replace(garment='tshirt', hem_mass=0.1).check()
  # an estimate with a hem was not calibrated: its note says so (the shipped
  # paper-size file matches this estimate but for the hem)
  paper = objective.EstimateConfig().replace(distance='shape')
  assert calibration_tables.calibration_note(paper)['matches']
  note = calibration_tables.calibration_note(paper.replace(hem_mass=0.3))
  assert note['differs'] == ['hem_mass']
  note = calibration_tables.calibration_note(
    objective.EstimateConfig().replace(distance='shape'), joint=True, recordings=2,
    uncalibrated=('recordings sharing one fan setting',),
  )  # fmt: skip
  assert 'recordings sharing one fan setting' in note['differs']


def test_a_protocol_file_names_the_fan_and_the_hem(tmp_path):
  for name in ('plain', 'hem', 'other'):
    (tmp_path / name).mkdir()
  entries = [
    {'recording': 'plain', 'fan': 'low'},
    {'recording': 'hem', 'fan': 'low', 'hem_mass': 0.3},
    {'recording': 'other'},  # a recording listed twice is refused (takes.read)
  ]
  path = tmp_path / 'p.json'
  path.write_text(json.dumps({'recordings': entries}))
  plain, hem, other = takes.read(str(path))
  assert (plain.fan, plain.hem_mass, hem.fan, hem.hem_mass) == ('low', 0.0, 'low', 0.3)
  assert takes.fans([plain, hem, other]) == ['low', 'low', '#2']
  assert takes.fans([plain, other]) is None  # nothing shared
  for bad, message in (
    ({'hem_mass': -0.1}, r'"hem_mass"=-0.1 must be in \[0.0, 1.0\]'),
    ({'hem_mass': 'heavy'}, r'"hem_mass" must be a number'),
    ({'fan': 3}, r'"fan" must be a label'),
    (
      {'wind_speed': 2.0, 'wind_speed_sd': 0.05},
      r"the recordings of fan 'low' were read",
    ),
  ):
    path.write_text(json.dumps({'recordings': [entries[0], {**entries[1], **bad}]}))
    with pytest.raises(ValueError, match=message):
      takes.read(str(path))


def test_the_joint_table_says_which_recordings_shared_a_fan_and_carried_a_hem():
  recs = [{'fan': 'low'}, {'fan': 'low', 'hem_mass': 0.3}, {'fan': '#2'}]
  assert table_notes._set_up_note(recs) == (
    "recordings 0, 1 share fan setting 'low' (one wind); recording 1 carries 300 g at its hem."
  )
  assert table_notes._set_up_note([{}, {}]) == ''


def test_the_joints_shared_discrepancy_caps_what_a_hem_pair_says_of_area_weight():
  """A pair whose ridges cross sharply (one wind, one of them hemmed) pins
  log area weight to a few percent; the joint's shared discrepancy (log sd
  0.1 on area weight, every recording of the rig off by the same factor)
  adds its own spread in quadrature: the posterior sd is then about
  sqrt(0.1^2 + s0^2), never under 0.1 (docs/studies/protocol.md: why a hem pair
  narrows area weight so little in an uncalibrated joint)."""
  nb, nv, nw = 1, 300, 40
  lls, w = _ridge_pair(nv, nw, 20)
  prior = np.zeros(nb * nv * nw)
  log_w = np.log(w)

  def sd(bias):
    out = posterior_lib.joint(
      lls, (nb, nv, nw), prior, jax.random.key(0), n=10, fans=['a', 'a'],
      shared_bias_sd=bias, area_weight_range=(0.1, 0.4),
    )  # fmt: skip
    p = np.exp(out['log_post_bw'][0])
    mean = (p * log_w).sum()
    return float(np.sqrt((p * (log_w - mean) ** 2).sum()))

  s0, s1 = sd(0.0), sd(0.1)
  assert s0 < 0.07  # the pair alone: a few grid cells
  assert s1 >= 0.1 and s1 == pytest.approx(np.hypot(0.1, s0), rel=0.1)
