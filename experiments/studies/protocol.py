"""Which recordings measure the fabric, not only the wind? A Fisher-bound study.

Issue 39, item 2. A candidate recording is a piece of the fabric (the 1 m
sheet, or a 10-30 cm swatch) pinned at its two top corners (or one) in front of
a fan at one setting (or none), filmed by a depth camera; or the fabric flat on
a table with a few centimetres of it over the edge, in still air, filmed from
the side (an overhang: the textile cantilever test). What the camera sees
is approximated from the simulated vertices by a few statistics, each divided
by the cloth's size (``summaries``): where the cloth hangs on average over the
clip (its centroid out of plane and up), where its free bottom edge hangs, how
curved it is (the mean norm of the grid Laplacian, times the size), and how
much it moves (the centroid's standard deviation over the clip).

Per candidate and truth (bending scale, area weight, wind), with MuJoCo C on
the CPU:

* the slopes J of the statistics with respect to (log bending, log area
  weight, log wind) by central finite differences in steady wind; a
  recording without wind has no wind parameter;
* their noise covariance R: the spread over ``draws`` gust histories
  (gust intensity ``gusts``), pulled half-way to its diagonal
  (``bo.design.shrink``: a 6 x 6 covariance from a few draws), plus a depth
  sensor and set-up term (``sensor_sd``): a Kinect-class camera
  (sigma(z) = 1.5 mm at 1 m, growing as z^2; 640 x 480 px, 58 deg horizontal
  field of view) placed so the cloth fills 60% of the frame's width, but no
  nearer than its 0.5 m minimum range; ``setup_mm`` of set-up repeatability on
  every position and a ``curvature_floor`` on the curvature.

A set of recordings of one fabric shares bending and area weight; each fan
setting has its own wind. With the search box as a Gaussian prior in log
space (the box's variance, ``bo.design.log_box_sd``), the Fisher information
of the set gives the Cramer-Rao posterior widths of log bending and log area
weight, reported as the prior's 90% width over the posterior's ("narrowing"),
in three modes: the video alone, every wind read by an anemometer to 2%, and
the area weight weighed to 2% (a kitchen scale and a ruler).

The bound is on simulated statistics with the estimator's own simulator: a
lower bound on the width, which real recordings (another simulator, a camera,
model error) can only widen. ``experiments/protocol.py`` is its command line.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time

import jax
import matplotlib
import matplotlib.ticker
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

import physsim  # noqa: E402
from bo import design  # noqa: E402
from experiments.pipeline import files, layout, progress  # noqa: E402
from physsim import cantilever  # noqa: E402

RESULT_FILE = 'protocol.json'
SUMMARY_FILE = 'protocol_summary.json'  # without the slopes: small enough to commit
FIGURE_FILE = 'protocol.png'
CACHE_DIR = 'slopes'
CHAOS_NUDGE = 1e-3  # log bending
CACHE_VERSION = 3  # bump when what a cached slope file means changes
STATS = ('centroid_out', 'centroid_up', 'free_edge_out', 'free_edge_up',
         'curvature', 'motion')  # fmt: skip
PARAMS = ('log_bending', 'log_area_weight', 'log_wind')
MODES = ('video', 'anemometer', 'scale')
# Kinect-class depth camera
HFOV_DEG = 58.0
WIDTH_PX = 640
DEPTH_SD_1M = 0.0015  # m at 1 m, growing as z^2
MIN_RANGE_M = 0.5
UNUSED_SD = 1e6  # a statistic's noise that leaves it out of the information
FILL = 0.6  # of the frame's width
SPACE = physsim.SearchSpace(wind_speed=(0.0, 6.0))  # a recording may be windless


@dataclasses.dataclass(frozen=True)
class Candidate:
  """One recording a person could make.

  Attributes:
    size: the cloth's side, m.
    wind: the fan's mean wind, m/s (0: no fan).
    pins: 2 (the two top corners) or 1 (the top-left corner).
    resolution: vertices a side of the simulated square.
    overhang: the square lies flat on a table and ``size`` of it overhangs the
      edge, in still air, filmed from the side (the textile cantilever test,
      ASTM D1388: the droop is set by the bending length
      (D / (w g))^(1/3) over the overhang); else it hangs from its pins.
    hem: grams of known mass taped evenly along the free bottom edge (coins:
      a US nickel is 5.000 g, a 1-euro coin 7.50 g), 0 for none
      (``physsim.hem_mass``). In a fan the cloth's weight is then measured
      against a known one: the wind's push, whatever the drag law, is the same
      with and without it at one fan setting.
  """

  size: float
  wind: float
  pins: int = 2
  resolution: int = 9
  overhang: bool = False
  hem: float = 0.0

  @property
  def name(self) -> str:
    cm = round(100 * self.size)
    if self.overhang:
      return f'overhang_{cm}cm_r{self.resolution}'
    where = 'sheet' if self.size >= 0.5 else 'swatch'
    fan = f'{self.wind:g}ms' if self.wind > 0 else 'still'
    pin = '' if self.pins == 2 else '_1pin'
    hem = f'_hem{self.hem:g}g' if self.hem > 0 else ''
    return f'{where}_{cm}cm_{fan}{pin}{hem}_r{self.resolution}'


def parse(name: str) -> Candidate:
  """The candidate a ``Candidate.name`` names (e.g. ``'swatch_20cm_2ms_r9'``,
  ``'overhang_15cm_r17'``)."""
  parts = name.split('_')
  try:
    size = float(parts[1].removesuffix('cm')) / 100
    res = int(parts[-1].removeprefix('r'))
    if parts[0] == 'overhang':
      c = Candidate(size, 0.0, 2, res, overhang=True)
    else:
      wind = 0.0 if parts[2] == 'still' else float(parts[2].removesuffix('ms'))
      hems = [p for p in parts[3:-1] if p.startswith('hem')]
      hem = float(hems[0].removeprefix('hem').removesuffix('g')) if hems else 0.0
      c = Candidate(size, wind, 1 if '1pin' in parts else 2, res, hem=hem)
  except (IndexError, ValueError):
    raise ValueError(
      f'candidate {name!r}: need e.g. sheet_100cm_2ms_r9, swatch_20cm_still_r9, '
      'swatch_20cm_2ms_1pin_r9, sheet_100cm_2ms_hem100g_r9, overhang_15cm_r17'
    ) from None
  if c.name != name or not (
    0 < size <= 2 and 0 <= c.wind <= 6 and res >= 3 and 0 <= c.hem <= 1000
  ):
    raise ValueError(f'candidate {name!r} is not a canonical name (or out of range)')
  return c


def camera_distance(size: float) -> float:
  """Metres from a Kinect-class camera at which the cloth fills ``FILL`` of the
  frame's width, but no nearer than its minimum range."""
  width_at_1m = 2 * np.tan(np.radians(HFOV_DEG / 2))
  return max(size / (FILL * width_at_1m), MIN_RANGE_M)


def sensor_sd(c: Candidate, clip_s: float, camera_fps: float, setup_mm: float,
              curvature_floor: float) -> np.ndarray:  # fmt: skip
  """(len(STATS),) noise standard deviations of the statistics from the depth
  sensor and the set-up, in the statistics' units (divided by the size).

  The camera at ``camera_distance``: a pixel spans ``fp`` metres on the cloth;
  depth noise ``sz = 1.5 mm (d / 1 m)^2`` per pixel and frame, independent.
  Means over the cloth's ``n`` pixels and ``T`` frames: depth-wise (out of
  plane) ``sz / sqrt(n T)``; in the image plane (up) from the silhouette's
  ``4 L / fp`` edge pixels, ``fp / sqrt(12 4 L / fp T)``; the free edge from
  its ``L / fp`` pixels; the curvature from 8 x 8 patches of side ``a = L / 8``
  (a quadratic fit's second derivative, ``~ 4 sz / (a^2 sqrt(n_patch))``);
  the motion (a standard deviation over time) like the centroid. Set-up
  repeatability (``setup_mm``: where the pins and the camera are) adds to
  every position; ``curvature_floor`` to the curvature (size x 1/m).
  """
  size = c.size
  d = camera_distance(size)
  fp = 2 * d * np.tan(np.radians(HFOV_DEG / 2)) / WIDTH_PX
  sz = DEPTH_SD_1M * d**2
  t = clip_s * camera_fps
  n = (size / fp) ** 2
  edge = size / fp
  a = size / 8
  setup = setup_mm / 1000
  sd_m = np.array([
    np.hypot(sz / np.sqrt(n * t), setup),
    np.hypot(fp / np.sqrt(12 * 4 * edge * t), setup),
    np.hypot(sz / np.sqrt(edge * t), setup),
    np.hypot(fp / np.sqrt(12 * edge * t), setup),
    0.0,
    sz / np.sqrt(n * t),
  ])  # fmt: skip
  sd = sd_m / size
  curv = 4 * sz / (a**2 * np.sqrt(n / 64)) / np.sqrt(64 * t)  # 1/m
  sd[4] = np.hypot(curv * size, curvature_floor)
  if c.overhang:
    # A resting overhang does not move; the simulated one swings after its
    # release from flat, which says nothing a real recording could show.
    sd[5] = UNUSED_SD
  return sd


def timestep(c: Candidate) -> float:
  """The simulator's step for the candidate's mesh spacing h: the bending
  force is explicit, so its stable step shrinks as h^2 (MuJoCo C blew up at
  bending 4.5x on a 6 mm mesh at 2 ms; 12.5 mm held 10x)."""
  h = c.size / (c.resolution - 1)
  return 0.002 if h >= 0.0124 else 0.001 if h >= 0.008 else 0.0005


def sim_config(
  c: Candidate, config: Config, physics: physsim.Mismatch = physsim.mismatch.OWN
) -> physsim.SimConfig:
  """The simulator's settings for the candidate: at most ``timestep(c)``, the
  step and edges ``physsim.config_for_mesh`` gives its mesh; ``physics``'s
  edges, drag and damping (``physsim.Mismatch``; default the estimator's)."""
  fields = physics.sim_fields()
  return physsim.config_for_mesh(
    mesh(c), config.fps, timestep(c), fields.pop('edge_solref'),
    scaled_edges=config.scaled_edges, **fields,
  )  # fmt: skip


def mesh(c: Candidate) -> physsim.Mesh:
  """The candidate's square, pinned at its two top corners or the top-left.

  An overhang lies flat, reaching out along +y: its first two rows are held
  (the table clamps the slope too), row 1 on the table's edge at y = 0 and
  row 0 one spacing back on the table, so that ``size`` is the free overhang
  on every mesh (the square's side is ``size`` plus that spacing)."""
  if c.overhang:
    h = c.size / (c.resolution - 2)
    m = physsim.square(c.resolution, c.size + h)
    v = m.vertices
    top = v[:, 2].max()
    flat = np.stack([v[:, 0], top - v[:, 2] - h, np.full(len(v), top)], axis=1)
    return dataclasses.replace(
      m, vertices=flat, pinned=np.arange(2 * c.resolution), name=m.name + '_overhang'
    )
  m = physsim.square(c.resolution, c.size)
  if c.pins == 1:
    m = dataclasses.replace(m, pinned=m.pinned[:1], name=m.name + '_1pin')
  return m


def summaries(positions: np.ndarray, rest: np.ndarray, res: int, size: float):
  """(B, len(STATS)) statistics of (B, T, V, 3) positions of a res x res square
  (row 0 the pinned top edge) whose rest vertices are ``rest`` (V, 3), each
  divided by ``size`` (the curvature multiplied by it)."""
  x = np.asarray(positions, np.float64)
  b, t = x.shape[:2]
  g = x.reshape(b, t, res, res, 3)
  rest_up = rest[:, 2].mean()
  centroid = x.mean(axis=2)  # (B, T, 3)
  bottom = g[:, :, -1].mean(axis=2)  # (B, T, 3)
  h = float(np.linalg.norm(rest[1] - rest[0]))  # the spacing (row 0's first two)
  lap = (g[:, :, 2:, 1:-1] + g[:, :, :-2, 1:-1] + g[:, :, 1:-1, 2:] + g[:, :, 1:-1, :-2]
         - 4 * g[:, :, 1:-1, 1:-1]) / h**2  # fmt: skip
  curvature = np.linalg.norm(lap, axis=-1).mean(axis=(1, 2, 3))
  out = np.stack([
    centroid[:, :, 1].mean(1) / size,
    (centroid[:, :, 2].mean(1) - rest_up) / size,
    bottom[:, :, 1].mean(1) / size,
    (bottom[:, :, 2].mean(1) - rest[-1, 2]) / size,
    curvature * size,
    centroid[:, :, 1].std(1) / size,
  ], axis=1)  # fmt: skip
  return out


@dataclasses.dataclass(frozen=True)
class Config:
  """The protocol study.

  Attributes:
    material: the fabric.
    bendings: truths' bending scales (comma-separated).
    area_weight: the truths' area weight, kg/m^2 (0: the middle of the range).
    candidates: candidate recordings (``Candidate.name``s, comma-separated).
    convergence: candidates simulated at a finer mesh too, at the first truth
      (names, comma-separated; same size and wind, another resolution).
    sets: candidate sets ``label=name+name+...`` (semicolon-separated); the
      ``rNN`` suffix may be left off (the candidate's own resolution).
    gusts: RMS relative gust intensity of the noise replicates.
    draws: gust histories per candidate with wind (>= 3).
    clip: seconds summarised per recording.
    warmup: seconds simulated before the clip.
    fps: frames per second summarised.
    camera_fps: the depth camera's frame rate (its noise averages over it).
    step_bending: half-step of the central differences in log bending.
    step_area_weight: half-step of the central differences in log area weight.
    step_wind: half-step of the central differences in log wind speed.
    setup_mm: set-up repeatability added to every position statistic, mm.
    curvature_floor: floor of the curvature statistic's noise (size / m).
    shrink: weight of the gust covariance's diagonal (``bo.design.shrink``).
    reading: relative standard error of an anemometer's or scale's reading.
    drag_sd: prior standard deviation of the log of the wind force's
      coefficient, shared by a set's recordings in the fan: how far the
      simulator's drag law may be from the world's (``set_narrowing``; 0:
      trusted, as the first studies did).
    workers: MuJoCo C processes.
    seed: gust histories.
    scaled_edges: the edges' time constant shrinks with the spacing
      (``physsim.config_for_mesh``: the same stretch stiffness on every mesh
      and cloth size; the default); off: the fixed one of the first study.
    stats: the statistics the bound reads (names of ``STATS``,
      comma-separated; empty: all six). The estimate's shape distance reads
      the sheet's mean position alone (``centroid_out,centroid_up``); the
      slopes are simulated for all of them either way (one cache).
  """

  material: str = 'gray_interlock'
  bendings: tuple[str, ...] = ('0.3', '1', '3')
  area_weight: float = 0.0
  candidates: tuple[str, ...] = (
    'sheet_100cm_2ms_r9', 'sheet_100cm_3.5ms_r9', 'sheet_100cm_5ms_r9',
    'sheet_100cm_still_r9', 'overhang_3cm_r9', 'overhang_5cm_r9',
    'overhang_10cm_r9', 'swatch_20cm_2ms_r17',
  )  # fmt: skip
  convergence: tuple[str, ...] = (
    'overhang_5cm_r13', 'overhang_5cm_r17', 'swatch_20cm_2ms_r9',
  )  # fmt: skip
  sets: str = (
    'sheet 2 m/s=sheet_100cm_2ms;'
    'sheet 3.5 m/s=sheet_100cm_3.5ms;'
    'sheet 5 m/s=sheet_100cm_5ms;'
    'sheet still=sheet_100cm_still;'
    'swatch 20 2 m/s=swatch_20cm_2ms;'
    'overhang 3=overhang_3cm;'
    'overhang 5=overhang_5cm;'
    'overhang 10=overhang_10cm;'
    'overhang 3+5=overhang_3cm+overhang_5cm;'
    'sheet x3=sheet_100cm_2ms+sheet_100cm_3.5ms+sheet_100cm_5ms;'
    'sheet 2 + swatch 20=sheet_100cm_2ms+swatch_20cm_2ms;'
    'sheet 2 + overhang 5=sheet_100cm_2ms+overhang_5cm;'
    'sheet x3 + overhang 5=sheet_100cm_2ms+sheet_100cm_3.5ms+sheet_100cm_5ms+overhang_5cm;'
    'sheet x3 + overhangs 3+5=sheet_100cm_2ms+sheet_100cm_3.5ms+sheet_100cm_5ms'
    '+overhang_3cm+overhang_5cm'
  )
  gusts: float = 0.3
  draws: int = 6
  clip: float = 1.5
  warmup: float = 1.0
  fps: float = 20.0
  camera_fps: float = 30.0
  step_bending: float = 0.2
  step_area_weight: float = 0.05
  step_wind: float = 0.05
  setup_mm: float = 2.0
  curvature_floor: float = 0.05
  shrink: float = 0.5
  reading: float = 0.02
  drag_sd: float = 0.0
  workers: int = 1
  seed: int = 0
  scaled_edges: bool = True
  stats: tuple[str, ...] = ()


PRESETS = {
  # about 25 minutes on 16 cores (MuJoCo C, --workers=16): the overhangs' 3 cm
  # 1.5 min, the 20 cm swatch in wind 1.8 min a truth
  'default': Config(),
  # every candidate of the first study (10-30 cm swatches, still, one pin) as
  # well: about 40 minutes more on 16 cores
  'full': Config(
    candidates=Config.candidates
    + (
      'swatch_10cm_still_r9',
      'swatch_20cm_still_r9',
      'swatch_30cm_still_r9',
      'swatch_10cm_2ms_r13',
      'swatch_30cm_2ms_r17',
      'swatch_20cm_2ms_1pin_r17',
    ),
    convergence=Config.convergence
    + (
      'swatch_20cm_2ms_r25',
      'swatch_20cm_2ms_1pin_r9',
      'sheet_100cm_5ms_r17',
    ),
    sets=Config.sets
    + (
      ';swatch 10 2 m/s=swatch_10cm_2ms;swatch 30 2 m/s=swatch_30cm_2ms;'
      'swatch 20 still=swatch_20cm_still;swatch 20 1 pin=swatch_20cm_2ms_1pin;'
      'swatches 10+20+30 2 m/s=swatch_10cm_2ms+swatch_20cm_2ms+swatch_30cm_2ms'
    ),
  ),
  # the end-to-end path on a CPU in well under a minute: one truth, two tiny
  # candidates, short clips
  'smoke': Config(
    bendings=('1',),
    candidates=('swatch_20cm_still_r5', 'sheet_100cm_2ms_r5'),
    convergence=('swatch_20cm_still_r7',),
    sets='sheet=sheet_100cm_2ms;swatch=swatch_20cm_still;both=sheet_100cm_2ms+swatch_20cm_still',
    draws=3,
    clip=0.5,
    warmup=0.25,
  ),
}


def floats(name: str, values) -> list[float]:
  """A list flag's values as positive numbers; a ValueError naming the flag."""
  try:
    out = [float(v) for v in values]
  except ValueError:
    out = []
  if not out or not all(np.isfinite(v) and v > 0 for v in out):
    raise ValueError(f'--{name}={",".join(values)}: need positive numbers')
  return out


def parse_sets(text: str, names: list[str]) -> dict[str, list[str]]:
  """``label=a+b;...`` as {label: [candidate names]}, each resolved against
  ``names`` (a name without its ``_rNN`` suffix means the one listed). A
  member joined by ``&`` instead of ``+`` was recorded at the same fan
  setting as the one before it, the fan untouched (one wind for both): its
  name keeps a leading ``&`` (``shares_wind``)."""
  out = {}
  for item in filter(None, (s.strip() for s in text.split(';'))):
    label, _, members = item.partition('=')
    resolved = []
    for part in filter(None, members.split('+')):
      for j, m in enumerate(part.split('&')):
        hits = [n for n in names if n == m or n.rsplit('_r', 1)[0] == m]
        if len(hits) != 1:
          raise ValueError(f'--sets: {m!r} in {label!r} is not one of --candidates')
        if j and not (0 < parse(hits[0]).wind == parse(resolved[-1]).wind):
          raise ValueError(
            f'--sets: {m!r} in {label!r} shares the wind (&) of a recording at '
            'another fan setting, or of one without a fan'
          )
        resolved.append(('&' if j else '') + hits[0])
    if not label or not resolved:
      raise ValueError(f'--sets: {item!r} is not label=candidate+candidate')
    out[label.strip()] = resolved
  return out


def shares_wind(member: str) -> tuple[str, bool]:
  """A ``parse_sets`` member: its candidate's name, and whether it shares the
  wind of the member before it."""
  return member.removeprefix('&'), member.startswith('&')


def robust_slope(near, far, scramble=0.0) -> np.ndarray:
  """Central-difference slopes at a step and at twice it, combined: the wider
  one, shrunk towards 0 by its error, estimated as the larger of how much the
  two disagree and ``scramble`` (the slope a nudge far below the step makes
  look like, divided by the step): ``far * max(0, 1 - err^2 / far^2)``. A
  smooth statistic keeps its slope; one whose clip mean the flapping
  scrambles (a flag in steady wind) loses it, instead of reporting the
  scramble divided by the step as information."""
  near, far = np.asarray(near, np.float64), np.asarray(far, np.float64)
  err = np.maximum(np.abs(near - far), np.asarray(scramble, np.float64))
  with np.errstate(divide='ignore', invalid='ignore'):
    keep = np.clip(1 - err**2 / far**2, 0, 1)
  return np.where(far == 0, 0.0, far * np.nan_to_num(keep))


def simulate_candidate(c: Candidate, bending: float, area_weight: float,
                       config: Config, key) -> dict:  # fmt: skip
  """Slopes (m, p) and noise covariance (m, m) of one candidate at one truth;
  p = 3 with wind, 2 without (no wind parameter). Steady wind at +-1 and +-2
  steps of each parameter and at +-``CHAOS_NUDGE`` of log bending
  (``robust_slope``), ``draws`` gusty histories at the truth."""
  m = mesh(c)
  model = _model(c, config)
  sim = model.config
  common = _steady_kwargs(config)
  steps = [config.step_bending, config.step_area_weight, config.step_wind]
  p = 3 if c.wind > 0 else 2
  base = np.log([bending, area_weight, max(c.wind, 1e-9)])
  points = []
  for i in range(p):
    for sign in (-2, -1, 1, 2):
      x = base.copy()
      x[i] += sign * steps[i]
      points.append(np.exp(x))
  for sign in (-1, 1):  # the chaos probe: a nudge of 1e-3 in log bending
    points.append(np.exp(base + sign * np.array([CHAOS_NUDGE, 0, 0])))
  points = np.array(points)
  winds = points[:, 2] if c.wind > 0 else np.zeros(len(points))
  steady = physsim.simulate(
    model, physsim.params.make(points[:, 0], winds, points[:, 1]), **common
  )
  if not np.all(steady.valid):
    raise RuntimeError(f'{c.name}: a steady simulation blew up at bending {bending}')
  out = summaries(steady.positions, m.vertices, c.resolution, c.size)
  s, nudged = out[:-2].reshape(p, 4, -1), out[-2:]
  h = np.array(steps[:p])[:, None]
  near = ((s[:, 2] - s[:, 1]) / (2 * h)).T  # (m, p)
  far = ((s[:, 3] - s[:, 0]) / (4 * h)).T
  # what a nudge far below any step does: smooth statistics move by ~0, ones
  # the flapping scrambles by their whole scatter, whatever the step
  scramble = np.abs(nudged[1] - nudged[0])  # (m,)
  jac = robust_slope(near, far, (scramble[None] / (4 * h)).T)
  if c.overhang:
    # A resting overhang's shape solves D (laplacian^2) u = w g: it depends on
    # D / w alone, so its slope in log area weight is minus its slope in log
    # bending. The simulated strip, released from flat, still swings through
    # the clip, and the air's drag on the swing (which does not scale with w)
    # would show area weight that a resting strip cannot.
    jac[:, 1] = -jac[:, 0]
  gust_cov = np.zeros((len(STATS), len(STATS)))
  gust_sd = np.zeros(len(STATS))
  if c.wind > 0 and config.draws > 0:
    gusty = physsim.simulate(
      model,
      physsim.params.make(bending, np.full(config.draws, c.wind), area_weight),
      wind=physsim.Wind(gust_intensity=config.gusts),
      key=key,
      **common,
    )
    if not np.all(gusty.valid):
      raise RuntimeError(f'{c.name}: a gusty simulation blew up')
    g = summaries(gusty.positions, m.vertices, c.resolution, c.size)
    gust_cov = design.shrink(np.cov(g, rowvar=False), config.shrink)
    gust_sd = g.std(axis=0, ddof=1)
  sensor = sensor_sd(c, config.clip, config.camera_fps, config.setup_mm,
                     config.curvature_floor)  # fmt: skip
  cov = gust_cov + np.diag(sensor**2)
  return {
    'candidate': c.name, 'bending': bending, 'area_weight': area_weight,
    'wind': c.wind, 'timestep': sim.timestep, 'edge_solref': sim.edge_solref,
    'params': list(PARAMS[:p]), 'slopes': jac.tolist(),
    'noise_cov': cov.tolist(), 'gust_sd': gust_sd.tolist(),
    'sensor_sd': sensor.tolist(), 'camera_distance_m': camera_distance(c.size),
    'summary': out.mean(axis=0).tolist(),
    'slope_near': near.tolist(), 'slope_far': far.tolist(),
    'scramble': scramble.tolist(),
  }  # fmt: skip


# Config fields a cached slope file depends on besides its name's own.
_SLOPE_FIELDS = ('gusts', 'draws', 'clip', 'warmup', 'fps', 'camera_fps',
                 'step_bending', 'step_area_weight', 'step_wind', 'setup_mm',
                 'curvature_floor', 'shrink', 'seed')  # fmt: skip


def _slope_digest(config: Config) -> str:
  """'' at the default settings, else '_' and a short digest of those of
  ``_SLOPE_FIELDS`` that differ from them."""
  default = Config()
  changed = {
    f: getattr(config, f)
    for f in _SLOPE_FIELDS
    if getattr(config, f) != getattr(default, f)
  }
  if not changed:
    return ''
  return (
    '_' + hashlib.sha1(json.dumps(changed, sort_keys=True).encode()).hexdigest()[:8]
  )


def _stem(c: Candidate, bending: float, area_weight: float, config: Config) -> str:
  """A cached file's name for the candidate at a truth, under ``config``."""
  return (
    f'{config.material}_{c.name}_b{bending:.4g}_w{area_weight:.4g}'
    f'{"" if config.scaled_edges else "_fixed_edges"}{_slope_digest(config)}'
  )


def _model(c: Candidate, config: Config,
           physics: physsim.Mismatch = physsim.mismatch.OWN) -> physsim.ClothModel:  # fmt: skip
  """The candidate's compiled cloth under ``physics``, its hem attached."""
  m = mesh(c)
  hem = physsim.hem_mass(m, c.resolution, c.hem / 1000) if c.hem > 0 else None
  return physsim.build(
    m, config.material, sim_config(c, config, physics), extra_mass=hem
  )


def _steady_kwargs(config: Config) -> dict:
  """``physsim.simulate``'s clip and backend settings of the study."""
  return dict(frames=round(config.clip * config.fps), fps=config.fps,
              warmup=config.warmup, backend='c', workers=config.workers,
              space=SPACE)  # fmt: skip


def slope_path(c: Candidate, bending: float, area_weight: float, config: Config,
               cache_dir: str) -> str:  # fmt: skip
  """Where ``candidate_slopes`` caches the candidate's slopes at a truth."""
  return os.path.join(
    cache_dir, f'{_stem(c, bending, area_weight, config)}_v{CACHE_VERSION}.json'
  )


def _cached_slopes(path: str) -> dict:
  """A cached slope file, checked: a damaged one (its writes are atomic, so
  damaged after) is refused naming it rather than ranked as garbage.

  Raises:
    ValueError: naming the file and how to recompute it.
  """
  why = ''
  try:
    out = physsim.dataset.read_json(path)
  except ValueError as e:
    out, why = None, str(e).removeprefix(f'{path}: ')[:100]
  if out is not None:
    try:
      slopes = np.asarray(out['slopes'], np.float64)
      cov = np.asarray(out['noise_cov'], np.float64)
      float(out['wind'])
    except (KeyError, TypeError, ValueError):
      why = 'no slopes, noise_cov and wind'
    else:
      m = slopes.shape[0] if slopes.ndim == 2 else -1
      if cov.shape != (m, m) or not (
        np.isfinite(slopes).all() and np.isfinite(cov).all()
      ):
        why = f'slopes {slopes.shape} and noise_cov {cov.shape} do not fit or are not finite'
  if why:
    raise ValueError(
      f'{path}: a damaged cached slope file ({why}); delete it to recompute'
    )
  return out


def candidate_slopes(c: Candidate, bending: float, area_weight: float,
                     config: Config, cache_dir: str, key) -> dict:  # fmt: skip
  """``simulate_candidate``, cached as JSON under ``cache_dir`` (a rerun, or
  ``experiments.plan``, reuses it). The file's name carries every setting that
  changes what is simulated or how its noise is read (``_SLOPE_FIELDS``; a
  short digest of those that differ from the defaults), so that a study of
  other clips never reads another's slopes."""
  path = slope_path(c, bending, area_weight, config, cache_dir)
  if os.path.exists(path):
    return _cached_slopes(path)
  t0 = time.time()
  out = simulate_candidate(c, bending, area_weight, config, key)
  out['seconds'] = time.time() - t0
  files.write_json(path, out)
  return out


WORLD_VERSION = 1  # bump when what a cached world file means changes


def world_residual(c: Candidate, bending: float, area_weight: float, config: Config,
                   cache_dir: str, physics: physsim.Mismatch = physsim.mismatch.WORLD
                   ) -> list[float]:  # fmt: skip
  """(len(STATS),) what ``physics`` (a world unlike the estimator's simulator,
  ``physsim.mismatch``) shows minus what the estimator's own simulator shows,
  in steady wind at the truth: the statistics' misfit that a fit with the
  estimator's simulator turns into bias (``set_bias``). Cached as JSON beside
  the slopes."""
  name = (
    f'{_stem(c, bending, area_weight, config)}_world{physics.fan_yaw_deg:g}_'
    f'{physics.air_drag:g}_{physics.bending_damping:g}_{physics.edge_solref_scale:g}'
    f'_v{WORLD_VERSION}.json'
  )
  path = os.path.join(cache_dir, name)
  if os.path.exists(path):
    with open(path) as f:
      return json.load(f)['residual']
  m = mesh(c)
  params = physsim.params.make(bending, c.wind, area_weight)
  stats = []
  for phys in (physsim.mismatch.OWN, physics):
    out = physsim.simulate(
      _model(c, config, phys), params, wind=phys.wind(0.0), **_steady_kwargs(config)
    )
    if not np.all(out.valid):
      raise RuntimeError(f'{c.name}: a steady simulation blew up at bending {bending}')
    stats.append(summaries(out.positions, m.vertices, c.resolution, c.size)[0])
  residual = (stats[1] - stats[0]).tolist()
  files.write_json(path, {'candidate': c.name, 'bending': bending,
                          'area_weight': area_weight, 'residual': residual})  # fmt: skip
  return residual


def priors(material: str, reading: float) -> dict[str, float]:
  """Prior standard deviations in log space: the search box's (bending 0.1-10x,
  the fabric's area-weight range, wind 1-6 m/s) and a reading's."""
  space = physsim.search_space(material)
  return {
    'log_bending': design.log_box_sd(*space.bending_scale),
    'log_area_weight': design.log_box_sd(*space.area_weight),
    'log_wind': design.log_box_sd(*space.wind_speed),
    'reading': float(np.log1p(reading)),
  }


def stat_index(stats) -> list[int] | slice:
  """Indices into ``STATS`` of the statistics ``stats`` names (every row:
  none named); a ValueError naming an unknown or repeated one."""
  unknown = [x for x in stats if x not in STATS]
  if unknown or len(set(stats)) < len(stats):
    raise ValueError(f'--stats={",".join(stats)}: need distinct names of {list(STATS)}')
  return [STATS.index(x) for x in stats] if stats else slice(None)


def _assemble(rows, prior, mode, shared, drag_sd):
  """The set's parameters and each recording's slopes on them: (the prior
  sds (n,), per recording (slopes (m, p_k), its parameters' indices))."""
  shared = list(shared) if shared is not None else [False] * len(rows)
  windy = [r['wind'] > 0 for r in rows]
  n_wind = sum(w and not s for w, s in zip(windy, shared, strict=True))
  drag = drag_sd > 0 and any(windy)
  n = 2 + n_wind + int(drag)
  parts = []
  k = 1
  for r, w, s in zip(rows, windy, shared, strict=True):
    slopes = np.array(r['slopes'])
    index = [0, 1]
    if w:
      k += 0 if s else 1
      index.append(k)
      if drag:
        slopes = np.concatenate([slopes, 0.5 * slopes[:, 2:3]], axis=1)
        index.append(n - 1)
    parts.append((slopes, index))
  sd = np.full(n, prior['log_wind'] if mode != 'anemometer' else prior['reading'])
  sd[0] = prior['log_bending']
  sd[1] = prior['reading'] if mode == 'scale' else prior['log_area_weight']
  if drag:
    sd[-1] = drag_sd
  return sd, parts


def _information(rows, prior, mode, shared, drag_sd, stats=()):
  """``_assemble``'s prior sds and parts (each recording's slopes on the
  statistics ``stats`` read, ``stat_index``), and the set's Fisher
  information."""
  sd, parts = _assemble(rows, prior, mode, shared, drag_sd)
  idx = stat_index(stats)
  parts = [(j[idx], i) for j, i in parts]
  infos = [
    design.fisher(j, np.array(r['noise_cov'])[idx][:, idx])
    for (j, _), r in zip(parts, rows, strict=True)
  ]
  return sd, parts, design.combine(infos, [i for _, i in parts], len(sd))


def set_narrowing(rows: list[dict], prior: dict[str, float], mode: str,
                  shared=None, drag_sd: float = 0.0, stats=()) -> dict:  # fmt: skip
  """Narrowing of log bending and log area weight by the recordings ``rows``
  (each ``simulate_candidate``'s dict) together, in ``mode``: ``'video'``,
  ``'anemometer'`` (every wind read) or ``'scale'`` (area weight read).

  ``shared``: per row, whether it was recorded at the fan setting of the row
  before it (one wind parameter for both). ``drag_sd``: the prior standard
  deviation of the log of the wind force's coefficient, one for every
  recording in the fan: what the simulator's drag law gets wrong about the
  world (0: nothing). The force goes as that coefficient times v^2, and the
  slopes are taken in steady wind with the cloth at rest, so a recording's
  slope in it is half its slope in log wind. ``stats``: the statistics read
  (``stat_index``; all by default)."""
  sd, _, total = _information(rows, prior, mode, shared, drag_sd, stats)
  n = len(sd)
  post = design.widths(sd, total)
  no_video = design.widths(sd, np.zeros((n, n)))
  return {
    'bending': float(prior['log_bending'] / post[0]),
    'area_weight': float(prior['log_area_weight'] / post[1]),
    'bending_sd_log': float(post[0]),
    'area_weight_sd_log': float(post[1]),
    'area_weight_without_video': float(prior['log_area_weight'] / no_video[1]),
  }


def set_bias(rows: list[dict], residuals: list, prior: dict[str, float], mode: str,
             shared=None, drag_sd: float = 0.0, stats=()) -> dict:  # fmt: skip
  """What a fit with the estimator's simulator makes of recordings of another
  physics, to first order: the shift of the posterior mean of (log bending,
  log area weight) that the statistics' misfit ``residuals`` (per row,
  ``world_residual``) causes, (F + P)^-1 sum_k J_k^T R_k^-1 r_k, beside the
  posterior's sd (``set_narrowing``'s model of the set, on ``stats``)."""
  sd, parts, info = _information(rows, prior, mode, shared, drag_sd, stats)
  idx = stat_index(stats)
  score = np.zeros(len(sd))
  for (j, index), r, res in zip(parts, rows, residuals, strict=True):
    score[index] += j.T @ np.linalg.solve(
      np.array(r['noise_cov'])[idx][:, idx], np.asarray(res, float)[idx]
    )
  cov = np.linalg.inv(info + np.diag(1.0 / sd**2))
  shift = cov @ score
  post = np.sqrt(np.diag(cov))
  return {
    'bending_bias_log': float(shift[0]),
    'area_weight_bias_log': float(shift[1]),
    'area_weight_sd_log': float(post[1]),
    'area_weight_z': float(shift[1] / post[1]),
  }


def run(config: Config, workdir: str) -> dict:
  """Simulates every candidate at every truth, evaluates the sets, writes
  ``protocol.json`` and ``protocol.png`` to ``workdir``; returns the result."""
  bendings = floats('bendings', config.bendings)
  if config.draws < 3 or not config.clip > 0:
    raise ValueError(
      f'need --draws >= 3 and --clip > 0, got {config.draws}, {config.clip}'
    )
  if not (np.isfinite(config.drag_sd) and config.drag_sd >= 0):
    raise ValueError(f'--drag_sd={config.drag_sd}: need a number >= 0 (0: trusted)')
  stat_index(config.stats)  # an unknown name refused before any simulation
  cands = [parse(n) for n in config.candidates]
  conv = [parse(n) for n in config.convergence]
  sets = parse_sets(config.sets, list(config.candidates))
  space = physsim.search_space(config.material)
  w = config.area_weight or float(space.center().area_weight)
  cache = os.path.join(workdir, CACHE_DIR)
  key = jax.random.key(config.seed)
  t0 = time.time()
  slopes = {}
  jobs = [(c, b) for b in bendings for c in cands] + [(c, bendings[0]) for c in conv]
  for i, (c, b) in enumerate(jobs):
    row = candidate_slopes(c, b, w, config, cache, jax.random.fold_in(key, i))
    slopes[(c.name, b)] = row
    print(f'[{i + 1}/{len(jobs)}] {c.name} at bending {b:g}: '
          f'{row.get("seconds", 0):.0f} s ({time.time() - t0:.0f} s so far)', flush=True)  # fmt: skip
  prior = priors(config.material, config.reading)
  table = []
  for label, members in sets.items():
    names, shared = zip(*map(shares_wind, members), strict=True)
    for b in bendings:
      rows = [slopes[(n, b)] for n in names]
      entry = {'set': label, 'members': members, 'bending_truth': b}
      for mode in MODES:
        entry[mode] = set_narrowing(
          rows, prior, mode, shared, config.drag_sd, config.stats
        )
      table.append(entry)
  convergence = []
  for c in conv:
    coarse = [
      n for n in config.candidates if n.rsplit('_r', 1)[0] == c.name.rsplit('_r', 1)[0]
    ]
    for n in coarse:
      pair = {}
      for name in (n, c.name):
        r = slopes[(name, bendings[0])]
        pair[name] = {
          mode: set_narrowing([r], prior, mode, stats=config.stats) for mode in MODES
        } | {'slope_log_bending': [s[0] for s in r['slopes']],
             'noise_sd': np.sqrt(np.diag(r['noise_cov'])).tolist()}  # fmt: skip
      convergence.append(pair)
  result = {
    'material': config.material, 'area_weight': w, 'bendings': bendings,
    'priors_sd_log': prior, 'stats': list(config.stats or STATS),
    'table': table,
    'convergence': convergence,
    'overhang_vs_elastica': against_elastica(
      [r for r in slopes.values() if parse(r['candidate']).overhang], config.material
    ),
    'camera_distance_m': {c.name: camera_distance(c.size) for c in cands},
    'slopes': [slopes[k] for k in slopes],
    'seconds': time.time() - t0,
    # each candidate's own simulation time, summed: the run's from scratch
    'simulation_seconds': float(sum(r.get('seconds', 0.0) for r in slopes.values())),
    'config': dataclasses.asdict(config),
  }  # fmt: skip
  files.write_json(os.path.join(workdir, RESULT_FILE), result)
  summary = {k: v for k, v in result.items() if k != 'slopes'}
  summary['table'] = [
    {k: (v if k not in MODES else {f: v[f] for f in ('bending', 'area_weight')})
     for k, v in e.items()}
    for e in result['table']
  ]  # fmt: skip
  summary['convergence'] = [
    {n: {m: r[m] for m in MODES} for n, r in pair.items()} for pair in convergence
  ]
  files.write_json(os.path.join(workdir, SUMMARY_FILE), summary)
  plot(result, os.path.join(workdir, FIGURE_FILE))
  return result


def elastica_check(
  overhang: float, bending: float, area_weight: float, reach: float, d0: float
) -> dict:
  """A simulated overhang's tip (``reach`` over the ``overhang``) against the
  heavy elastica of its nominal rigidity D = ``bending`` x ``d0``
  (``physsim.cantilever``): its bending length, both reaches, and the rigidity
  whose elastica reaches as far as the simulation, over D. The last two are
  None for an overhang of more than ``cantilever.MAX_RATIO`` bending lengths
  (hanging straight down), the ratio also beyond the elastica's range."""
  c = float(physsim.params.bending_length(bending, area_weight, d0))
  row = {
    'bending': bending, 'bending_length_cm': float(100 * c),
    'overhang_over_c': float(overhang / c), 'elastica_reach': None,
    'simulated_reach': float(reach), 'rigidity_ratio': None,
  }  # fmt: skip
  if overhang / c > cantilever.MAX_RATIO:
    return row
  row['elastica_reach'] = float(cantilever.tip(overhang / c)[0][0])
  try:
    found = cantilever.bending_length(overhang, reach * overhang)
    row['rigidity_ratio'] = float((found / c) ** 3)
  except ValueError:  # a reach beyond what the elastica's range covers
    pass
  return row


def against_elastica(rows: list[dict], material: str) -> list[dict]:
  """``elastica_check`` of each simulated overhang (slope rows: its clip's mean
  tip reach is ``summary[2]``), those within the elastica's range."""
  d0 = physsim.reference_rigidity(physsim.fabric(material).material)
  out = []
  for r in rows:
    size = parse(r['candidate']).size
    row = elastica_check(size, r['bending'], r['area_weight'], r['summary'][2], d0)
    if row['elastica_reach'] is not None:
      out.append({'candidate': r['candidate'], **row})
  return out


def geomean_range(table, label, mode, field):
  v = np.array([e[mode][field] for e in table if e['set'] == label])
  return float(np.exp(np.log(v).mean())), float(v.min()), float(v.max())


def plot(result: dict, path: str) -> None:
  """Bars: narrowing per candidate set, bending and area weight, per mode
  (geometric mean over truths, whiskers their range)."""
  table = result['table']
  labels = list(dict.fromkeys(e['set'] for e in table))
  fig, axes = plt.subplots(1, len(MODES), figsize=(5 * len(MODES), 0.35 * len(labels) + 2),
                           sharey=True)  # fmt: skip
  y = np.arange(len(labels))
  for ax, mode in zip(axes, MODES, strict=True):
    for off, field, color in ((-0.2, 'bending', 'C0'), (0.2, 'area_weight', 'C1')):
      stats = np.array([geomean_range(table, s, mode, field) for s in labels])
      ax.barh(y + off, stats[:, 0], height=0.4, color=color, label=field.replace('_', ' '),
              xerr=np.maximum(0, [stats[:, 0] - stats[:, 1], stats[:, 2] - stats[:, 0]]),
              capsize=2)  # fmt: skip
    ax.axvline(1, color='k', lw=0.8)
    ax.set_xscale('log')
    ticks = [1, 1.5, 2, 3, 4, 6, 10, 20, 40]
    ax.set_xticks(ticks, [f'{t:g}' for t in ticks])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_title({'video': 'video alone', 'anemometer': 'winds read to 2%',
                  'scale': 'area weight weighed to 2%'}[mode])  # fmt: skip
    ax.set_xlabel("prior's 90% width / posterior's")
  axes[0].set_yticks(y, labels)
  axes[0].invert_yaxis()
  axes[-1].legend(loc='lower left')
  b = ', '.join(f'{v:g}' for v in result['bendings'])
  fig.suptitle(f'{result["material"]}: Cramer-Rao narrowing of bending and area weight '
               f'(bending truths {b}; bars: geometric mean, whiskers: range)')  # fmt: skip
  fig.tight_layout()
  files.savefig(fig, path)
  plt.close(fig)


def markdown(result: dict) -> str:
  """The narrowing table (geometric mean over truths, range in brackets)."""
  lines = ['| set | mode | bending | area weight |', '|---|---|---:|---:|']
  labels = list(dict.fromkeys(e['set'] for e in result['table']))
  for s in labels:
    for mode in MODES:
      cells = []
      for field in ('bending', 'area_weight'):
        g, lo, hi = geomean_range(result['table'], s, mode, field)
        cells.append(f'{g:.2f} ({lo:.2f}-{hi:.2f})')
      lines.append(f'| {s} | {mode} | {cells[0]} | {cells[1]} |')
  return '\n'.join(lines)


def convergence_line(pair: dict) -> str:
  """One line: a candidate's narrowing (video; winds read) at two meshes."""
  parts = []
  for name, r in pair.items():
    parts.append(
      f'{name}: bending x{r["video"]["bending"]:.2f} '
      f'(winds read x{r["anemometer"]["bending"]:.2f}), '
      f'area weight x{r["video"]["area_weight"]:.2f} '
      f'(winds read x{r["anemometer"]["area_weight"]:.2f})'
    )
  return '; '.join(parts)


# ------------------------------------------------- what to record next (item 4)

PLAN_FILE = 'plan.json'
PLAN_CACHE_DIR = 'plan_slopes'
# the study's meshes: a swatch needs ~1.25 cm (or finer) to show bending at all
PLAN_CANDIDATES = (
  'sheet_100cm_2ms_r9', 'sheet_100cm_3.5ms_r9', 'sheet_100cm_5ms_r9',
  'swatch_10cm_2ms_r13', 'swatch_20cm_2ms_r17', 'swatch_30cm_2ms_r17',
  'swatch_20cm_still_r9', 'overhang_3cm_r9', 'overhang_5cm_r9',
)  # fmt: skip


def node_values(draws: np.ndarray, nodes: int) -> np.ndarray:
  """(K, 2) points where slopes are simulated: the posterior median of log
  area weight and K quantiles of log bending (its effect is the most
  nonlinear), kept where the finite differences stay inside the box."""
  q = (np.arange(nodes) + 0.5) / nodes
  b = np.quantile(draws[:, 0], q)
  w = np.full(nodes, np.median(draws[:, 1]))
  b = np.clip(b, np.log(0.1) + 0.41, np.log(10) - 0.41)  # +-2 steps of 0.2
  w = np.clip(
    w, np.log(SPACE.area_weight[0]) + 0.11, np.log(SPACE.area_weight[1]) - 0.11
  )
  return np.stack([b, w], axis=1)


def rank_candidates(draws, weights, rows_per_node: dict[str, list[dict]], nodes,
                    reading: float, material: str) -> list[dict]:  # fmt: skip
  """Expected information gain about (log bending, log area weight) of each
  candidate from the current posterior draws (``bo.design.expected_gain``),
  each draw using the slopes of its nearest node; a new fan setting's wind is
  a nuisance with the box's prior, or a reading's (``reading`` > 0).

  Returns:
    One dict per candidate, the most informative first: ``candidate``,
    ``eig_nats``, and the posterior standard deviations of log bending and
    log area weight now and after (Laplace, at the draws' covariance).
  """
  prior = priors(material, reading or 0.02)
  wind_sd = prior['reading'] if reading > 0 else prior['log_wind']
  near = design.nearest(draws, nodes)
  _, cov = design.weighted_cov(draws, weights)
  out = []
  for name, rows in rows_per_node.items():
    infos = np.stack([
      design.fisher(np.array(r['slopes']), np.array(r['noise_cov'])) for r in rows
    ])[near]  # fmt: skip
    q = [wind_sd] if rows[0]['wind'] > 0 else []
    gain = design.expected_gain(draws, weights, infos, nuisance_sd=q, keep=[0, 1])
    s = np.zeros((2 + len(q),) * 2)
    s[:2, :2] = cov
    s[2:, 2:] = np.diag(np.square(q))
    mean_info = np.einsum('s,sij->ij', weights / weights.sum(), infos)
    after = np.sqrt(np.diag(design.posterior_cov(s, mean_info)))[:2]
    out.append({
      'candidate': name, 'eig_nats': gain,
      'sd_log_bending': [float(np.sqrt(cov[0, 0])), float(after[0])],
      'sd_log_area_weight': [float(np.sqrt(cov[1, 1])), float(after[1])],
    })  # fmt: skip
  return sorted(out, key=lambda r: -r['eig_nats'])


def describe(name: str, clip: float) -> str:
  """A candidate in words a person can act on."""
  c = parse(name)
  if c.overhang:
    return (
      f'the fabric flat on a table, {100 * c.size:.0f} cm of it over the edge, '
      f'still air, the camera {camera_distance(c.size):.2f} m in front of the edge '
      '20-40 degrees above the table, a few still frames (python -m '
      'experiments.overhang --depth reads it)'
    )
  fan = f'the fan at {c.wind:g} m/s' if c.wind > 0 else 'no fan'
  pins = 'its two top corners' if c.pins == 2 else 'one top corner'
  return (
    f'a {100 * c.size:.0f} cm square pinned at {pins}, {fan}, the camera '
    f'{camera_distance(c.size):.2f} m away, {clip:g} s'
  )


# What experiments.plan may ask, checked before anything is read or simulated:
# each candidate and node is up to a minute of MuJoCo C on two cores.
PLAN_LIMITS = {'candidates': (1, 32), 'nodes': (1, 16), 'draws': (3, 64)}
PLAN_CLIP_S = (0.25, 10.0)
PLAN_READING = (0.0, 1.0)


def check_plan(candidates, nodes: int, reading: float, config: Config) -> None:
  """Refuses what ``plan`` cannot do sensibly, before anything is allocated:
  counts outside ``PLAN_LIMITS`` (fewer than 3 gust histories give no noise
  covariance, so any candidate looks informative), a clip outside
  ``PLAN_CLIP_S``, a reading outside ``PLAN_READING``, a candidate that is
  not one.

  Raises:
    ValueError: naming the flag and its value.
  """
  counts = {'candidates': len(candidates), 'nodes': nodes, 'draws': config.draws}
  for name, value in counts.items():
    lo, hi = PLAN_LIMITS[name]
    if isinstance(value, bool) or not lo <= value <= hi:
      what = f'{value} given' if name == 'candidates' else str(value)
      raise ValueError(f'--{name}={what}: need {lo} to {hi}')
  lo, hi = PLAN_CLIP_S
  if not lo <= config.clip <= hi:
    raise ValueError(f'--clip={config.clip:g}: need {lo:g} to {hi:g} s')
  lo, hi = PLAN_READING
  if not lo <= reading <= hi:
    raise ValueError(f'--reading={reading:g}: need {lo:g} to {hi:g} (relative sd)')
  twice = sorted({n for n in candidates if list(candidates).count(n) > 1})
  if twice:
    raise ValueError(f'--candidates: {twice[0][:64]} listed twice')
  for name in candidates:
    if len(name) > 64:
      raise ValueError(f'--candidates: a name of {len(name)} characters is none')
    try:
      parse(name)
    except ValueError as e:
      raise ValueError(f'--candidates: {e}') from None


def plan(workdir: str, candidates=PLAN_CANDIDATES, nodes: int = 1,
         reading: float = 0.0, config: Config | None = None, *,
         show_progress: bool = True) -> dict:  # fmt: skip
  """Ranks ``candidates`` for the estimate in ``workdir`` (``layout.read_draws``);
  slopes simulated at ``nodes`` posterior points with ``config``'s settings,
  cached in ``<workdir>/plan_slopes/``, with a progress bar and its time left
  (``show_progress``); writes ``plan.json``.

  Raises:
    ValueError: settings ``check_plan`` refuses, or an estimate's files that
      are missing or unreadable (named).
  """
  config = config or Config()
  check_plan(candidates, nodes, reading, config)
  material, draws, weights = layout.read_draws(workdir)
  config = dataclasses.replace(config, material=material)
  points = node_values(draws, nodes)
  cache = os.path.join(
    workdir,
    PLAN_CACHE_DIR,
    f'clip{config.clip:g}_draws{config.draws}_seed{config.seed}',
  )
  key = jax.random.key(config.seed)
  jobs = [
    (name, k, float(np.exp(b)), float(np.exp(w)))
    for name in candidates
    for k, (b, w) in enumerate(points)
  ]
  cached = [
    os.path.exists(slope_path(parse(name), b, w, config, cache))
    for name, _, b, w in jobs
  ]  # fmt: skip
  rows = {name: [] for name in candidates}
  with progress.Bar(len(jobs), 'plan: slopes', 'sim', disable=not show_progress) as bar:
    bar.skip(sum(cached))  # read back, not timed
    for (name, k, bending, area_weight), done in zip(jobs, cached, strict=True):
      rows[name].append(
        candidate_slopes(
          parse(name), bending, area_weight, config, cache, jax.random.fold_in(key, k)
        )
      )
      if not done:
        bar.done(1)
  ranked = rank_candidates(draws, weights, rows, points, reading, material)
  best = ranked[0]
  line = recommendation(best, config.clip)
  result = {'material': material, 'nodes': np.exp(points).tolist(),
            'reading': reading, 'ranked': ranked, 'recommendation': line}  # fmt: skip
  files.write_json(os.path.join(workdir, PLAN_FILE), result)
  return result


def recommendation(best: dict, clip: float) -> str:
  """The one line: what to record next and what it should give."""
  nb = best['sd_log_bending'][0] / best['sd_log_bending'][1]
  nw = best['sd_log_area_weight'][0] / best['sd_log_area_weight'][1]
  if best['eig_nats'] < 0.05:
    return ('Next recording: none of the candidates narrows bending or area weight '
            f'much (best {best["eig_nats"]:.2f} nats); weigh the fabric instead.')  # fmt: skip
  return (
    f'Next recording: {describe(best["candidate"], clip)} '
    f'(expected gain {best["eig_nats"]:.2f} nats: bending x{nb:.2f}, '
    f'area weight x{nw:.2f} narrower; a Fisher bound).'
  )


def plan_table(result: dict) -> str:
  lines = ['| candidate | EIG (nats) | bending sd (log) now -> after | '
           'area weight sd (log) now -> after |', '|---|---:|---:|---:|']  # fmt: skip
  for r in result['ranked']:
    b, w = r['sd_log_bending'], r['sd_log_area_weight']
    lines.append(f'| {r["candidate"]} | {r["eig_nats"]:.3f} | {b[0]:.3f} -> {b[1]:.3f} '
                 f'| {w[0]:.3f} -> {w[1]:.3f} |')  # fmt: skip
  return '\n'.join(lines)
