"""Tessellation helpers the synthetic primitives build their ground-truth surfaces from.

:class:`Surface` (vertices, faces, exact normals, part labels), grids, rectangles, box
faces and circle segment counts; :mod:`eslam.synthetic.primitives` uses them and
:mod:`eslam.synthetic.mesh` gathers the surfaces into the scene mesh. Curved surfaces
stay within MESH_TOLERANCE of the exact ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MESH_TOLERANCE = 2e-4
"""Largest distance (m) between a curved surface and its ground-truth tessellation."""
MESH_SPACING = 0.05
"""Grid spacing (m) of planar and cylindrical faces in the mesh, for vertex colours."""


@dataclass(frozen=True, eq=False)
class Surface:
    """A triangulated piece of a primitive with exact per-vertex normals.

    Attributes:
        vertices: (V, 3) float64, m.  faces: (F, 3) int64.  normals: (V, 3) unit.
        parts: (V,) int64 part index (which face of a box, side or cap of a cylinder).
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    parts: np.ndarray

    def oriented(self) -> Surface:
        """The same surface with every triangle wound counter-clockwise about its normal."""
        tri = self.vertices[self.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        flip = np.einsum("fi,fi->f", cross, self.normals[self.faces].sum(axis=1)) < 0
        faces = np.where(flip[:, None], self.faces[:, ::-1], self.faces)
        return Surface(self.vertices, faces, self.normals, self.parts)


def merge_surfaces(surfaces: list[Surface]) -> Surface:
    """Concatenate surfaces into one (face indices shifted)."""
    offsets = np.cumsum([0] + [len(s.vertices) for s in surfaces])
    return Surface(
        np.concatenate([s.vertices for s in surfaces]),
        np.concatenate([s.faces + o for s, o in zip(surfaces, offsets, strict=False)]),
        np.concatenate([s.normals for s in surfaces]),
        np.concatenate([s.parts for s in surfaces]),
    )


def grid_faces(rows: int, cols: int, wrap: bool = False) -> np.ndarray:
    """Two triangles per cell of a (rows+1) x cols(+1) vertex grid; ``wrap`` closes columns."""
    width = cols if wrap else cols + 1
    index = np.arange((rows + 1) * width).reshape(rows + 1, width)
    right = np.roll(index, -1, axis=1) if wrap else index[:, 1:]
    left = index if wrap else index[:, :-1]
    a, b, c, d = left[:-1], right[:-1], right[1:], left[1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])
    return faces.reshape(-1, 3).astype(np.int64)


def _rectangle(corner, edge_u, edge_v, normal, part: int) -> Surface:
    rows = max(1, math.ceil(np.linalg.norm(edge_u) / MESH_SPACING))
    cols = max(1, math.ceil(np.linalg.norm(edge_v) / MESH_SPACING))
    a = np.linspace(0.0, 1.0, rows + 1)[:, None, None]
    b = np.linspace(0.0, 1.0, cols + 1)[None, :, None]
    vertices = (np.asarray(corner) + a * edge_u + b * edge_v).reshape(-1, 3)
    normals = np.broadcast_to(np.asarray(normal, dtype=np.float64), vertices.shape).copy()
    parts = np.full(len(vertices), part, dtype=np.int64)
    return Surface(vertices, grid_faces(rows, cols), normals, parts).oriented()


def circle_segments(radius: float, tolerance: float = MESH_TOLERANCE) -> int:
    """Segments n of a circle polygon with sagitta r (1 - cos(pi / n)) <= tolerance (>= 128)."""
    return max(128, math.ceil(math.pi / math.acos(1.0 - tolerance / radius)))


def box_faces(lo, hi, skip: tuple[int, ...] = ()) -> list[Surface]:
    """Faces of the box [lo, hi]; part 2a is the face at lo[a], 2a+1 at hi[a], normals outward."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    surfaces = []
    for axis in range(3):
        u, v = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
        size = hi - lo
        for side, plane in enumerate((lo[axis], hi[axis])):
            if 2 * axis + side in skip:
                continue
            corner = lo.copy()
            corner[axis] = plane
            normal = np.eye(3)[axis] * (1.0 if side else -1.0)
            surfaces.append(
                _rectangle(corner, u * (size @ u), v * (size @ v), normal, 2 * axis + side)
            )
    return surfaces
