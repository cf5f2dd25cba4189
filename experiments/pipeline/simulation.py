"""What an estimate simulates: the ``Simulation`` section of its settings and
the cloth it makes (the rest mesh, the step that mesh needs, its pins).

A module of its own so that what only needs the cloth (the intake fitting a
recording's pins to the simulated ones) does not import the objective:

  from experiments.pipeline import simulation
  sim = simulation.Simulation(cloth_size=0.2)
  simulation.mesh(sim).vertices.shape   # (625, 3)

``objective`` re-exports these names (``objective.Simulation``, ``objective.mesh``).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

import physsim
from experiments.pipeline import cli


@dataclasses.dataclass(frozen=True)
class Simulation:
  """What is simulated and rendered for each candidate.

  Attributes:
    material: paper fabric name (physsim.FABRICS): the search box and the
      bending reference.
    garment: '' for the square cloth, else a physsim.GARMENTS name.
    cloth_resolution: square cloth vertices per side.
    cloth_size: the square cloth's side, metres (1: the paper's sheet; a
      small swatch shows bending); the simulator's step shrinks with the
      mesh spacing (physsim.stable_timestep).
    garment_spacing: garment grid spacing, metres.
    frames: most frames compared (at fps); a longer recording is cut, a
      shorter one sets how many frames are simulated.
    fps: frame rate of the comparison, Hz: simulations render at it and the
      recording is resampled to it (flag ``--sim_fps``; estimate's ``--fps`` is the
      recording's own rate).
    warmup: simulated seconds before the first frame.
    gusts: RMS relative gust intensity of the simulated wind.
    cameras: training-like cameras to render from when the recording's camera
      is unknown (their embeddings are pooled).
    sensor_noise: pass candidates' rendered depth through the depth-sensor
      model (physsim.sensor) before embedding, as the recording went through
      a real sensor.
    hem_mass: kg of known mass spread along the square cloth's free edge
      (coins or a rod taped along the hem: ``physsim.hem_mass``), 0 for none.
      Filmed beside the same cloth without it, the fan untouched (a protocol
      file's ``"fan"``: one wind for both), it weighs the cloth against a
      known mass rather than through the simulator's drag law
      (docs/studies/protocol.md, "A known mass at the hem").
  """

  material: str = 'gray_interlock'
  garment: str = ''
  cloth_resolution: int = 25
  cloth_size: float = 1.0
  garment_spacing: float = 0.04
  frames: int = 60
  fps: float = cli.renamed(20.0, 'sim_fps')
  warmup: float = 1.0
  gusts: float = 0.2
  cameras: int = 2
  sensor_noise: bool = True
  hem_mass: float = 0.0


def mesh(sim: Simulation) -> physsim.Mesh:
  """The rest mesh an estimate simulates: the square or the garment."""
  if sim.garment:
    return physsim.garment(sim.garment, sim.garment_spacing)
  return physsim.square(sim.cloth_resolution, sim.cloth_size)


def sim_config(sim: Simulation) -> physsim.SimConfig:
  """The simulator's settings of an estimate's mesh: the default step, or a
  shorter one that a fine mesh needs to stay stable (``stable_timestep``)."""
  return physsim.config_for_mesh(mesh(sim), sim.fps)


def pin_centre(sim: Simulation) -> np.ndarray:
  """(3,) the midpoint of the estimate's pinned vertices: where a camera's
  placement error turns about (``Scoring.camera_sd_deg``)."""
  m = mesh(sim)
  return m.vertices[m.pinned].mean(0)


def cloth(sim: Simulation) -> physsim.ClothModel:
  """The compiled cloth of an estimate's mesh. Worlds name their fabric's
  bending reference (``rigidity_ratio``), so every fabric of a mesh shares one
  model and its compiles; built once per process for each mesh, step and hem
  (a calibration sets up hundreds of recordings of one mesh; the model is
  only read)."""
  mesh_only = dataclasses.replace(
    Simulation(), garment=sim.garment, garment_spacing=sim.garment_spacing,
    cloth_resolution=sim.cloth_resolution, cloth_size=sim.cloth_size,
    fps=sim.fps, hem_mass=sim.hem_mass,
  )  # fmt: skip
  return _cloth(mesh_only)


@functools.lru_cache(maxsize=8)
def _cloth(sim: Simulation) -> physsim.ClothModel:
  m = mesh(sim)
  extra = (
    physsim.hem_mass(m, sim.cloth_resolution, sim.hem_mass) if sim.hem_mass else None
  )
  return physsim.build(m, 'gray_interlock', sim_config(sim), extra_mass=extra)
