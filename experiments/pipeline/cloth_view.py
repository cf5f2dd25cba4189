"""The simulated cloth as a recording's camera sees it: its outermost pins
(which the recording's pins are matched to), the rest mesh swung about them
as the wind swings a sheet, and the silhouettes of those swings in the
camera's image, which the intake compares with the recording's cloth.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import physsim
from experiments.pipeline import simulation

# The swing angles about the pins' line that are compared, degrees.
SWINGS_DEG = tuple(range(0, 91, 10))


def simulated_pins(sim: simulation.Simulation) -> tuple[np.ndarray, physsim.Mesh]:
  """((2, 3) the simulated cloth's outer pins, left first; its rest mesh) for
  an estimate's ``Simulation``."""
  mesh = simulation.mesh(sim)
  return outer_pins(mesh), mesh


def outer_pins(mesh) -> np.ndarray:
  """(2, 3) the outermost pinned vertices of ``mesh``, left (-x) first."""
  pinned = mesh.vertices[mesh.pinned]
  return pinned[np.argsort(pinned[:, 0])[[0, -1]]].astype(np.float64)


def swung(vertices: np.ndarray, pins_world: np.ndarray, deg: float) -> np.ndarray:
  """Rest vertices turned by ``deg`` about the pins' line, downwind (+y)."""
  a = np.deg2rad(deg)
  rel = vertices - pins_world.mean(axis=0)
  y = rel[:, 1] * np.cos(a) - rel[:, 2] * np.sin(a)
  z = rel[:, 1] * np.sin(a) + rel[:, 2] * np.cos(a)
  return np.stack([rel[:, 0], y, z], axis=1) + pins_world.mean(axis=0)


def silhouettes(mesh, pins_world, intr, pose, degs=SWINGS_DEG) -> np.ndarray:
  """(len(degs), H, W) bool: the simulated cloth swung by each angle, seen
  by the camera."""
  render = physsim.make_depth_renderer(mesh.faces, intr)
  positions = np.stack([swung(mesh.vertices, pins_world, d) for d in degs])
  poses = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32)[None, None], pose)
  out = render(jnp.asarray(positions, jnp.float32)[None], poses)  # (1, 1, S, H, W)
  return np.asarray(out)[0, 0] > 0
