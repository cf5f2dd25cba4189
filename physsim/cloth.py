"""MJCF for a flex cloth, and the static arrays a rollout needs from it.

Modelling choices (measured; see BENCHMARKS.md and experiments/fabric_motion.py):
  * Stretching: flex edge equality constraints, slightly soft (``solref`` 4 ms)
    so edges may strain about 1% (p99) and a few percent next to the pins, like
    ArcSim's 0.95-1.05 strain limit. Softer (20 ms) let pin edges stretch >100%.
    Solver: CG with an iteration cap of 50 (it stops early on tolerance). MuJoCo
    C converges in ~20 on a 25x25 cloth; MuJoCo Warp's float32 CG does not: with
    these stiff edges 62% of its worlds blew up at 20 and 1 in 1024 at 40, while
    50 held every world with the same edge strain as 100 (p99 1.2%) at 1.4x the
    speed (BENCHMARKS.md). Softer edges let 20 iterations run, at 6-48% strain.
  * Bending: MuJoCo's own 2-D flex bending (``elastic2d="bend"``) is compiled
    once at the reference rigidity D0 of the material (``reference_rigidity``)
    but turned off in MuJoCo; the rollout applies the same compiled 4x4 stencil
    (``flex_bending``) times each world's bending scale as an applied force,
    because MuJoCo Warp keeps ``flex_bending`` shared by all worlds.
  * Mass: per-vertex, a third of each adjacent face's rest area times the area
    weight (ArcSim's rule), set per world through ``body_mass``; plus any
    known masses attached to vertices (``build``'s ``extra_mass``: coins taped
    along a hem), the same in every world.
  * Wind: ArcSim's face force, computed in JAX each substep (``physsim.wind``).
    MuJoCo's own fluid model stays off (density 0), so nothing double counts.
  * Self-collision off: a sheet in a fan's wind barely touches itself, and the
    collision pipeline would dominate the cost.
  * MuJoCo's passive forces off (``spring`` and ``damper`` disabled): the cloth
    has none (no joint springs or dampers, edges are constraints, bending is
    applied by the rollout), so this changes nothing but skips MuJoCo's
    passive pass, which was a fifth of a MuJoCo Warp step on a GPU and half
    of one on a CPU.

Bending mapping (``reference_rigidity``): ArcSim's hinge energy is
``ke l^2 theta^2 / (8 (A0 + A1))``. Bent into a cylinder of curvature k, our
alternating-diagonal grid stores ``7 ke k^2 / 72`` per unit area under that
formula, while a plate of rigidity D stores ``D k^2 / 2``; so D0 = 7/36 ke. ``ke``
is the measured 3x5 matrix averaged over its three directions at ArcSim's
curvature sample 0.5 (between the first two columns), the range a 1 m sheet in
a fan mostly sees. What one isotropic, linear D cannot represent: the 0/45/90
degree anisotropy (up to ~2x in some fabrics), stiffening with curvature along
a row, and ArcSim's min-over-sides rule.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from physsim import materials
from physsim.mesh import Mesh

THICKNESS = 1e-3  # m; only the product E t^3 matters for bending.
FLEX_RADIUS = 0.002  # m, the flex's collision radius (no collisions: a formality)
EDGE_SOLIMP = '0.95 0.99 0.001'  # the edge equality constraints' impedance


def young_modulus(rigidity: float) -> float:
  """Pa: MuJoCo's ``young`` at ``THICKNESS`` for a plate rigidity in N*m
  (D = E t^3 / 12 with poisson 0)."""
  return rigidity * 12.0 / THICKNESS**3


GRAPH_MODES = ('auto', 'jax', 'warp')


@dataclasses.dataclass(frozen=True)
class SimConfig:
  """Static simulation settings (changing any recompiles).

  Attributes:
    timestep: MuJoCo step, seconds.
    iterations: constraint solver iterations.
    solver: ``'CG'`` or ``'Newton'``.
    edge_solref: time constant of the edge equality constraints, seconds.
    air_density: ArcSim ``wind.density`` (its default 1, with no 1/2 factor).
    air_drag: ArcSim ``wind.drag`` on the tangential flow (default 0).
    bending_damping: Rayleigh damping on the bending stencil, seconds.
    tolerance: the solver's relative tolerance (MuJoCo's ``opt.tolerance``):
      it stops before ``iterations`` once an iteration improves the cost by
      less than this (MuJoCo Warp exits the whole batch's loop once every
      world has; at MuJoCo's 1e-8 float32 CG never does).
    graph_mode: how MJX ``impl='warp'`` captures MuJoCo Warp's kernels:
      ``'auto'`` (MJX's choice for the device), ``'jax'`` (XLA's command
      buffers; on a GPU it cannot hold the solver's conditional loop) or
      ``'warp'`` (a CUDA graph per call); only the speed differs.
  """

  timestep: float = 0.002
  iterations: int = 50
  solver: str = 'CG'
  edge_solref: float = 0.004
  air_density: float = 1.0
  air_drag: float = 0.0
  bending_damping: float = 0.0
  tolerance: float = 1e-8
  graph_mode: str = 'auto'


# The bending force is explicit, so the largest stable step shrinks as the
# square of the mesh spacing: MuJoCo C held bending 10x on a 12.4 mm mesh at
# 2 ms and blew up at 4.5x on a 6 mm mesh at 2 ms (experiments.studies.protocol).
STABLE_STEP_AT = (0.0124, 0.002)  # (edge, metres; step, seconds)


def stable_timestep(edge: float, frame_dt: float, timestep: float = 0.002) -> float:
  """The largest step at most ``timestep`` and stable for a mesh whose
  shortest edge is ``edge`` metres, that divides the frame interval
  ``frame_dt`` into whole substeps. A 1 m sheet of up to 81 vertices a side
  keeps 2 ms; a 20 cm swatch of 25 gets about 0.9 ms. The step is computed
  as ``frame_dt / n`` and may differ from a given ``timestep`` in its last
  bit (a fluttering sheet's trajectory then differs, not its statistics)."""
  if not (edge > 0 and frame_dt > 0 and timestep > 0):
    raise ValueError(
      f'need edge, frame_dt and timestep > 0, got {edge}, {frame_dt}, {timestep}'
    )
  h0, dt0 = STABLE_STEP_AT
  bound = min(timestep, dt0 * (edge / h0) ** 2)
  return frame_dt / math.ceil(frame_dt / bound - 1e-9)


# The vertex spacing at which SimConfig.edge_solref was chosen: the garments'
# 4 cm (the 1 m sheet of 25 vertices a side that the estimate simulates has
# 4.17 cm). Meshes this coarse or coarser keep edge_solref, so the paper's
# sheet, the garments and the shipped calibrations are the same either way.
EDGE_SOLREF_SPACING = 0.04


def scaled_edge_solref(
  edge: float, edge_solref: float = SimConfig.edge_solref
) -> float:
  """The edges' time constant that keeps a finer mesh as stiff in stretch as
  the mesh ``edge_solref`` was chosen on (``EDGE_SOLREF_SPACING``).

  An edge constraint with time constant tau pulls its two vertices (mass
  ~ rho h^2 for spacing h) back like a spring of rho h^2 / tau^2, so a cloth's
  tension per unit width and strain is rho h^2 / tau^2: at a fixed tau every
  refinement makes the cloth stretchier (a 20 cm swatch's 99th-percentile
  strain went 0.6% to 8% from 9 to 41 vertices a side, and its deflection
  never settled). tau proportional to h keeps it; meshes as coarse as the
  reference or coarser keep ``edge_solref`` (within rounding: a garment's
  4 cm grid measures 4 cm less 1e-16)."""
  if not (edge > 0 and edge_solref > 0):
    raise ValueError(f'need edge and edge_solref > 0, got {edge} and {edge_solref}')
  ratio = edge / EDGE_SOLREF_SPACING
  return edge_solref if ratio > 1.0 - 1e-9 else edge_solref * ratio


def config_for_mesh(
  mesh: Mesh,
  fps: float,
  timestep: float = 0.002,
  edge_solref: float = SimConfig.edge_solref,
  scaled_edges: bool = True,
  **fields,
) -> SimConfig:
  """``SimConfig`` for ``mesh`` recorded at ``fps``: the step
  ``stable_timestep`` gives its shortest edge (at most ``timestep``), edges no
  stiffer than two steps (MuJoCo's stiffest safe time constant), and any other
  ``fields``. The edges' time constant ``edge_solref`` is the one of the
  reference spacing (``EDGE_SOLREF_SPACING``) and shrinks with a finer
  spacing (``scaled_edge_solref``: the same stretch stiffness on every mesh and
  cloth size, so a finer mesh converges), the step with it, to half of it;
  ``scaled_edges=False`` keeps ``edge_solref`` on every mesh (the recipe of
  the results made before this was the default)."""
  if scaled_edges:
    edge_solref = scaled_edge_solref(mesh.shortest_edge, edge_solref)
    timestep = min(timestep, edge_solref / 2)
  step = stable_timestep(mesh.shortest_edge, 1.0 / fps, timestep)
  return SimConfig(timestep=step, edge_solref=max(edge_solref, 2 * step), **fields)


def reference_rigidity(material: str) -> float:
  """D0 in N*m: the material's measured bending as one plate rigidity."""
  bend = materials.load_material(material).bending
  ke = 0.5 * (bend[:, 0] + bend[:, 1]).mean()
  return 7.0 / 36.0 * ke


def mjcf(mesh: Mesh, config: SimConfig, rigidity: float = 1e-5) -> str:
  """MJCF text of ``mesh`` as a pinned flex cloth.

  The flex's total mass is a placeholder: rollouts set area-weighted masses.
  """
  if config.solver not in ('CG', 'Newton'):
    raise ValueError(f"solver must be 'CG' or 'Newton', got {config.solver!r}")
  if config.graph_mode not in GRAPH_MODES or not 0 <= config.tolerance < 1:
    raise ValueError(
      f'need graph_mode in {GRAPH_MODES} and 0 <= tolerance < 1, got '
      f'{config.graph_mode!r}, {config.tolerance}'
    )
  if not (config.timestep > 0 and config.edge_solref >= 2 * config.timestep):
    raise ValueError(
      f'need timestep > 0 and edge_solref >= 2 * timestep, got '
      f'{config.timestep} and {config.edge_solref}'
    )
  young = young_modulus(rigidity)
  points = ' '.join(f'{v:.9g}' for v in mesh.vertices.ravel())
  elements = ' '.join(str(i) for i in mesh.faces.ravel())
  pins = ' '.join(str(i) for i in mesh.pinned)
  return f"""<mujoco model="{mesh.name}">
  <option timestep="{config.timestep}" integrator="Euler" solver="{config.solver}"
          iterations="{config.iterations}" ls_iterations="10" tolerance="{config.tolerance:g}"
          density="0" viscosity="0">
    <flag spring="disable" damper="disable"/>
  </option>
  <worldbody>
    <flexcomp name="cloth" type="direct" dim="2" radius="{FLEX_RADIUS}" mass="{mesh.area * 0.2}"
              point="{points}" element="{elements}">
      <edge equality="true" solref="{config.edge_solref} 1" solimp="{EDGE_SOLIMP}"/>
      <elasticity young="{young:.9g}" poisson="0" thickness="{THICKNESS}" elastic2d="bend"/>
      <contact selfcollide="none" contype="0" conaffinity="0"/>
      <pin id="{pins}"/>
    </flexcomp>
  </worldbody>
</mujoco>"""


@dataclasses.dataclass(frozen=True)
class ClothModel:
  """A compiled cloth and the static arrays a rollout needs.

  Attributes:
    mesh: the rest mesh.
    config: the static simulation settings.
    material: ArcSim material name.
    rigidity: D0, N*m, the bending that a scale of 1 means.
    mj_model: MuJoCo model with MuJoCo's own bending switched off (see module doc).
    vert_qadr: (V,) qpos/qvel address of each vertex's x slide, -1 if pinned.
    vert_body: (V,) body id of each vertex, 0 (world) if pinned.
    hinge_verts: (H, 4) the edge's two vertices then its two flaps.
    hinge_coef: (H, 4, 4) MuJoCo's compiled bending stencil at D0.
    hinge_c16: (H,) MuJoCo's curved-rest-shape term (0 for flat meshes).
    extra_mass: (V,) kg attached to each vertex besides the cloth's own (a
      known mass: coins taped along a hem), the same in every world.
  """

  mesh: Mesh
  config: SimConfig
  material: str
  rigidity: float
  mj_model: mujoco.MjModel
  vert_qadr: np.ndarray
  vert_body: np.ndarray
  hinge_verts: np.ndarray
  hinge_coef: np.ndarray
  hinge_c16: np.ndarray
  extra_mass: np.ndarray
  # Compiled rollouts and worker pools of this model (``physsim.rollout``),
  # built on first use and kept as long as the model: a model is compiled for
  # MJX once, whoever simulates it.
  programs: dict = dataclasses.field(
    default_factory=dict, compare=False, repr=False, hash=False
  )

  @property
  def n_vertices(self) -> int:
    return len(self.mesh.vertices)

  def vertex_masses(self, area_weight) -> np.ndarray:
    """(..., V) physical vertex masses, kg, for area weights of shape (...),
    the attached ``extra_mass`` included."""
    own = np.asarray(area_weight, np.float64)[..., None] * self.mesh.vertex_areas
    return own + self.extra_mass

  def body_masses(self, area_weight) -> np.ndarray:
    """(..., nbody) MuJoCo body masses for the given area weights."""
    vm = self.vertex_masses(area_weight)
    out = np.zeros(vm.shape[:-1] + (self.mj_model.nbody,))
    moving = self.vert_qadr >= 0
    out[..., self.vert_body[moving]] = vm[..., moving]
    return out

  def body_masses_jax(self, area_weight) -> jax.Array:
    """``body_masses`` as a traceable function: (B,) -> (B, nbody) float32."""
    moving = self.vert_qadr >= 0
    areas = jnp.asarray(self.mesh.vertex_areas[moving], jnp.float32)
    out = jnp.zeros(jnp.shape(area_weight) + (self.mj_model.nbody,), jnp.float32)
    extra = jnp.asarray(self.extra_mass[moving], jnp.float32)
    mass = jnp.asarray(area_weight, jnp.float32)[..., None] * areas + extra
    return out.at[..., self.vert_body[moving]].set(mass)


def build(
  mesh: Mesh, material: str = 'gray_interlock', config: SimConfig | None = None,
  extra_mass=None,
):  # fmt: skip
  """Compiles ``mesh`` into a ``ClothModel`` for ``material``.

  Args:
    mesh: rest mesh with pinned vertices.
    material: a paper fabric name or an ArcSim material file stem.
    config: static settings; defaults to ``SimConfig()``.
    extra_mass: (V,) kg attached to each vertex (``hem_mass``), or None.

  Returns:
    The ``ClothModel``.
  """
  config = config or SimConfig()
  n = len(mesh.vertices)
  extra = np.zeros(n) if extra_mass is None else np.asarray(extra_mass, np.float64)
  if extra.shape != (n,) or not np.all(np.isfinite(extra) & (extra >= 0)):
    raise ValueError(
      f'extra_mass: need {n} finite masses >= 0 (kg, one per vertex), got shape '
      f'{extra.shape}'
    )
  rigidity = reference_rigidity(material)
  m = mujoco.MjModel.from_xml_string(mjcf(mesh, config, rigidity))
  if m.nflexvert != len(mesh.vertices):
    raise ValueError(f'flex has {m.nflexvert} vertices, mesh {len(mesh.vertices)}')
  vert_body = m.flex_vertbodyid.astype(np.int64)
  vert_body[vert_body < 0] = 0
  vert_qadr = -np.ones(len(vert_body), np.int64)
  for v, b in enumerate(vert_body):
    if b == 0:
      continue
    j = m.body_jntadr[b]
    if m.body_jntnum[b] != 3 or not np.allclose(m.jnt_axis[j : j + 3], np.eye(3)):
      raise ValueError(f'vertex {v}: expected x, y, z slide joints on body {b}')
    vert_qadr[v] = m.jnt_qposadr[j]
  if not np.array_equal(np.flatnonzero(vert_qadr < 0), np.sort(mesh.pinned)):
    raise ValueError('pinned vertices of the compiled flex differ from the mesh')

  flap = m.flex_edgeflap.reshape(-1, 2)
  edge = m.flex_edge.reshape(-1, 2)
  inner = flap[:, 1] >= 0
  coef = m.flex_bending.reshape(-1, 17)[inner]
  hinge_verts = np.concatenate([edge[inner], flap[inner]], axis=1).astype(np.int64)
  # MuJoCo's bending is applied by the rollout (per-world scale), not by MuJoCo.
  m.flex_bending[:] = 0.0
  model = ClothModel(
    mesh=mesh,
    config=config,
    material=material,
    rigidity=rigidity,
    mj_model=m,
    vert_qadr=vert_qadr,
    vert_body=vert_body,
    hinge_verts=hinge_verts,
    hinge_coef=coef[:, :16].reshape(-1, 4, 4).copy(),
    hinge_c16=coef[:, 16].copy(),
    extra_mass=extra,
  )
  # Area-weighted masses at a typical 0.2 kg/m^2; rollouts set their own.
  m.body_mass[:] = model.body_masses(0.2)
  return model


def hem_mass(mesh: Mesh, rows: int, mass: float) -> np.ndarray:
  """(V,) ``build``'s ``extra_mass`` for ``mass`` kg spread evenly over the
  last row of a ``rows``-row grid mesh (``square``'s bottom edge, or an
  overhang's tip): a strip of coins or a rod of known mass along the free edge,
  which a recording can add so that the cloth's own weight is measured
  against it (``experiments.studies.protocol``)."""
  n = len(mesh.vertices)
  if n % rows or not (np.isfinite(mass) and mass >= 0):
    raise ValueError(
      f'hem_mass: need a grid of {rows} rows (got {n} vertices) and a mass '
      f'>= 0 kg, got {mass}'
    )
  out = np.zeros(n)
  last = np.arange(n - n // rows, n)
  out[last] = mass / len(last)
  return out
