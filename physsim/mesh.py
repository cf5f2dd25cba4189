"""Flat triangle meshes: the square cloth and single-panel garment outlines.

All meshes are built in the x-z plane (y = 0), x to the right and z up, so the
cloth hangs facing the fan, which blows along +y. Squares are triangulated with
alternating diagonals: a uniform diagonal direction makes the sheet fold more
easily one way than the other, and crossing them halves that bias.
"""

from __future__ import annotations

import dataclasses

import numpy as np

GARMENTS = ('tshirt', 'shirt', 'jeans')

# Outlines in metres, counter-clockwise, (x, z); symmetric about x = 0.
_HALF_OUTLINES = {
  # hem, side, armpit, sleeve end, shoulder, neck
  'tshirt': [
    (0.26, 0.0),
    (0.26, 0.44),
    (0.42, 0.36),
    (0.50, 0.52),
    (0.30, 0.70),
    (0.10, 0.72),
    (0.0, 0.66),
  ],
  # long sleeves that hang down and out
  'shirt': [
    (0.28, 0.0),
    (0.28, 0.46),
    (0.58, 0.04),
    (0.70, 0.12),
    (0.36, 0.72),
    (0.10, 0.76),
    (0.0, 0.70),
  ],
  # leg hem, outseam, waistband; the crotch is added below
  'jeans': [(0.06, 0.0), (0.27, 0.0), (0.24, 1.0), (0.0, 1.0)],
}


@dataclasses.dataclass(frozen=True)
class Mesh:
  """A flat triangle mesh at rest.

  Attributes:
    vertices: (V, 3) rest positions, metres.
    faces: (F, 3) vertex indices, one orientation (normals along -y at rest).
    pinned: (P,) indices of vertices held fixed.
    name: what it is, e.g. ``'square25'`` or ``'tshirt'``.
  """

  vertices: np.ndarray
  faces: np.ndarray
  pinned: np.ndarray
  name: str

  @property
  def face_areas(self) -> np.ndarray:
    """(F,) rest areas, m^2."""
    p = self.vertices[self.faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

  @property
  def vertex_areas(self) -> np.ndarray:
    """(V,) a third of each adjacent face's area (ArcSim's lumped mass rule)."""
    out = np.zeros(len(self.vertices))
    np.add.at(out, self.faces.ravel(), np.repeat(self.face_areas / 3.0, 3))
    return out

  @property
  def area(self) -> float:
    return float(self.face_areas.sum())

  @property
  def shortest_edge(self) -> float:
    """The shortest rest edge, metres (what limits the simulator's step)."""
    p = self.vertices[self.faces]
    edges = p - np.roll(p, 1, axis=1)
    return float(np.linalg.norm(edges, axis=-1).min())

  @property
  def edges(self) -> np.ndarray:
    """(E, 2) unique undirected edges, sorted."""
    e = np.concatenate(
      [self.faces[:, [0, 1]], self.faces[:, [1, 2]], self.faces[:, [2, 0]]]
    )
    return np.unique(np.sort(e, axis=1), axis=0)


def _grid_faces(mask: np.ndarray) -> np.ndarray:
  """Alternating-diagonal triangles of every grid cell whose 4 corners are in."""
  rows, cols = mask.shape
  idx = np.arange(rows * cols).reshape(rows, cols)
  faces = []
  for i in range(rows - 1):
    for j in range(cols - 1):
      if not mask[i : i + 2, j : j + 2].all():
        continue
      a, b, c, d = idx[i, j], idx[i, j + 1], idx[i + 1, j], idx[i + 1, j + 1]
      faces += [(a, c, d), (a, d, b)] if (i + j) % 2 == 0 else [(a, c, b), (b, c, d)]
  return np.asarray(faces, dtype=np.int64)


def square(resolution: int = 25, size: float = 1.0, height: float = 1.5) -> Mesh:
  """A ``size`` x ``size`` square, ``resolution`` vertices a side, top at ``height``.

  The two top corners are pinned, as in the paper's setup.
  """
  if resolution < 3:
    raise ValueError(f'resolution must be >= 3 vertices a side, got {resolution}')
  if not size > 0:
    raise ValueError(f'size must be > 0 m, got {size}')
  s = np.linspace(-size / 2, size / 2, resolution)
  x, z = np.meshgrid(s, height - (s + size / 2))  # row 0 at the top
  verts = np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)
  faces = _grid_faces(np.ones((resolution, resolution), bool))
  pinned = np.array([0, resolution - 1])
  return Mesh(verts, faces, pinned, f'square{resolution}')


def _outline(name: str) -> np.ndarray:
  half = np.asarray(_HALF_OUTLINES[name])
  if name == 'jeans':
    half = np.concatenate([[(0.0, 0.72)], half])  # crotch point
  mirror = half[::-1] * [-1, 1]
  return np.concatenate([half, mirror[1:-1] if half[0, 0] == 0 else mirror])


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
  """Even-odd point-in-polygon test, vectorised over points."""
  x, y = pts[:, 0], pts[:, 1]
  out = np.zeros(len(pts), bool)
  for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, axis=0), strict=True):
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide='ignore', invalid='ignore'):
      xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    out ^= crosses & (x < xc)
  return out


def garment(name: str, spacing: float = 0.04, height: float = 1.5) -> Mesh:
  """A flat single-panel garment (``'tshirt'``, ``'shirt'``, ``'jeans'``).

  The outline is rasterised on a grid of ``spacing`` metres; every cell whose
  four corners are inside becomes two triangles. The two top-most vertices at the
  far left and right of the top edge (shoulders, or the waistband) are pinned.
  """
  if name not in GARMENTS:
    raise ValueError(f'unknown garment {name!r}; choose one of {GARMENTS}')
  if not 0.005 <= spacing <= 0.2:
    raise ValueError(f'spacing must be in [0.005, 0.2] m, got {spacing}')
  poly = _outline(name)
  top = poly[:, 1].max()
  xs = np.arange(poly[:, 0].min(), poly[:, 0].max() + 1e-9, spacing)
  zs = np.arange(top, -1e-9, -spacing)
  gx, gz = np.meshgrid(xs, zs)
  inside = _inside(poly, np.stack([gx.ravel(), gz.ravel()], 1)).reshape(gx.shape)
  faces = _grid_faces(inside)
  used = np.unique(faces)
  remap = -np.ones(gx.size, np.int64)
  remap[used] = np.arange(len(used))
  verts = np.stack([gx.ravel(), np.zeros(gx.size), height - top + gz.ravel()], 1)[used]
  faces = remap[faces]
  ztop = verts[:, 2].max()
  top_row = np.flatnonzero(np.isclose(verts[:, 2], ztop))
  pinned = np.array(
    [top_row[np.argmin(verts[top_row, 0])], top_row[np.argmax(verts[top_row, 0])]]
  )
  return Mesh(verts, faces, pinned, name)
