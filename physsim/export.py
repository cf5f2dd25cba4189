"""A measured fabric for another simulation: MuJoCo MJCF and an ArcSim material.

An estimate's bending scale ``s`` and area weight ``w`` mean, in the estimator's
own simulator (``physsim.cloth``), a MuJoCo flex cloth whose plate rigidity is
``s * D0`` (``reference_rigidity``) and whose vertices carry ``w`` times their
area (a third of each adjacent face's). The estimator applies that bending
itself, world by world; an exported model lets MuJoCo apply it (its own
``elastic2d="bend"`` at Young's modulus ``12 s D0 / t^3``) and bakes the
masses into the bodies, so that the file, loaded anywhere, is the cloth the
estimate simulated, minus the wind: the estimator's air force (ArcSim's
per-face ``rho |u_n| u_n A``, ``rho = 1``, no 1/2) is its own code, not
MuJoCo's fluid model, so the exported model has no air (density 0).

ArcSim's material keeps its stretching table; its bending table is scaled by
``s`` (the estimator's one rigidity is the table's average, ``reference_rigidity``)
and its density is ``w``.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np

from physsim import cloth, materials
from physsim.mesh import Mesh

# Beyond these a parameter is a corrupt file or a typo, never a fabric: an
# area weight of 1e308 kg/m^2 would be written as vertex masses of 1e305 kg.
MAX_BENDING_SCALE = 1e4
MAX_AREA_WEIGHT = 10.0  # kg/m^2


def check(bending_scale: float, area_weight: float) -> None:
  """Raises ValueError unless both are finite, > 0 and at most
  ``MAX_BENDING_SCALE`` and ``MAX_AREA_WEIGHT`` (named)."""
  for name, v, hi in (('bending_scale', bending_scale, MAX_BENDING_SCALE),
                      ('area_weight', area_weight, MAX_AREA_WEIGHT)):  # fmt: skip
    if not (np.isfinite(v) and 0 < v <= hi):
      raise ValueError(f'{name}={v}: need a finite value > 0 and <= {hi:g}')


def young_modulus(bending_scale: float, material: str) -> float:
  """Pa: MuJoCo's ``young`` (``cloth.young_modulus``) for a rigidity of
  ``bending_scale`` times the material's reference."""
  return cloth.young_modulus(bending_scale * cloth.reference_rigidity(material))


# Custom numeric of an exported model: the estimator's edge weights (``load``).
INVWEIGHT_KEY = 'estimator_flexedge_invweight0'


def _num(x, digits: int = 12) -> str:
  return ' '.join(f'{float(v):.{digits}g}' for v in np.ravel(x))


# Digits of the rest positions and Young's modulus: ``cloth.mjcf``'s, so that
# MuJoCo compiles the estimator's own stencil from them, to the bit.
_GEOMETRY_DIGITS = 9


def mujoco_xml(
  mesh: Mesh,
  material: str,
  bending_scale: float,
  area_weight: float,
  config: cloth.SimConfig,
  comment: str = '',
) -> str:
  """MJCF text of ``mesh`` as the estimator's cloth at these parameters:
  one body of three slide joints per free vertex carrying its mass, the
  pinned vertices fixed in the world, the flex's edges as soft equality
  constraints and MuJoCo's own bending on; the geometry to the digits the estimator's own
  MJCF has, masses and weights to 12.

  MuJoCo softens an equality constraint by its ``invweight0``, computed at
  compile from the masses it is compiled with; the estimator's models are
  compiled once at a placeholder area weight (0.2 kg/m^2, equal masses) and
  given each world's masses after, so their edges are as soft as those
  placeholder masses make them. The file keeps those weights as the custom
  numeric ``INVWEIGHT_KEY``: ``load`` (or a user's loader copying it into
  ``flexedge_invweight0``) gives the estimator's cloth; compiled as it is,
  the edges follow the true masses (a stiffer or softer sheet by a few cm
  in a fan at 1 m).

  Args:
    mesh: the cloth (e.g. ``physsim.square``), its pinned vertices fixed.
    material: the fabric (a paper name or ArcSim file stem) whose measured
      bending a scale of 1 means.
    bending_scale: times the material's bending.
    area_weight: kg/m^2.
    config: step, edges and solver (``config_for_mesh``); its air settings
      are not exported (module doc).
    comment: text for an XML comment at the top (where the numbers came from).

  Raises:
    ValueError: a parameter that is not finite and > 0.
  """
  check(bending_scale, area_weight)
  placeholder = cloth.build(mesh, material, config).mj_model
  bodies, names, vertex = _bodies(mesh, area_weight)
  note = f'  <!-- {comment.replace("--", "- -")} -->\n' if comment else ''
  c = config
  young = young_modulus(bending_scale, material)
  return f"""<mujoco model="{material}_{mesh.name}">
{note}  <compiler angle="radian"/>
  <option timestep="{_num(c.timestep)}" integrator="Euler" solver="{c.solver}"
          iterations="{c.iterations}" ls_iterations="10" tolerance="{_num(c.tolerance)}"
          density="0" viscosity="0"/>
  <custom>
    <numeric name="{INVWEIGHT_KEY}" data="{_num(placeholder.flexedge_invweight0)}"/>
  </custom>
  <worldbody>
{chr(10).join(bodies)}
  </worldbody>
  <deformable>
    <flex name="cloth" dim="2" radius="{cloth.FLEX_RADIUS}" body="{' '.join(names)}"
          vertex="{_num(vertex, _GEOMETRY_DIGITS)}" element="{' '.join(str(i) for i in mesh.faces.ravel())}">
      <contact contype="0" conaffinity="0" selfcollide="none"/>
      <elasticity young="{_num(young, _GEOMETRY_DIGITS)}" poisson="0"
                  thickness="{_num(cloth.THICKNESS)}" elastic2d="bend"/>
    </flex>
  </deformable>
  <equality>
    <flex flex="cloth" solref="{_num(c.edge_solref)} 1" solimp="{cloth.EDGE_SOLIMP}"/>
  </equality>
</mujoco>
"""


def _bodies(mesh: Mesh, area_weight: float) -> tuple[list, list, list]:
  """The MJCF of ``mesh``'s vertices at ``area_weight``: ``(bodies, names,
  vertex)``, each free vertex's body (its mass, a ball's inertia, three slide
  joints), the flex's body per vertex ('world' for a pinned one) and its
  position in that body (a pinned one's in the world, a free one's at its
  body's origin)."""
  pinned = set(int(i) for i in mesh.pinned)
  masses = area_weight * mesh.vertex_areas
  bodies, names, vertex = [], [], []
  for v, (x, m) in enumerate(zip(mesh.vertices, masses, strict=True)):
    if v in pinned:
      names.append('world')
      vertex.append(x)
      continue
    name = f'cloth_{v}'
    names.append(name)
    vertex.append(np.zeros(3))
    inertia = 0.4 * m * cloth.FLEX_RADIUS**2  # a solid ball of the flex's radius
    bodies.append(
      f'    <body name="{name}" pos="{_num(x, _GEOMETRY_DIGITS)}">\n'
      f'      <inertial pos="0 0 0" mass="{_num(m)}" diaginertia="{_num([inertia] * 3)}"/>\n'
      '      <joint type="slide" axis="1 0 0"/>\n'
      '      <joint type="slide" axis="0 1 0"/>\n'
      '      <joint type="slide" axis="0 0 1"/>\n'
      '    </body>'
    )
  return bodies, names, vertex


def load(source: str) -> mujoco.MjModel:
  """Compiles an exported model (a path to its file, or its XML text when
  ``source`` starts with '<') with the estimator's edge weights (the custom
  numeric ``INVWEIGHT_KEY``, ``mujoco_xml``); a model without it as it is.

  Raises:
    ValueError: a file that cannot be read (named), or weights that do not
      match the flex's edges.
  """
  xml = source
  if not source.lstrip().startswith('<'):
    if not os.path.isfile(source):
      raise ValueError(f'{source}: no such file (an exported fabric.xml, or MJCF text)')
    try:
      with open(source, encoding='utf-8') as f:
        xml = f.read()
    except (OSError, UnicodeDecodeError) as e:
      raise ValueError(f'{source}: cannot be read ({type(e).__name__})') from None
  m = mujoco.MjModel.from_xml_string(xml)
  try:
    i = m.numeric(INVWEIGHT_KEY).id
  except KeyError:
    return m
  a, n = m.numeric_adr[i], m.numeric_size[i]
  if n != len(m.flexedge_invweight0):
    raise ValueError(
      f'{INVWEIGHT_KEY}: {n} edge weights for {len(m.flexedge_invweight0)} edges'
    )
  m.flexedge_invweight0[:] = m.numeric_data[a : a + n]
  return m


def arcsim_material(material: str, bending_scale: float, area_weight: float) -> dict:
  """ArcSim's material JSON (``density``, ``stretching``, ``bending``) of
  ``material`` with its bending table times ``bending_scale`` and its
  density ``area_weight``."""
  check(bending_scale, area_weight)
  m = materials.load_material(material)
  return {
    'density': float(area_weight),
    'stretching': np.asarray(m.stretching).tolist(),
    'bending': (bending_scale * np.asarray(m.bending)).tolist(),
  }
