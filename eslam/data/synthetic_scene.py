"""Analytic scenes for synthetic RGB-D: primitives, textures, exact ray casting, meshes.

A scene is a tuple of primitives (an inward-facing room box, boxes, spheres, vertical
cylinders), each with a procedural :class:`Material`. Rendering intersects every ray
with every primitive in closed form and keeps the nearest hit, so depth is exact up to
float64 rounding; there is no rasteriser. Colour is albedo times a shading term that
depends only on the surface normal, so it is the same from every viewpoint.

World frame: metres, z up, the floor at z = 0. Ray directions come from
:mod:`eslam.geometry.camera` with unit z in the camera frame, so the ray parameter t
of a hit IS its depth along the optical axis.
"""

from __future__ import annotations

import colorsys
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from eslam.atomic import write_with
from eslam.geometry.camera import camera_to_world_rays, pixel_grid, pixels_to_camera_directions
from eslam.types import Intrinsics

LIGHT_DIRECTION = np.array([0.36, 0.48, 0.8]) / np.linalg.norm([0.36, 0.48, 0.8])
"""Unit direction towards the (infinitely far) light, world frame."""
AMBIENT = 0.6
"""Shading = AMBIENT + (1 - AMBIENT) * (1 + n.l) / 2: never black, view-independent."""
MESH_TOLERANCE = 2e-4
"""Largest distance (m) between a curved surface and its ground-truth tessellation."""
MESH_SPACING = 0.05
"""Grid spacing (m) of planar and cylindrical faces in the mesh, for vertex colours."""
PATTERNS = ("checker", "stripes", "rings")
_BIG = 1e300  # stands in for 1/0 in slab tests


@dataclass(frozen=True, eq=False)
class Material:
    """A procedural texture: a smooth two-colour gradient with a sharp pattern over it.

    albedo(p) = lerp(low, high, g(p)) * ripple(p), then lerp towards ``accent`` by
    ``strength`` where the pattern is on; g = (1 + sin(wave.p + phase)) / 2 and
    ripple = 0.85 + 0.15 sin(ripple.p). The gradients give the colour loss slopes
    everywhere; the pattern gives edges.

    Attributes:
        low: (3,) RGB in [0, 1] at one end of the gradient.
        high: (3,) RGB at the other end.
        accent: (3,) RGB of the pattern.
        wave: (3,) wave vector of the gradient, rad/m.
        ripple: (3,) wave vector of a finer brightness ripple, rad/m.
        phase: gradient phase, rad.
        pattern: one of PATTERNS: "checker" (3D lattice of cubes), "stripes"
            (parallel slabs), "rings" (concentric spherical shells).
        scale: cell / stripe / ring width, m.
        vector: checker: lattice offset (m); stripes: unit normal of the slabs;
            rings: centre (m).
        strength: how far towards ``accent`` the pattern pulls, in [0, 1].
    """

    low: np.ndarray
    high: np.ndarray
    accent: np.ndarray
    wave: np.ndarray
    ripple: np.ndarray
    phase: float
    pattern: str
    scale: float
    vector: np.ndarray
    strength: float

    def albedo(self, points: np.ndarray) -> np.ndarray:
        """(M, 3) RGB in [0, 1] at world ``points`` (M, 3)."""
        g = 0.5 + 0.5 * np.sin(points @ self.wave + self.phase)
        base = self.low + g[:, None] * (self.high - self.low)
        base *= (0.85 + 0.15 * np.sin(points @ self.ripple))[:, None]
        if self.pattern == "checker":
            cells = np.floor((points + self.vector) / self.scale).sum(axis=1)
        elif self.pattern == "stripes":
            cells = np.floor(points @ self.vector / self.scale)
        else:
            cells = np.floor(np.linalg.norm(points - self.vector, axis=1) / self.scale)
        on = (np.mod(cells, 2.0) * self.strength)[:, None]
        return base * (1.0 - on) + self.accent * on


def _hsv(hue: float, saturation: float, value: float) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb(hue % 1.0, min(saturation, 1.0), min(value, 1.0)))


def _unit(rng: np.random.Generator) -> np.ndarray:
    """A random unit vector with every component at least ~0.2: no face sees it edge-on."""
    vector = rng.uniform(0.35, 1.0, 3) * rng.choice([-1.0, 1.0], 3)
    return vector / np.linalg.norm(vector)


def random_material(
    rng: np.random.Generator, hue: float, value: float, saturation: float
) -> Material:
    """A material whose colours stay near ``hue`` and ``value`` (distinct mean colours)."""
    pattern = PATTERNS[int(rng.integers(len(PATTERNS)))]
    scale = rng.uniform(0.08, 0.3)
    vector = {
        "checker": rng.uniform(0.0, scale, 3),
        "stripes": _unit(rng),
        "rings": rng.uniform(-3.0, 3.0, 3),
    }[pattern]
    return Material(
        low=_hsv(hue, saturation, 0.7 * value),
        high=_hsv(hue + 0.05, 0.8 * saturation, 1.25 * value),
        accent=_hsv(hue + rng.choice([-0.1, 0.1]), saturation, rng.choice([0.25, 0.98])),
        wave=_unit(rng) * 2 * math.pi / rng.uniform(1.0, 3.0),
        ripple=_unit(rng) * 2 * math.pi / rng.uniform(0.25, 0.6),
        phase=float(rng.uniform(0.0, 2 * math.pi)),
        pattern=pattern,
        scale=float(scale),
        vector=vector,
        strength=float(rng.uniform(0.5, 0.75)),
    )


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


def _grid_faces(rows: int, cols: int, wrap: bool = False) -> np.ndarray:
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
    return Surface(vertices, _grid_faces(rows, cols), normals, parts).oriented()


def circle_segments(radius: float, tolerance: float = MESH_TOLERANCE) -> int:
    """Segments n of a circle polygon with sagitta r (1 - cos(pi / n)) <= tolerance (>= 128)."""
    return max(128, math.ceil(math.pi / math.acos(1.0 - tolerance / radius)))


def _box_faces(lo, hi, skip: tuple[int, ...] = ()) -> list[Surface]:
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
            for s in _box_faces(self.lo, self.hi)
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
        merged = merge_surfaces(_box_faces(-self.half, self.half, self.hidden))
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
        faces = np.concatenate([north, _grid_faces(n - 2, 2 * n, wrap=True) + 1, south])
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
                _grid_faces(rows, segments, wrap=True),
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
            faces = np.concatenate([fan, _grid_faces(rings - 1, segments, wrap=True) + 1])
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


@dataclass(frozen=True, eq=False)
class RenderedView:
    """Everything a render computes per pixel.

    Attributes:
        rgb: (H, W, 3) uint8.  depth: (H, W) float32 m along the optical axis, 0 = miss.
        normals: (H, W, 3) float64 world-frame unit normals.
        primitive: (H, W) int64 index into scene.primitives, -1 = miss.
        cos_incidence: (H, W) float64 |cos| of the angle between ray and normal.
    """

    rgb: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    primitive: np.ndarray
    cos_incidence: np.ndarray


def shading(normals: np.ndarray) -> np.ndarray:
    """(M,) view-independent shading factor in [AMBIENT, 1] for unit ``normals`` (M, 3)."""
    return AMBIENT + (1.0 - AMBIENT) * 0.5 * (1.0 + normals @ LIGHT_DIRECTION)


def cast_rays(
    scene: Scene, origin: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of rays ``origin + t * directions`` (N, 3) over all primitives.

    Rays that miss an object's bounding sphere skip its exact test (a speed-up only:
    the cull is conservative, so the result is that of testing every ray).

    Returns:
        t (N,) float64 (inf = miss) and primitive*8 + part (N,) int64 (-1 = miss).
    """
    best = np.full(len(directions), np.inf)
    label = np.full(len(directions), -1, dtype=np.int64)
    lengths = np.linalg.norm(directions, axis=1)
    for index, primitive in enumerate(scene.primitives):
        rays = slice(None)
        bound = getattr(primitive, "bounding_sphere", None)
        if bound is not None:
            offset = bound[0] - origin
            reach = bound[1] * (1.0 + 1e-9) + 1e-9
            if offset @ offset > reach**2:
                along = (directions @ offset) / lengths
                rays = np.flatnonzero((along > 0) & (offset @ offset - along**2 <= reach**2))
        t, part = primitive.intersect(origin, directions[rays])
        closer = t < best[rays]
        if isinstance(rays, np.ndarray):
            rays = rays[closer]
        else:
            rays = np.flatnonzero(closer)
        best[rays] = t[closer]
        label[rays] = index * 8 + part[closer]
    return best, label


@functools.lru_cache(maxsize=8)
def _camera_directions(intrinsics: Intrinsics) -> torch.Tensor:
    uv = pixel_grid(intrinsics, dtype=torch.float64)
    return pixels_to_camera_directions(uv, intrinsics).reshape(-1, 3)


def render_view(scene: Scene, intrinsics: Intrinsics, c2w: np.ndarray) -> RenderedView:
    """Ray cast one view exactly: depth along the optical axis, shaded colour, normals."""
    origins, directions = camera_to_world_rays(
        _camera_directions(intrinsics), torch.as_tensor(c2w, dtype=torch.float64)
    )
    origin, directions = origins[0].numpy(), directions.numpy()
    t, label = cast_rays(scene, origin, directions)
    colour = np.zeros_like(directions)
    normals = np.zeros_like(directions)
    owner = np.where(label >= 0, label // 8, -1)
    for index, primitive in enumerate(scene.primitives):
        mask = np.flatnonzero(owner == index)
        points = origin + t[mask, None] * directions[mask]
        parts = label[mask] % 8
        normals[mask] = primitive.normals(points, parts)
        colour[mask] = primitive.albedo(points, parts) * shading(normals[mask])[:, None]
    hit = label >= 0
    cosine = np.abs(np.einsum("ni,ni->n", normals, directions)) / np.linalg.norm(directions, axis=1)
    h, w = intrinsics.height, intrinsics.width
    return RenderedView(
        rgb=np.clip(colour * 255.0 + 0.5, 0, 255).astype(np.uint8).reshape(h, w, 3),
        depth=np.where(hit, t, 0.0).astype(np.float32).reshape(h, w),
        normals=normals.reshape(h, w, 3),
        primitive=owner.reshape(h, w),
        cos_incidence=cosine.reshape(h, w),
    )


def render_frame(
    scene: Scene, intrinsics: Intrinsics, c2w: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Render ``scene`` from camera-to-world ``c2w`` (4, 4), OpenCV axes.

    Returns:
        rgb (H, W, 3) uint8 and depth (H, W) float32 metres along the optical axis
        (exact up to float32 rounding; 0 where a ray hits nothing).
    """
    view = render_view(scene, intrinsics, c2w)
    return view.rgb, view.depth


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """A triangle mesh with vertex colours.

    Attributes:
        vertices: (V, 3) float64, m.  faces: (F, 3) int64.  colours: (V, 3) uint8.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colours: np.ndarray


def scene_mesh(scene: Scene) -> TriangleMesh:
    """Ground-truth mesh of ``scene`` in its world frame.

    Planar faces are exact; spheres and cylinders are within MESH_TOLERANCE (0.2 mm)
    of the analytic surfaces. Room faces point into the room, objects' faces outward;
    faces resting on the floor are left out (never observable). Vertex colours are the
    rendered colours (albedo times shading) at the vertices.
    """
    pieces, colours = [], []
    for primitive in scene.primitives:
        surface = primitive.surface()
        albedo = primitive.albedo(surface.vertices, surface.parts)
        colours.append(albedo * shading(surface.normals)[:, None])
        pieces.append(surface)
    merged = merge_surfaces(pieces)
    rgb = np.clip(np.concatenate(colours) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return TriangleMesh(merged.vertices, merged.faces, rgb)


def write_mesh_ply(path: str | Path, mesh: TriangleMesh) -> None:
    """Write ``mesh`` as a binary PLY with vertex colours (atomically)."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=mesh.colours, process=False)
    write_with(path, lambda tmp: tm.export(tmp, file_type="ply", encoding="binary"))
