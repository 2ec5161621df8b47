"""Analytic scene primitives: closed-form ray intersection, normals, albedo, tessellation.

A :class:`Scene` is a tuple of primitives (an inward-facing room box, boxes, spheres,
vertical cylinders), each with a procedural material (:mod:`eslam.synthetic.materials`).
Each primitive intersects rays in closed form (:mod:`eslam.synthetic.render` keeps the
nearest hit over all of them) and tessellates itself for the ground-truth mesh
(:mod:`eslam.synthetic.tessellation`, :mod:`eslam.synthetic.mesh`).

World frame: metres, z up, the floor at z = 0.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from eslam.synthetic.materials import Material
from eslam.synthetic.tessellation import (
    MESH_SPACING,
    MESH_TOLERANCE,
    Surface,
    box_faces,
    circle_segments,
    grid_faces,
    merge_surfaces,
)

_BIG = 1e300  # stands in for 1/0 in slab tests


class Primitive(Protocol):
    """What the renderer and the mesher need from a primitive."""

    name: str

    def intersect(
        self, origin: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nearest hit with t > 0 of rays origin + t * d: t (N,) (inf = miss), part (N,) int."""
        ...

    def normals(self, points: np.ndarray, parts: np.ndarray) -> np.ndarray:
        """(M, 3) unit normals facing the side the camera sees, at surface ``points``."""
        ...

    def albedo(self, points: np.ndarray, parts: np.ndarray) -> np.ndarray:
        """(M, 3) RGB in [0, 1] at surface ``points``."""
        ...

    def surface(self) -> Surface:
        """The triangulated surface (within MESH_TOLERANCE of the exact one)."""
        ...


def _safe(directions: np.ndarray) -> np.ndarray:
    return np.where(directions == 0.0, 1.0 / _BIG, directions)


def _axis_normals(parts: np.ndarray, inward: bool) -> np.ndarray:
    normals = np.zeros((len(parts), 3))
    sign = np.where(parts % 2 == 1, 1.0, -1.0) * (-1.0 if inward else 1.0)
    normals[np.arange(len(parts)), parts // 2] = sign
    return normals


@dataclass(frozen=True, eq=False)
class RoomBox:
    """The room: an axis-aligned box seen from INSIDE (camera must be inside).

    Parts 0..5: walls at x = lo, x = hi, y = lo, y = hi, the floor, the ceiling; each
    with its own material. Normals point into the room.
    """

    lo: np.ndarray
    hi: np.ndarray
    materials: tuple[Material, ...]
    name: str = "room"

    def intersect(self, origin, directions):
        d = _safe(directions)
        t = (np.where(d > 0, self.hi, self.lo) - origin) / d
        axis = np.argmin(t, axis=1)
        rows = np.arange(len(t))
        return t[rows, axis], 2 * axis + (d[rows, axis] > 0)

    def normals(self, points, parts):
        return _axis_normals(parts, inward=True)

    def albedo(self, points, parts):
        colours = np.empty((len(points), 3))
        for part, material in enumerate(self.materials):
            mask = parts == part
            colours[mask] = material.albedo(points[mask])
        return colours

    def surface(self):
        inward = [
            Surface(s.vertices, s.faces, -s.normals, s.parts).oriented()
            for s in box_faces(self.lo, self.hi)
        ]
        return merge_surfaces(inward)


@dataclass(frozen=True, eq=False)
class Box:
    """A box of half extents ``half`` centred at ``centre``, rotated by ``yaw`` about z.

    Parts 2a / 2a+1: the faces at -half[a] / +half[a] (local axes). ``hidden`` parts
    (faces flush with the floor or a wall, never observable) are left out of the mesh.
    """

    centre: np.ndarray
    half: np.ndarray
    yaw: float
    material: Material
    name: str = "box"
    hidden: tuple[int, ...] = (4,)

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return self.centre, float(np.linalg.norm(self.half))

    @functools.cached_property
    def rotation(self) -> np.ndarray:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def intersect(self, origin, directions):
        local_origin = (origin - self.centre) @ self.rotation
        d = _safe(directions @ self.rotation)
        t1, t2 = (-self.half - local_origin) / d, (self.half - local_origin) / d
        entry = np.minimum(t1, t2)
        near, far = entry.max(axis=1), np.maximum(t1, t2).min(axis=1)
        axis = entry.argmax(axis=1)
        hit = (near <= far) & (near > 0)
        return np.where(hit, near, np.inf), 2 * axis + (d[np.arange(len(d)), axis] < 0)

    def normals(self, points, parts):
        return _axis_normals(parts, inward=False) @ self.rotation.T

    def albedo(self, points, parts):
        return self.material.albedo(points)

    def surface(self):
        merged = merge_surfaces(box_faces(-self.half, self.half, self.hidden))
        return Surface(
            merged.vertices @ self.rotation.T + self.centre,
            merged.faces,
            merged.normals @ self.rotation.T,
            merged.parts,
        )


@dataclass(frozen=True, eq=False)
class Sphere:
    """A sphere (camera must be outside)."""

    centre: np.ndarray
    radius: float
    material: Material
    name: str = "sphere"

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return self.centre, self.radius

    def intersect(self, origin, directions):
        offset = origin - self.centre
        a = np.einsum("ni,ni->n", directions, directions)
        b = directions @ offset
        disc = b * b - a * (offset @ offset - self.radius**2)
        t = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
        return np.where((disc >= 0) & (t > 0), t, np.inf), np.zeros(len(t), dtype=np.int64)

    def normals(self, points, parts):
        return (points - self.centre) / self.radius

    def albedo(self, points, parts):
        return self.material.albedo(points)

    def rings(self) -> int:
        """Latitude bands n (longitudes 2n) of the UV sphere.

        Every triangle's vertices lie within the angle alpha = pi / (sqrt(2) n) of its
        cell centre, so the triangle is above the cap's base plane and deviates from
        the sphere by at most r (1 - cos alpha) <= MESH_TOLERANCE.
        """
        alpha = math.acos(1.0 - MESH_TOLERANCE / self.radius)
        return max(64, math.ceil(math.pi / (math.sqrt(2.0) * alpha)))

    def surface(self):
        n = self.rings()
        theta = math.pi * np.arange(1, n) / n
        phi = 2 * math.pi * np.arange(2 * n) / (2 * n)
        ring = np.stack(
            [
                np.sin(theta)[:, None] * np.cos(phi),
                np.sin(theta)[:, None] * np.sin(phi),
                np.broadcast_to(np.cos(theta)[:, None], (n - 1, 2 * n)),
            ],
            axis=-1,
        ).reshape(-1, 3)
        unit = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]])
        j = np.arange(2 * n)
        north = np.stack([np.zeros_like(j), 1 + j, 1 + (j + 1) % (2 * n)], -1)
        last = len(unit) - 1
        south = np.stack(
            [np.full_like(j, last), last - 2 * n + (j + 1) % (2 * n), last - 2 * n + j], -1
        )
        faces = np.concatenate([north, grid_faces(n - 2, 2 * n, wrap=True) + 1, south])
        parts = np.zeros(len(unit), dtype=np.int64)
        return Surface(self.centre + self.radius * unit, faces, unit, parts).oriented()


@dataclass(frozen=True, eq=False)
class Cylinder:
    """A vertical cylinder, axis through ``centre`` (x, y), from z = z0 to z = z1, capped.

    Parts: 0 side, 1 top cap, 2 bottom cap. ``on_floor`` leaves the bottom cap out of
    the mesh.
    """

    centre: np.ndarray
    radius: float
    z0: float
    z1: float
    material: Material
    name: str = "cylinder"
    on_floor: bool = True

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        centre = np.array([*self.centre, (self.z0 + self.z1) / 2])
        return centre, math.hypot(self.radius, (self.z1 - self.z0) / 2)

    def intersect(self, origin, directions):
        ox, oy = origin[:2] - self.centre
        dx, dy, dz = directions[:, 0], directions[:, 1], directions[:, 2]
        a = dx * dx + dy * dy
        b = dx * ox + dy * oy
        disc = b * b - a * (ox * ox + oy * oy - self.radius**2)
        with np.errstate(divide="ignore", invalid="ignore"):
            side = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
            z = origin[2] + side * dz
        side = np.where((disc >= 0) & (side > 0) & (z >= self.z0) & (z <= self.z1), side, np.inf)
        candidates = [side]
        dz = _safe(dz)
        for height in (self.z1, self.z0):
            t = (height - origin[2]) / dz
            inside = (ox + t * dx) ** 2 + (oy + t * dy) ** 2 <= self.radius**2
            candidates.append(np.where((t > 0) & inside, t, np.inf))
        stacked = np.stack(candidates)
        part = np.argmin(stacked, axis=0)
        return stacked[part, np.arange(len(part))], part

    def normals(self, points, parts):
        normals = np.zeros_like(points)
        normals[:, :2] = (points[:, :2] - self.centre) / self.radius
        normals[parts == 1] = (0.0, 0.0, 1.0)
        normals[parts == 2] = (0.0, 0.0, -1.0)
        return normals

    def albedo(self, points, parts):
        return self.material.albedo(points)

    def surface(self):
        segments = circle_segments(self.radius)
        phi = 2 * math.pi * np.arange(segments) / segments
        unit = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], -1)
        rows = max(1, math.ceil((self.z1 - self.z0) / MESH_SPACING))
        heights = np.linspace(self.z0, self.z1, rows + 1)
        side_vertices = (self.radius * unit[None] + [*self.centre, 0.0]).repeat(rows + 1, 0)
        side_vertices = side_vertices.reshape(rows + 1, segments, 3)
        side_vertices[..., 2] = heights[:, None]
        pieces = [
            Surface(
                side_vertices.reshape(-1, 3),
                grid_faces(rows, segments, wrap=True),
                np.tile(unit, (rows + 1, 1)),
                np.zeros((rows + 1) * segments, dtype=np.int64),
            ).oriented()
        ]
        caps = ((self.z1, 1.0, 1),) + (() if self.on_floor else ((self.z0, -1.0, 2),))
        rings = max(1, math.ceil(self.radius / MESH_SPACING))
        radii = self.radius * np.arange(1, rings + 1) / rings
        for height, sign, part in caps:
            ring = radii[:, None, None] * unit[None] + [*self.centre, height]
            vertices = np.concatenate([[[*self.centre, height]], ring.reshape(-1, 3)])
            j = np.arange(segments)
            fan = np.stack([np.zeros_like(j), 1 + j, 1 + (j + 1) % segments], -1)
            faces = np.concatenate([fan, grid_faces(rings - 1, segments, wrap=True) + 1])
            normals = np.broadcast_to([0.0, 0.0, sign], vertices.shape).copy()
            parts = np.full(len(vertices), part, dtype=np.int64)
            pieces.append(Surface(vertices, faces, normals, parts).oriented())
        return merge_surfaces(pieces)


@dataclass(frozen=True, eq=False)
class Scene:
    """A closed synthetic scene and where a camera may move inside it.

    Attributes:
        primitives: the room first, then the objects.
        camera_lo: (3,) lower corner of the box the camera centre must stay in, m.
        camera_hi: (3,) upper corner of that box, m.
    """

    primitives: tuple[Primitive, ...]
    camera_lo: np.ndarray
    camera_hi: np.ndarray
