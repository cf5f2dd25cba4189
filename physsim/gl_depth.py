"""Depth frames from MuJoCo's own OpenGL renderer.

The project's ray-caster (``physsim.render``) is what estimates use; MuJoCo's
renderer is a second, independent one: tests check the ray-caster against it,
and benchmarks render the worlds an estimate must read with it, so that no
reader leans on the ray-caster's conventions. It needs an OpenGL context (EGL
or OSMesa offscreen); making the ``mujoco.Renderer`` is the caller's, since
where that context comes from differs (tests fall back between backends).
"""

from __future__ import annotations

import mujoco
import numpy as np


def mujoco_depth(
  model, renderer, camera: str = 'cam', far: float = np.inf
) -> np.ndarray:
  """(H, W) float64 metric depth of ``model`` at rest (``mj_forward``) from its
  ``camera``, by ``renderer`` (a ``mujoco.Renderer`` of that model, closed
  here); pixels at or beyond ``far`` (the background, MuJoCo's far plane) are
  0, as the ray-caster marks "no surface"."""
  data = mujoco.MjData(model)
  mujoco.mj_forward(model, data)
  try:
    renderer.enable_depth_rendering()
    renderer.update_scene(data, camera=camera)
    depth = np.asarray(renderer.render(), np.float64)
  finally:
    renderer.close()
  return np.where(depth < far, depth, 0.0)
