"""Tests for model.retrieval against a float64 NumPy brute force and hand-derived cases."""

import numpy as np
from absl.testing import absltest

from model import retrieval

_TOLERANCE = 1e-9  # log ratios of the exact stored parameters


def _numpy_energy(x, y):
  """Energy distance, V-statistics, float64 (the definition in model.psd)."""

  def mean_norm(a, b):
    return np.linalg.norm(a[:, None] - b[None], axis=-1).mean()

  return 2 * mean_norm(x, y) - mean_norm(x, x) - mean_norm(y, y)


def _brute_force(emb, videos, query_idx, ref_idx):
  out = []
  for q in np.unique(videos.video[query_idx]):
    qi = query_idx[videos.video[query_idx] == q]
    best, best_d = None, np.inf
    for r in np.unique(videos.video[ref_idx]):
      ri = ref_idx[videos.video[ref_idx] == r]
      if videos.camera[ri[0]] != videos.camera[qi[0]]:
        continue
      d = _numpy_energy(emb[qi].astype(np.float64), emb[ri].astype(np.float64))
      if d < best_d:
        best, best_d = ri[0], d
    out.append(np.log(videos.params[best] / videos.params[qi[0]]))
  return np.asarray(out)


def _random_set(seed=0, sims=9, cameras=2, frames=7):
  """Clips of `sims` simulations x `cameras`; embeddings drift with the parameters."""
  rng = np.random.default_rng(seed)
  params = np.exp(rng.normal(size=(sims, 3)))
  video, camera, rows, emb = [], [], [], []
  for s in range(sims):
    for c in range(cameras):
      centre = np.log(params[s, 1:]) + 0.3 * c
      emb.append(centre + 0.2 * rng.normal(size=(frames, 2)))
      video += [s * cameras + c] * frames
      camera += [c] * frames
      rows += [params[s]] * frames
  videos = retrieval.Videos(
    np.asarray(video), np.asarray(camera), np.asarray(rows), ('b', 'w', 'a')
  )
  return np.concatenate(emb).astype(np.float32), retrieval.check_videos(
    videos, len(video)
  )


class RetrievalTest(absltest.TestCase):
  def test_matches_numpy_brute_force(self):
    emb, videos = _random_set()
    n = len(emb)
    sims = videos.video // 2
    query_idx = np.flatnonzero(sims >= 6)
    ref_idx = np.flatnonzero(sims < 6)
    got = retrieval.retrieval_log_ratios(emb, videos, query_idx, ref_idx)
    want = _brute_force(emb, videos, query_idx, ref_idx)
    self.assertEqual(got.shape, (6, 3))  # 3 query simulations x 2 cameras
    np.testing.assert_allclose(got, want, atol=_TOLERANCE)
    self.assertEqual(n, 9 * 2 * 7)

  def test_hand_case_camera_and_oracle(self):
    # Query clip (camera 0) sits on reference A; reference C lies on it too but
    # is seen from camera 1, so it must be ignored.
    pts = {
      'q': [[0.0, 0.0], [0.1, 0.0]],
      'A': [[0.0, 0.1], [0.1, 0.1]],
      'B': [[5.0, 5.0], [5.1, 5.0]],
      'C': [[0.0, 0.0], [0.1, 0.0]],
    }
    params = {'q': [1.0, 2.0], 'A': [4.0, 2.0], 'B': [1.0, 1.0], 'C': [1.0, 2.0]}
    cams = {'q': 0, 'A': 0, 'B': 0, 'C': 1}
    names = list(pts)
    emb = np.concatenate([pts[k] for k in names]).astype(np.float32)
    videos = retrieval.check_videos(
      retrieval.Videos(
        np.repeat(np.arange(4), 2),
        np.repeat([cams[k] for k in names], 2),
        np.repeat([params[k] for k in names], 2, axis=0),
      ),
      8,
    )
    q, refs = np.arange(2), np.arange(2, 8)
    got = retrieval.retrieval_log_ratios(emb, videos, q, refs)
    np.testing.assert_allclose(got, [[np.log(4.0), 0.0]], atol=_TOLERANCE)
    # The oracle picks B (mean |log| = log(2)/2) over A (log(4)/2); C is camera 1.
    oracle = retrieval.oracle_log_ratios(videos, q, refs)
    np.testing.assert_allclose(oracle, [[0.0, np.log(0.5)]], atol=_TOLERANCE)
    # A random camera-0 reference: A or B, |log ratios| (log 4, 0) or (0, log 2).
    chance = retrieval.chance_errors(videos, q, refs)
    np.testing.assert_allclose(
      chance, [[np.log(4) / 2, np.log(2) / 2]], atol=_TOLERANCE
    )
    both = np.concatenate([got, oracle])
    s = retrieval.summary(both, np.repeat(chance, 2, 0), 'bw')
    self.assertEqual(s['queries'], 2)
    np.testing.assert_allclose(s['b'], np.log(4.0) / 2, atol=_TOLERANCE)
    np.testing.assert_allclose(s['w'], np.log(2.0) / 2, atol=_TOLERANCE)
    # Each parameter's mean error equals its chance value here: 1 = chance.
    np.testing.assert_allclose(s['error'], 1.0, atol=_TOLERANCE)
    np.testing.assert_allclose(s['chance']['w'], np.log(2) / 2, atol=_TOLERANCE)
    # Retrieving A: bending at twice its chance error, wind exact.
    s = retrieval.summary(got, chance, 'bw')
    np.testing.assert_allclose(s['error'], (2.0 + 0.0) / 2, atol=_TOLERANCE)
    self.assertEqual(videos.names, ('p0', 'p1'))
    # No reference of the query's camera: the query is left out.
    none = retrieval.retrieval_log_ratios(emb, videos, np.arange(6, 8), np.arange(0, 6))
    self.assertEqual(none.shape, (0, 2))
    self.assertEqual(retrieval.summary(none, none, ('b', 'w')), {})
    with self.assertRaisesRegex(ValueError, 'disagree'):
      retrieval.summary(got, chance[:, :1], 'bw')

  def test_ragged_references_agree_with_equal_ones(self):
    emb, videos = _random_set(seed=1)
    sims = videos.video // 2
    query_idx = np.flatnonzero(sims >= 6)
    ref_idx = np.flatnonzero(sims < 6)
    # Dropping one frame of one reference clip takes the one-by-one path.
    ragged = np.delete(ref_idx, 0)
    got = retrieval.retrieval_log_ratios(emb, videos, query_idx, ragged)
    np.testing.assert_allclose(
      got, _brute_force(emb, videos, query_idx, ragged), atol=_TOLERANCE
    )

  def test_bad_videos_are_named(self):
    ok = retrieval.Videos(np.zeros(2), np.zeros(2), np.ones((2, 3)))
    with self.assertRaisesRegex(ValueError, 'video has 2 rows for 3 items'):
      retrieval.check_videos(ok, 3)
    with self.assertRaisesRegex(ValueError, r'finite and > 0.*0\.0'):
      retrieval.check_videos(ok._replace(params=np.array([[1, 1, 1], [1, 0, 1.0]])), 2)
    with self.assertRaisesRegex(ValueError, 'video 0 disagree on camera'):
      retrieval.check_videos(ok._replace(camera=np.array([0, 1])), 2)
    with self.assertRaisesRegex(ValueError, 'video 0 disagree on params'):
      retrieval.check_videos(ok._replace(params=np.array([[1, 1, 1], [1, 2, 1.0]])), 2)
    with self.assertRaisesRegex(ValueError, '2 names for 3'):
      retrieval.check_videos(ok._replace(names=('a', 'b')), 2)

  def test_vs_chance_by_hand(self):
    lr = np.array([[0.2, 1.0], [0.4, 3.0]])
    chance = np.array([[0.5, 2.0], [0.7, 2.0]])
    s = retrieval.summary(lr, chance, ('wind', 'bend'))
    got = retrieval.vs_chance(s)
    # means 0.3 / 0.6 and 2.0 / 2.0
    self.assertEqual(set(got), {'wind', 'bend'})
    self.assertAlmostEqual(got['wind'], 0.5, places=12)
    self.assertAlmostEqual(got['bend'], 1.0, places=12)
    self.assertAlmostEqual(s['error'], 0.75, places=12)
    self.assertEqual(retrieval.vs_chance({}), {})


if __name__ == '__main__':
  absltest.main()
