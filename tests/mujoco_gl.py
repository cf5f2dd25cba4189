"""MuJoCo's own OpenGL renderer, offscreen, for tests that use it as an
independent reference (skipped where no offscreen GL exists)."""

import importlib
import os

import mujoco
import pytest


def offscreen_renderer(model, height, width):
  """A mujoco.Renderer on an offscreen GL (EGL, else OSMesa), else pytest.skip.

  The context class is chosen here rather than through MUJOCO_GL, which MuJoCo
  reads once at import (other tests may import it first); its default, GLFW,
  aborts the process without a display, so it is never tried.
  """
  from mujoco.rendering.classic import gl_context

  order = ['egl', 'osmesa']
  if os.environ.get('MUJOCO_GL', '').lower() == 'osmesa':
    order.reverse()
  errors = []
  for backend in order:
    try:
      context = importlib.import_module(f'mujoco.{backend}').GLContext
      old, gl_context.GLContext = gl_context.GLContext, context
      try:
        return mujoco.Renderer(model, height, width)
      finally:
        gl_context.GLContext = old
    except Exception as e:  # noqa: BLE001 - any GL failure means "try the next"
      errors.append(f'{backend}: {type(e).__name__}: {e}')
  pytest.skip(
    'no offscreen OpenGL for MuJoCo (needs libegl1 + libgl1-mesa-dri for EGL, or '
    'libosmesa6 with MUJOCO_GL=osmesa): ' + '; '.join(errors)
  )
