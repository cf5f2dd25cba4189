"""A predictive check of an exported fabric on a recording it was not estimated from.

``experiments.export`` writes a fabric for a mesh; this asks whether that
fabric, simulated in another recording's set-up (its camera, its sheet, its
anemometer's wind), hangs where the recording's sheet hangs. The comparison is
the estimate's own shape distance (``physsim.shape``: the clip's mean place of
the visible cloth in the world, through the recording's camera and the depth
sensor's model), so its scale is the gusts' own: the recording is one gust
history, and so is every simulation. The check therefore reads the distance
of the prediction from the recording against its **noise floor**: the same
fabric simulated with other gust seeds, whose summaries lie that far from each
other (the RMS over pairs; a correct fabric lies from the recording about as
far as its seeds lie from each other, a ratio near 1), and against a default
fabric of the library (the export's material at its ArcSim bending and the
paper's measured area weight) in the same worlds.

The recording is taken in as an estimate takes it (``intake.take_in``: its
camera file, background removed, pins found, the camera placed in the
simulator's world) and the worlds simulated, rendered and summarised by the
estimate's own objective (``objective.Objective`` with the shape distance);
what is new here is only which parameters are simulated and how the distances
are read. The exported fabric is simulated as the estimator's cloth at the
export's mesh and bending scale, which the exported MJCF is (``physsim.export``,
tested against the estimator's MuJoCo C rollout).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import re

import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline import (
  embedding,
  fabric_files,
  files,
  intake,
  intake_files,
  layout,
)
from experiments.pipeline import objective as objective_lib
from physsim import bags

RESULT_FILE = 'validate.json'
FIGURE_FILE = 'validate.png'
SIZE_TOL = 0.01  # relative: the recording's sheet and the export's are one size
WIND_RANGE = (0.5, 8.0)  # m/s, an anemometer's reading a sheet is blown by
MAX_SEEDS = 64
# Within this many times its noise floor a prediction is as close as the
# gusts allow (issue 76's target for an exported sheet).
FLOOR_FACTOR = 1.2


@dataclasses.dataclass(frozen=True)
class Exported:
  """An export's fabric (``fabric_files.write``'s ``fabric.json``).

  Attributes:
    folder: the export's folder.
    material: the fabric.
    flex_scale: the flex's bending scale at the export's mesh.
    area_weight: kg/m^2.
    size: the sheet's side, m.
    resolution: its vertices a side.
    fps: the clock the export's step divides.
  """

  folder: str
  material: str
  flex_scale: float
  area_weight: float
  size: float
  resolution: int
  fps: float


def read_export(folder: str) -> Exported:
  """The fabric an export's folder holds, checked against its MJCF (the
  Young's modulus written there is the flex scale's).

  Raises:
    ValueError: no such folder or file, a corrupt one, or numbers out of
      range or disagreeing between the two files (named).
  """
  path = os.path.join(folder, fabric_files.FABRIC_FILE)
  xml_path = os.path.join(folder, fabric_files.MJCF_FILE)
  for p in (path, xml_path):
    if not os.path.isfile(p):
      raise ValueError(f'{p}: no such file (an export: python -m experiments.export)')
  data = layout.read_json(path)
  try:
    material = data['material']
    scale = data['simulator']['flex_bending_scale']
    w = data['point']['area_weight']
    mesh = data['mesh']
    size, n, fps = mesh['size_m'], mesh['vertices_per_side'], mesh['fps']
  except (KeyError, TypeError) as e:
    raise ValueError(
      f'{path}: not an export of this version ({type(e).__name__}: {str(e)[:40]}); '
      'export again'
    ) from None
  if not isinstance(material, str) or material not in physsim.FABRICS:
    raise ValueError(f'{path}: material {str(material)[:40]!r} is no known fabric')
  rng = fabric_files
  out = Exported(
    folder=folder,
    material=material,
    flex_scale=rng.in_range(
      path, 'flex_bending_scale', scale, *rng.BENDING_SCALE_RANGE
    ),  # fmt: skip
    area_weight=rng.in_range(path, 'area_weight', w, *rng.AREA_WEIGHT_RANGE),
    size=rng.in_range(path, 'mesh.size_m', size, *rng.CLOTH_SIZE_RANGE),
    resolution=round(
      rng.in_range(path, 'mesh.vertices_per_side', n, *rng.RESOLUTION_RANGE)
    ),  # fmt: skip
    fps=rng.in_range(path, 'mesh.fps', fps, *rng.FPS_RANGE),
  )
  with open(xml_path, encoding='utf-8', errors='replace') as f:
    found = re.search(r'young="([^"]+)"', f.read())
  young = physsim.export.young_modulus(out.flex_scale, material)
  if found is None or not math.isclose(float(found.group(1)), young, rel_tol=1e-6):
    raise ValueError(
      f"{xml_path}: its Young's modulus is not the flex scale of {path}; export again"
    )
  return out


@dataclasses.dataclass(frozen=True)
class Settings:
  """How the prediction is simulated and compared.

  Attributes:
    frames: frames compared (at the export's frame rate).
    warmup: seconds simulated before the first.
    gusts: the simulated wind's RMS relative gust intensity.
    seeds: gust seeds per fabric (the floor: their pairs; at least 2).
    image_size: the frames' side, pixels, where the summaries are read.
    seed: the gust and sensor-noise seeds.
    backend: the simulator (``physsim.BACKENDS``; 'auto': MuJoCo Warp on a
      GPU, MuJoCo C on a CPU).
  """

  frames: int = 60
  warmup: float = 1.0
  gusts: float = 0.2
  seeds: int = 4
  image_size: int = 64
  seed: int = 0
  backend: str = 'auto'

  def check(self) -> None:
    """Refuses a count or setting out of range, naming its flag."""
    for name, v, lo, hi in (
      ('frames', self.frames, 2, 1000), ('seeds', self.seeds, 2, MAX_SEEDS),
      ('image_size', self.image_size, *embedding.IMAGE_SIZES),
      ('seed', self.seed, 0, 2**31 - 1),
    ):  # fmt: skip
      if not lo <= v <= hi:
        raise ValueError(f'--{name}={v}: need {lo}-{hi}')
    if not (0 <= self.warmup <= 10 and 0 <= self.gusts <= 1):
      raise ValueError(
        f'--warmup={self.warmup}, --gusts={self.gusts}: need 0-10 s and 0-1'
      )
    if self.backend not in physsim.BACKENDS:
      raise ValueError(f'--backend={self.backend}: one of {physsim.BACKENDS}')


def check_set_up(
  exported: Exported, recording: str, camera_json: str, cloth_size: float,
  wind_speed: float,
) -> None:  # fmt: skip
  """Refuses, before the recording is read, a set-up the export cannot be
  compared in: no camera file (the prediction is seen through the
  recording's camera), a sheet of another size than the export's, the
  recording the estimate was made from, a wind outside what a fan blows.

  Raises:
    ValueError: one line naming the recording or the flag.
  """
  if not camera_json and not bags.is_bag(recording):
    raise ValueError(
      f'{recording}: no camera file (--camera_json): the prediction is compared '
      "where the recording's camera sees the sheet, which needs its camera"
    )
  if not (math.isfinite(cloth_size) and cloth_size > 0):
    raise ValueError(f"--cloth_size={cloth_size}: need the recording's sheet side, m")
  if abs(cloth_size / exported.size - 1) > SIZE_TOL:
    raise ValueError(
      f'{recording}: a sheet of {cloth_size:g} m (--cloth_size), but the export in '
      f'{exported.folder} is a {exported.size:g} m sheet; export for this one '
      f'(experiments.export --cloth_size={cloth_size:g})'
    )
  source = os.path.join(exported.folder, fabric_files.FABRIC_FILE)
  estimated = estimated_from(layout.read_json(source).get('source', ''))
  if os.path.realpath(recording) in estimated:
    raise ValueError(
      f'{recording}: the estimate behind {exported.folder} was made from it; '
      'validate on a recording it did not see'
    )
  lo, hi = WIND_RANGE
  if not (math.isfinite(wind_speed) and lo <= wind_speed <= hi):
    raise ValueError(
      f"--wind_speed={wind_speed}: need the anemometer's reading, {lo:g}-{hi:g} m/s"
    )


def estimated_from(estimate_file) -> set[str]:
  """The real paths of the recordings an estimate's JSON (one recording's or
  a joint's) was made from; none where it cannot be read."""
  try:
    data = layout.read_json(str(estimate_file))
  except ValueError:
    return set()
  found = [data.get('recording')]
  recordings = data.get('recordings')
  if isinstance(recordings, list):
    found += [r.get('recording') for r in recordings if isinstance(r, dict)]
  return {os.path.realpath(p) for p in found if isinstance(p, str) and p}


def simulation(exported: Exported, settings: Settings) -> objective_lib.Simulation:
  """The estimate's ``Simulation`` of the export's sheet and clock."""
  return objective_lib.Simulation(
    material=exported.material, cloth_resolution=exported.resolution,
    cloth_size=exported.size, frames=settings.frames, fps=exported.fps,
    warmup=settings.warmup, gusts=settings.gusts,
  )  # fmt: skip


def baseline(material: str) -> tuple[float, float]:
  """(bending scale, area weight) of the library's default for ``material``:
  its ArcSim bending and the paper's measured area weight."""
  return 1.0, physsim.fabric(material).real_area_weight


@dataclasses.dataclass(frozen=True)
class Result:
  """What ``predict`` found (lengths in metres).

  Attributes:
    recording: the recording's (2,) shape summary (mean y, mean z).
    predicted: (seeds, 2) the exported fabric's, one per gust seed.
    library: (seeds, 2) the library fabric's, in the same worlds.
    frames: (3, H, W) depth of the recording's middle frame, the prediction's
      and the library fabric's (seed 0), for the figure.
    wind_speed: the simulated mean wind, m/s.
    library_params: the library fabric's (bending scale, area weight).
  """

  recording: np.ndarray
  predicted: np.ndarray
  library: np.ndarray
  frames: np.ndarray
  wind_speed: float
  library_params: tuple[float, float]

  @property
  def floor(self) -> float:
    """The noise floor: RMS distance between the prediction's seeds' summaries."""
    return _rms_pairs(self.predicted)

  @property
  def distance(self) -> float:
    """RMS distance of the prediction's summaries from the recording's."""
    return float(np.sqrt(np.mean(np.sum((self.predicted - self.recording) ** 2, -1))))

  @property
  def library_distance(self) -> float:
    """The same for the library fabric."""
    return float(np.sqrt(np.mean(np.sum((self.library - self.recording) ** 2, -1))))

  def record(self) -> dict:
    """JSON-ready numbers, in mm."""
    mm = lambda a: (1e3 * np.asarray(a)).tolist()  # noqa: E731
    return {
      'recording_summary_mm': mm(self.recording),
      'predicted_summaries_mm': mm(self.predicted),
      'library_summaries_mm': mm(self.library),
      'distance_mm': 1e3 * self.distance, 'floor_mm': 1e3 * self.floor,
      'library_distance_mm': 1e3 * self.library_distance,
      'distance_over_floor': self.distance / self.floor,
      'library_over_floor': self.library_distance / self.floor,
      'wind_speed': self.wind_speed,
      'library': dict(zip(('bending_scale', 'area_weight'), self.library_params,
                          strict=True)),
    }  # fmt: skip


def _rms_pairs(points: np.ndarray) -> float:
  d = [np.sum((a - b) ** 2) for a, b in itertools.combinations(points, 2)]
  return float(np.sqrt(np.mean(d)))


def take_in(
  exported: Exported, path: str, camera_json: str, ik: intake.IntakeConfig,
  settings: Settings,
):  # fmt: skip
  """The recording taken in as an estimate of the export's sheet takes it, at
  ``settings.image_size``: (``intake_record.Intake``, ``recording.Recording``).

  Raises:
    ValueError: the intake's refusals (named): pins at another spacing than
      the export's sheet, a camera that cannot be placed, a short clip.
  """
  sim = simulation(exported, settings)
  taken = intake.take_in(path, ik, camera_json, sim)
  if taken.pose is None:
    raise ValueError(
      f"{path}: its camera could not be placed in the simulator's world; give "
      '--camera_json'
    )
  size = (settings.image_size, settings.image_size)
  return taken, intake_files.to_recording(taken, sim.fps, size, sim.frames)


def predict(exported: Exported, rec, wind_speed: float, settings: Settings) -> Result:
  """The exported fabric and the library's default, each simulated with
  ``settings.seeds`` gust seeds at ``wind_speed`` in the recording's set-up
  and summarised through its camera (``objective.Objective``, shape distance)."""
  sim = simulation(exported, settings)
  config = objective_lib.EstimateConfig().replace(
    **dataclasses.asdict(sim), distance='shape', backend=settings.backend,
    seed=settings.seed, camera_sd_m=0.0, camera_sd_deg=0.0,
  )  # fmt: skip
  net = embedding.no_network(tuple(rec.depth.shape[1:]))
  problem = objective_lib.make_problem(config, net, rec)
  lib = baseline(exported.material)
  ours = (exported.flex_scale, exported.area_weight)
  bend = sorted(v[0] for v in (ours, lib))
  weight = sorted(v[1] for v in (ours, lib))
  space = physsim.SearchSpace(
    bending_scale=(bend[0] / 2, bend[1] * 2), wind_speed=(wind_speed / 2, wind_speed * 2),
    area_weight=(weight[0] / 2, weight[1] * 2),
  )  # fmt: skip
  lo, hi, log = physsim.params.unit_map(space)
  data = problem.data._replace(
    lo=jnp.asarray(lo, jnp.float32), hi=jnp.asarray(hi, jnp.float32),
    log=jnp.asarray(log),
  )  # fmt: skip
  k = settings.seeds
  params = physsim.params.make(
    np.repeat([ours[0], lib[0]], k), np.full(2 * k, wind_speed),
    np.repeat([ours[1], lib[1]], k),
  )  # fmt: skip
  u = physsim.to_unit(params, space)[None]  # (1, 2k, 3)
  gust, noise = objective_lib.candidate_keys(config.seed, config.search, 0, k)
  gust, noise = (jnp.concatenate([a, a])[None] for a in (gust, noise))  # both alike
  run = objective_lib.Objective(problem)
  scores = run(objective_lib.stack([data]), u, gust, noise, positions=True)
  if not np.all(scores.valid):
    raise ValueError(
      f'{exported.folder}: {int((~scores.valid).sum())} of {2 * k} simulations blew '
      'up in this set-up'
    )
  rec_summary = np.asarray(problem.data.rec_shape, np.float64)
  summaries = rec_summary + scores.residual[0]
  middle = len(rec.depth) // 2
  poses = jax.tree.map(
    lambda a: np.broadcast_to(np.asarray(a, np.float32), (2, 1, *np.shape(a))),
    rec.pose,
  )
  pos = scores.positions[0][[0, k], middle][:, None]  # (2, T=1, V, 3)
  faces = objective_lib.mesh(sim).faces
  seen = np.asarray(physsim.render_depth(pos, faces, problem.intr, poses))
  frames = np.concatenate([rec.depth[middle][None], seen[:, 0, 0]])
  return Result(rec_summary, summaries[:k], summaries[k:], frames, wind_speed, lib)


def verdict(result: Result) -> str:
  """One line: whether the prediction is as close as the gusts allow."""
  r = result.distance / result.floor
  if r <= FLOOR_FACTOR:
    return (
      f'consistent: the export lies {r:.2f}x its noise floor from the recording '
      f'(within {FLOOR_FACTOR:g}x)'
    )
  return (
    f'not explained by the gusts: the export lies {r:.2f}x its noise floor from the '
    'recording (the fabric, its air, the wind reading or the set-up differ)'
  )


def report(
  exported: Exported, recording: str, result: Result, alignment_sd=(0.0, 0.0)
) -> list[str]:
  """The lines ``experiments.validate`` prints; ``alignment_sd`` (metres,
  degrees): the intake's own placement error of the camera, 1 sd, which
  moves the recording's summary and not the floor."""
  y, z = 1e3 * result.recording
  b, w = result.library_params
  placed = []
  if any(alignment_sd):
    placed = [
      f"the camera's placement (the intake's own error, 1 sd): "
      f'{1e3 * alignment_sd[0]:.0f} mm and {alignment_sd[1]:.2g} degrees, which '
      'the distance carries and the floor does not'
    ]
  return [
    f"{recording}: the sheet's mean place (wind-wise, up) {y:.1f}, {z:.1f} mm in "
    "the simulator's world",
    f'exported fabric ({exported.material}, {exported.resolution}x{exported.resolution}'
    f', {1e3 * exported.area_weight:.4g} g/m^2) at {result.wind_speed:g} m/s: '
    f'{1e3 * result.distance:.1f} mm from the recording (RMS over '
    f'{len(result.predicted)} gust seeds)',
    f'noise floor (the same fabric, other gust seeds): {1e3 * result.floor:.1f} mm; '
    f'the export {result.distance / result.floor:.2f}x it',
    f'library fabric ({exported.material} at its ArcSim bending, '
    f'{1e3 * w:.4g} g/m^2; internal bending scale {b:g}): '
    f'{1e3 * result.library_distance:.1f} mm, '
    f'{result.library_distance / result.floor:.2f}x the floor',
    *placed,
    verdict(result),
  ]


def figure(exported: Exported, recording: str, result: Result, path: str) -> None:
  """The recording's middle frame beside the prediction's and the library
  fabric's (one gust seed each), and every summary (mm)."""
  plt = files.pyplot()
  fig, ax = plt.subplots(1, 4, figsize=(15, 3.8))
  valid = result.frames[result.frames > 0]
  lo, hi = np.percentile(valid, [2, 98]) if valid.size else (0.0, 1.0)
  titles = ('recording', f'export ({exported.resolution}x{exported.resolution})',
            'library default')  # fmt: skip
  for a, f, t in zip(ax[:3], result.frames, titles, strict=True):
    a.imshow(np.where(f > 0, f, np.nan), cmap='viridis', vmin=lo, vmax=hi)
    a.set_title(t)
    a.axis('off')
  s = ax[3]
  for pts, label, mark in ((result.predicted, 'export', 'o'),
                           (result.library, 'library', 'x')):  # fmt: skip
    s.scatter(1e3 * pts[:, 0], 1e3 * pts[:, 1], marker=mark, label=label)
  s.scatter(*(1e3 * result.recording), marker='*', s=200, c='k', label='recording')
  s.set_xlabel('mean wind-wise place, mm')
  s.set_ylabel('mean height, mm')
  s.set_title(f"distance {result.distance / result.floor:.2f}x the gusts' floor")
  s.legend(fontsize=8)
  fig.suptitle(f'{os.path.basename(os.path.normpath(recording))} at '
               f'{result.wind_speed:g} m/s: depth, m, and the sheet\'s mean place')  # fmt: skip
  fig.tight_layout()
  files.savefig(fig, path)
  plt.close(fig)
