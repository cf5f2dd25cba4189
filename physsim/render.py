"""A pure-JAX depth ray-caster and Lambert shader for triangle meshes.

Depth is the z-depth (distance along the optical axis) of the nearest triangle
hit through each pixel centre, in metres, as depth cameras report; 0.0 means
nothing was hit. Two exact methods compute the same per-(pixel, triangle) test
and differ only in which pairs they visit:

* ``'brute'`` tests every pixel against every triangle (work H W F); the
  reference.
* ``'raster'`` visits only the pixels inside each triangle's screen bounding
  box (work proportional to covered pixels): the boxes are laid end to end in a
  flat list of "fragments", processed ``fragments_per_pass`` at a time, and each
  fragment's depth is scatter-minimised into a depth buffer.

The per-pair test projects the triangle to the image and takes edge functions
at the pixel centre (inclusive, so pixels on a shared edge are never lost);
1/z is affine in screen space on a plane, so interpolating 1/z with the screen
barycentrics gives the exact ray-plane depth. Triangles with a vertex closer
than ``_NEAR`` metres to the camera plane are skipped (no near-plane clipping;
the cameras here stay metres away).

Batching: `depth_image` renders one frame; `render_depth` maps it over
(worlds, cameras, frames) in chunks so memory stays bounded. Jit the batched
call once, e.g. ``make_depth_renderer(faces, intrinsics)`` or
``jax.jit(render_depth, static_argnames=('intrinsics', 'method', 'chunk',
'fragments_per_pass'))``.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from physsim.camera import Intrinsics, Pose

METHODS = ('brute', 'raster')

# Approximate colours (RGB in [0, 1]) of the paper's fabrics (names as in
# physsim.FABRICS; camel ponte roma, navy sparkle fleece), for RGB baselines.
FABRIC_COLORS = {
  'white_tablecloth': (0.9, 0.9, 0.88),
  'gray_interlock': (0.55, 0.55, 0.56),
  'black_denim': (0.12, 0.12, 0.14),
  'sparkle_fleece': (0.15, 0.17, 0.35),
  'pink_nylon': (0.95, 0.6, 0.7),
  'ponte_roma': (0.76, 0.6, 0.42),
  'red_violet': (0.6, 0.12, 0.3),
  'default': (0.7, 0.7, 0.7),
}

_NEAR = 1e-2  # metres; closer triangles are skipped
_MIN_AREA = 1e-12  # px^2; degenerate (edge-on) projected triangles are skipped
_DEFAULT_LIGHT = (0.3, -1.0, 0.8)  # world direction toward the light: front, above
_AMBIENT = 0.25


class _Triangles(NamedTuple):
  """Projected triangles of one frame, each field (F,) or (F, 3)."""

  u: jax.Array  # (F, 3) pixel columns of the corners
  v: jax.Array  # (F, 3) pixel rows
  inv_z: jax.Array  # (F, 3) 1 / camera z of the corners
  inv_area: jax.Array  # (F,) 1 / (twice the signed screen area)
  valid: jax.Array  # (F,) bool


def _camera_coords(vertices, pose: Pose):
  """(V, 3) vertices in camera coordinates: R^T (X - p)."""
  r = jnp.asarray(pose.rotation, jnp.float32)
  p = jnp.asarray(pose.position, jnp.float32)
  return (jnp.asarray(vertices, jnp.float32) - p) @ r


def _project(vertices, faces, intrinsics: Intrinsics, pose: Pose) -> _Triangles:
  xc = _camera_coords(vertices, pose)
  z = xc[:, 2]
  safe_z = jnp.where(z > _NEAR, z, 1.0)
  u = intrinsics.fx * xc[:, 0] / safe_z + intrinsics.cx
  v = intrinsics.fy * xc[:, 1] / safe_z + intrinsics.cy
  u, v, z, safe_z = u[faces], v[faces], z[faces], safe_z[faces]  # (F, 3) each
  area = (u[:, 1] - u[:, 0]) * (v[:, 2] - v[:, 0]) - (u[:, 2] - u[:, 0]) * (
    v[:, 1] - v[:, 0]
  )
  valid = jnp.all(z > _NEAR, axis=1) & (jnp.abs(area) > _MIN_AREA)
  inv_area = jnp.where(valid, 1.0 / jnp.where(valid, area, 1.0), 0.0)
  return _Triangles(u, v, 1.0 / safe_z, inv_area, valid)


def _pair_depth(t: _Triangles, px, py):
  """Depth of triangle(s) ``t`` at pixel centre(s) (px, py); inf where missed.

  All arguments broadcast: ``t`` fields indexed down to (...,) / (..., 3).
  """
  du = t.u - px[..., None]
  dv = t.v - py[..., None]
  # Edge function of the edge opposite each corner, each from its own two
  # corners only, so a shared edge gives exactly opposite values in the two
  # triangles that share it (watertight).
  e0 = du[..., 1] * dv[..., 2] - du[..., 2] * dv[..., 1]
  e1 = du[..., 2] * dv[..., 0] - du[..., 0] * dv[..., 2]
  e2 = du[..., 0] * dv[..., 1] - du[..., 1] * dv[..., 0]
  b0, b1, b2 = e0 * t.inv_area, e1 * t.inv_area, e2 * t.inv_area
  inside = t.valid & (b0 >= 0) & (b1 >= 0) & (b2 >= 0)
  inv_depth = b0 * t.inv_z[..., 0] + b1 * t.inv_z[..., 1] + b2 * t.inv_z[..., 2]
  return jnp.where(inside & (inv_depth > 0), 1.0 / inv_depth, jnp.inf)


def _pixel_grid(intrinsics: Intrinsics):
  py, px = jnp.meshgrid(
    jnp.arange(intrinsics.height, dtype=jnp.float32),
    jnp.arange(intrinsics.width, dtype=jnp.float32),
    indexing='ij',
  )
  return px.ravel(), py.ravel()  # (H W,) each, row-major


def _brute_nearest(t: _Triangles, intrinsics: Intrinsics, block: int = 64):
  """(H W,) nearest depth (inf if none) and triangle index (F if none)."""
  n_tri = t.u.shape[0]
  pad = -n_tri % block
  t = jax.tree.map(
    lambda a: jnp.concatenate([a, jnp.zeros((pad,) + a.shape[1:], a.dtype)]), t
  )
  blocks = jax.tree.map(lambda a: a.reshape((-1, block) + a.shape[1:]), t)
  px, py = _pixel_grid(intrinsics)

  def body(carry, xs):
    best_z, best_i = carry
    tb, first = xs
    z = _pair_depth(
      jax.tree.map(lambda a: a[None], tb), px[:, None], py[:, None]
    )  # (HW, block)
    j = jnp.argmin(z, axis=1)
    zj = jnp.min(z, axis=1)
    better = zj < best_z  # strict: ties keep the lower triangle index
    return (jnp.where(better, zj, best_z), jnp.where(better, first + j, best_i)), None

  init = (
    jnp.full(px.shape, jnp.inf, jnp.float32),
    jnp.full(px.shape, n_tri, jnp.int32),
  )
  firsts = jnp.arange(0, n_tri + pad, block, dtype=jnp.int32)
  (best_z, best_i), _ = jax.lax.scan(body, init, (blocks, firsts))
  return best_z, jnp.where(best_i < n_tri, best_i, n_tri)


def _raster_boxes(t: _Triangles, intrinsics: Intrinsics):
  """Per-triangle pixel bounding boxes clipped to the image: x0, y0, w, count."""
  w_img, h_img = intrinsics.width, intrinsics.height
  # Clamp before rounding so far-off or huge coordinates stay finite ints.
  umin = jnp.clip(jnp.min(t.u, axis=1), -1.0, w_img)
  umax = jnp.clip(jnp.max(t.u, axis=1), -1.0, w_img)
  vmin = jnp.clip(jnp.min(t.v, axis=1), -1.0, h_img)
  vmax = jnp.clip(jnp.max(t.v, axis=1), -1.0, h_img)
  x0 = jnp.maximum(jnp.ceil(umin), 0).astype(jnp.int32)
  x1 = jnp.minimum(jnp.floor(umax), w_img - 1).astype(jnp.int32)
  y0 = jnp.maximum(jnp.ceil(vmin), 0).astype(jnp.int32)
  y1 = jnp.minimum(jnp.floor(vmax), h_img - 1).astype(jnp.int32)
  w = jnp.maximum(x1 - x0 + 1, 0)
  h = jnp.maximum(y1 - y0 + 1, 0)
  count = jnp.where(t.valid, w * h, 0)
  return x0, y0, w, count


def _raster_pass(t, boxes, intrinsics, n_frag, reduce_fn, init):
  """Loops over all bounding-box fragments, ``n_frag`` at a time.

  ``reduce_fn(state, pix, depth, tri)`` folds one pass of fragments (pix = H W
  for fragments to drop) into ``state``.
  """
  x0, y0, w, count = boxes
  n_tri = count.shape[0]
  ends = jnp.cumsum(count)  # inclusive
  starts = ends - count
  total = ends[-1]
  lanes = jnp.arange(n_frag, dtype=jnp.int32)
  tri_ids = jnp.arange(n_tri, dtype=jnp.int32)
  n_pix = intrinsics.width * intrinsics.height

  def body(carry):
    base, state = carry
    idx = base + lanes
    # Owner triangle of each fragment: mark where each box starts, then a
    # running max; lane 0 takes the box that contains ``base``.
    rel = starts - base
    rel = jnp.where((rel >= 0) & (rel < n_frag) & (count > 0), rel, n_frag)
    marks = jnp.zeros(n_frag, jnp.int32).at[rel].max(tri_ids, mode='drop')
    first = jnp.searchsorted(ends, base, side='right').astype(jnp.int32)
    marks = marks.at[0].max(jnp.minimum(first, n_tri - 1))
    tri = jax.lax.cummax(marks)
    active = idx < total
    local = idx - starts[tri]
    wt = jnp.maximum(w[tri], 1)
    px = x0[tri] + local % wt
    py = y0[tri] + local // wt
    tt = jax.tree.map(lambda a: a[tri], t)
    depth = _pair_depth(tt, px.astype(jnp.float32), py.astype(jnp.float32))
    hit = active & jnp.isfinite(depth)
    pix = jnp.where(hit, py * intrinsics.width + px, n_pix)
    return base + n_frag, reduce_fn(state, pix, depth, tri)

  _, state = jax.lax.while_loop(lambda c: c[0] < total, body, (jnp.int32(0), init))
  return state


def _raster_depth(t, intrinsics, n_frag):
  boxes = _raster_boxes(t, intrinsics)
  n_pix = intrinsics.width * intrinsics.height

  def reduce_fn(zbuf, pix, depth, tri):
    del tri
    return zbuf.at[pix].min(depth, mode='drop')

  init = jnp.full(n_pix, jnp.inf, jnp.float32)
  return _raster_pass(t, boxes, intrinsics, n_frag, reduce_fn, init), boxes


def _raster_nearest(t: _Triangles, intrinsics: Intrinsics, n_frag: int):
  """(H W,) nearest depth (inf if none) and triangle index (F if none)."""
  zbuf, boxes = _raster_depth(t, intrinsics, n_frag)
  n_tri = t.u.shape[0]

  def reduce_fn(ids, pix, depth, tri):
    # Second pass: the lowest-index triangle achieving the buffer's depth.
    on_top = depth == zbuf[jnp.minimum(pix, zbuf.shape[0] - 1)]
    return ids.at[jnp.where(on_top, pix, zbuf.shape[0])].min(tri, mode='drop')

  init = jnp.full(zbuf.shape, n_tri, jnp.int32)
  ids = _raster_pass(t, boxes, intrinsics, n_frag, reduce_fn, init)
  return zbuf, ids


def _check(vertices, faces, intrinsics, method):
  if not isinstance(intrinsics, Intrinsics):
    raise ValueError(f'intrinsics must be an Intrinsics, got {type(intrinsics)}')
  if method not in METHODS:
    raise ValueError(f'method must be one of {METHODS}, got {method!r}')
  if vertices.ndim != 2 or vertices.shape[-1] != 3:
    raise ValueError(f'vertices must be (V, 3), got {vertices.shape}')
  if faces.ndim != 2 or faces.shape[-1] != 3 or faces.shape[0] < 1:
    raise ValueError(f'faces must be (F, 3) with F >= 1, got {faces.shape}')


def _default_frags(intrinsics: Intrinsics, fragments_per_pass: int | None) -> int:
  if fragments_per_pass is None:
    return max(1024, intrinsics.width * intrinsics.height // 2)
  if fragments_per_pass < 1:
    raise ValueError(f'fragments_per_pass must be >= 1, got {fragments_per_pass}')
  return int(fragments_per_pass)


def depth_image(
  vertices,
  faces,
  intrinsics: Intrinsics,
  pose: Pose,
  method: str = 'raster',
  fragments_per_pass: int | None = None,
) -> jax.Array:
  """Z-depth image of one mesh from one camera.

  Args:
    vertices: (V, 3) world positions, metres.
    faces: (F, 3) int vertex indices (either winding; both sides are seen).
    intrinsics: the camera's static intrinsics.
    pose: one camera pose, rotation (3, 3), position (3,).
    method: ``'raster'`` (fast) or ``'brute'`` (reference); the same depths.
    fragments_per_pass: raster only; bounding-box pixels tested per loop pass
      (default H W / 2). Larger uses more memory and fewer passes.

  Returns:
    (H, W) float32 depth along the optical axis, metres; 0.0 where no triangle
    is hit.
  """
  vertices = jnp.asarray(vertices)
  faces = jnp.asarray(faces)
  _check(vertices, faces, intrinsics, method)
  t = _project(vertices, faces, intrinsics, pose)
  if method == 'brute':
    z, _ = _brute_nearest(t, intrinsics)
  else:
    z, _ = _raster_depth(t, intrinsics, _default_frags(intrinsics, fragments_per_pass))
  z = jnp.where(jnp.isfinite(z), z, 0.0)
  return z.reshape(intrinsics.height, intrinsics.width)


def shade_rgb(
  vertices,
  faces,
  intrinsics: Intrinsics,
  pose: Pose,
  color=FABRIC_COLORS['default'],
  light_dir=_DEFAULT_LIGHT,
  ambient: float = _AMBIENT,
  background=(0.0, 0.0, 0.0),
  method: str = 'raster',
  fragments_per_pass: int | None = None,
) -> jax.Array:
  """Two-sided Lambert-shaded colour image of one mesh from one camera.

  Each triangle is flat-shaded with its normal turned toward the camera, so
  both sides of the cloth look alike: ``color * (ambient + (1 - ambient) *
  max(0, n . l))``.

  Args:
    vertices: (V, 3) world positions, metres.
    faces: (F, 3) int vertex indices.
    intrinsics: static intrinsics.
    pose: one camera pose.
    color: (3,) RGB in [0, 1], e.g. ``FABRIC_COLORS['denim']``.
    light_dir: (3,) world direction toward a distant light.
    ambient: fraction of the colour shown without direct light.
    background: (3,) RGB where no triangle is hit.
    method: ``'raster'`` or ``'brute'``.
    fragments_per_pass: as in `depth_image`.

  Returns:
    (H, W, 3) float32 in [0, 1].
  """
  vertices = jnp.asarray(vertices)
  faces = jnp.asarray(faces)
  _check(vertices, faces, intrinsics, method)
  t = _project(vertices, faces, intrinsics, pose)
  if method == 'brute':
    _, ids = _brute_nearest(t, intrinsics)
  else:
    _, ids = _raster_nearest(
      t, intrinsics, _default_frags(intrinsics, fragments_per_pass)
    )
  xc = _camera_coords(vertices, pose)[faces]  # (F, 3, 3)
  n = jnp.cross(xc[:, 1] - xc[:, 0], xc[:, 2] - xc[:, 0])
  n = n / jnp.maximum(jnp.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
  n = jnp.where(jnp.sum(n * xc[:, 0], axis=-1, keepdims=True) > 0, -n, n)
  light = jnp.asarray(light_dir, jnp.float32)
  light = (light / jnp.linalg.norm(light)) @ jnp.asarray(pose.rotation, jnp.float32)
  lambert = ambient + (1.0 - ambient) * jnp.maximum(n @ light, 0.0)  # (F,)
  lambert = jnp.concatenate([lambert, jnp.zeros(1, lambert.dtype)])[ids]
  hit = (ids < faces.shape[0])[:, None]
  rgb = jnp.where(
    hit,
    lambert[:, None] * jnp.asarray(color, jnp.float32),
    jnp.asarray(background, jnp.float32),
  )
  return jnp.clip(rgb, 0.0, 1.0).reshape(intrinsics.height, intrinsics.width, 3)


def _default_chunk(method: str, chunk: int | None) -> int:
  if chunk is None:
    return 16 if method == 'brute' else 256
  if chunk < 1:
    raise ValueError(f'chunk must be >= 1, got {chunk}')
  return int(chunk)


def _render_batched(frame_fn, positions, poses: Pose, chunk: int):
  """Maps ``frame_fn(vertices, pose)`` over (B, C, T) frames, ``chunk`` at a time."""
  positions = jnp.asarray(positions)
  if positions.ndim != 4 or positions.shape[-1] != 3:
    raise ValueError(f'positions must be (B, T, V, 3), got {positions.shape}')
  rot = jnp.asarray(poses.rotation, jnp.float32)
  pos = jnp.asarray(poses.position, jnp.float32)
  b, t = positions.shape[:2]
  if rot.shape[:1] != (b,) or rot.ndim != 4 or pos.shape != rot.shape[:2] + (3,):
    raise ValueError(
      f'poses must have rotation (B, C, 3, 3) and position (B, C, 3) with B={b}, '
      f'got {rot.shape} and {pos.shape}'
    )
  c = rot.shape[1]

  def one(i):
    bi, ci, ti = i // (c * t), (i // t) % c, i % t
    return frame_fn(positions[bi, ti], Pose(rot[bi, ci], pos[bi, ci]))

  frames = jax.lax.map(one, jnp.arange(b * c * t, dtype=jnp.int32), batch_size=chunk)
  return frames.reshape((b, c, t) + frames.shape[1:])


def render_depth(
  positions,
  faces,
  intrinsics: Intrinsics,
  poses: Pose,
  method: str = 'raster',
  chunk: int | None = None,
  fragments_per_pass: int | None = None,
) -> jax.Array:
  """Depth video of every (world, camera, frame).

  Args:
    positions: (B, T, V, 3) vertex trajectories, metres.
    faces: (F, 3) int vertex indices, shared by all worlds.
    intrinsics: static intrinsics.
    poses: Pose with rotation (B, C, 3, 3), position (B, C, 3).
    method: ``'raster'`` or ``'brute'``.
    chunk: frames rendered at once (vmapped); chunks run one after another, so
      memory is bounded by ``chunk`` (default 256 raster, 16 brute).
    fragments_per_pass: as in `depth_image`.

  Returns:
    (B, C, T, H, W) float32 depths, 0.0 where empty.
  """
  fn = functools.partial(
    depth_image,
    faces=jnp.asarray(faces),
    intrinsics=intrinsics,
    method=method,
    fragments_per_pass=fragments_per_pass,
  )
  return _render_batched(
    lambda v, p: fn(v, pose=p), positions, poses, _default_chunk(method, chunk)
  )


def render_rgb(
  positions,
  faces,
  intrinsics: Intrinsics,
  poses: Pose,
  color=FABRIC_COLORS['default'],
  light_dir=_DEFAULT_LIGHT,
  method: str = 'raster',
  chunk: int | None = None,
  fragments_per_pass: int | None = None,
) -> jax.Array:
  """Shaded colour video of every (world, camera, frame), as `shade_rgb`.

  Args:
    positions: (B, T, V, 3) vertex trajectories, metres.
    faces: (F, 3) int vertex indices.
    intrinsics: static intrinsics.
    poses: Pose with rotation (B, C, 3, 3), position (B, C, 3).
    color: (3,) RGB in [0, 1] shared by all worlds.
    light_dir: (3,) world direction toward the light.
    method: ``'raster'`` or ``'brute'``.
    chunk: frames rendered at once.
    fragments_per_pass: as in `depth_image`.

  Returns:
    (B, C, T, H, W, 3) float32 in [0, 1].
  """

  def fn(v, p):
    return shade_rgb(
      v,
      jnp.asarray(faces),
      intrinsics,
      p,
      color=color,
      light_dir=light_dir,
      method=method,
      fragments_per_pass=fragments_per_pass,
    )

  return _render_batched(fn, positions, poses, _default_chunk(method, chunk))


def render_rgb8(
  positions,
  faces,
  intrinsics: Intrinsics,
  poses: Pose,
  colors,
  method: str = 'raster',
) -> jax.Array:
  """8-bit colour video of worlds of different colours, as datasets store it.

  Shades in white once and tints each world (the shading is lambert times the
  colour on a black background, so tinting commutes with it up to rounding),
  then rounds to 8 bits.

  Args:
    positions: (B, T, V, 3) vertex trajectories, metres.
    faces: (F, 3) int vertex indices.
    intrinsics: static intrinsics.
    poses: Pose with rotation (B, C, 3, 3), position (B, C, 3).
    colors: (B, 3) RGB in [0, 1], one per world.
    method: ``'raster'`` or ``'brute'``.

  Returns:
    (B, C, T, H, W, 3) uint8.
  """
  white = render_rgb(
    positions, faces, intrinsics, poses, (1.0, 1.0, 1.0), method=method
  )
  tint = jnp.asarray(colors, jnp.float32)[:, None, None, None, None, :]
  return jnp.round(jnp.clip(white * tint, 0.0, 1.0) * 255).astype(jnp.uint8)


def make_depth_renderer(
  faces,
  intrinsics: Intrinsics,
  method: str = 'raster',
  chunk: int | None = None,
  fragments_per_pass: int | None = None,
):
  """A jitted ``fn(positions (B, T, V, 3), poses (B, C)) -> (B, C, T, H, W)``.

  The faces and settings are baked in; new positions or poses of the same
  shapes reuse the compiled program.
  """
  faces = np.asarray(faces, np.int32)
  if method not in METHODS:
    raise ValueError(f'method must be one of {METHODS}, got {method!r}')

  @jax.jit
  def fn(positions, poses):
    return render_depth(
      positions,
      faces,
      intrinsics,
      poses,
      method=method,
      chunk=chunk,
      fragments_per_pass=fragments_per_pass,
    )

  return fn
