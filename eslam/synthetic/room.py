"""The procedural room: a closed box with furniture-like primitives around a camera area."""

from __future__ import annotations

import numpy as np

from eslam.synthetic.materials import random_material
from eslam.synthetic.primitives import Box, Cylinder, RoomBox, Scene, Sphere

OBJECT_CLEARANCE = 0.7
"""Horizontal gap (m) between the camera's box and any object: depth stays >= 0.5 m."""
WALL_GAP = 0.08
"""Gap (m) between objects and walls, and (twice) between objects."""


def _free(lo: np.ndarray, hi: np.ndarray, boxes: list[tuple[np.ndarray, np.ndarray]]) -> bool:
    """Whether the box [lo, hi] keeps 2 WALL_GAP from every box in ``boxes``."""
    gap = 2 * WALL_GAP
    return all(np.any((lo >= b_hi + gap) | (hi <= b_lo - gap)) for b_lo, b_hi in boxes)


def build_room(rng: np.random.Generator) -> Scene:
    """A closed room (4.5-6 x 3.5-5 x 2.5-3 m) around a free central area for the camera.

    On the floor: 4 boxes (one rotated about z, one carrying a sphere), 2 capped
    cylinders and 2 spheres; on the walls: 2 flat boxes (cabinets). Every surface has
    its own material with a distinct hue. The camera box is centred at 1.3-1.7 m
    height, OBJECT_CLEARANCE (horizontally) from every object.
    """
    size = np.array([rng.uniform(4.5, 6.0), rng.uniform(3.5, 5.0), rng.uniform(2.5, 3.0)])
    half = size / 2
    camera_half = np.array([0.1 * size[0], 0.08 * size[1]])
    keep_out = camera_half + OBJECT_CLEARANCE
    # 18 hue slots 20 degrees apart, neighbours alternating dark and bright
    slots = rng.permutation(18)
    looks = iter(zip(slots / 18 + rng.uniform(), np.where(slots % 2 == 0, 0.58, 0.82), strict=True))
    room = RoomBox(
        np.array([-half[0], -half[1], 0.0]),
        np.array([half[0], half[1], size[2]]),
        tuple(random_material(rng, *next(looks), rng.uniform(0.35, 0.55)) for _ in range(6)),
    )
    objects: list = []
    boxes: list[tuple[np.ndarray, np.ndarray]] = []  # bounds of everything placed

    def material():
        return random_material(rng, *next(looks), rng.uniform(0.6, 0.85))

    def spot(radius: float, top: float) -> tuple[np.ndarray, float]:
        """A floor position for a footprint circle of ``radius`` (shrunk until one fits)."""
        for _ in range(30):
            limit = half[:2] - radius - WALL_GAP
            for _ in range(200):
                xy = rng.uniform(-limit, limit)
                lo, hi = np.array([*(xy - radius), 0.0]), np.array([*(xy + radius), top])
                clear = np.linalg.norm(np.maximum(np.abs(xy) - keep_out, 0.0)) >= radius
                if clear and _free(lo, hi, boxes):
                    boxes.append((lo, hi))
                    return xy, radius
            radius *= 0.9
        raise RuntimeError("room too small for its objects")

    for index in range(4):
        extent = np.array([rng.uniform(0.15, 0.4), rng.uniform(0.15, 0.4), 0.0])
        extent[2] = rng.uniform(0.15, 0.45 if index == 0 else 0.55)
        r = min(extent[0], extent[1], 0.3) * rng.uniform(0.7, 1.0)
        top = 2 * extent[2] + (2 * r if index == 0 else 0.0)
        footprint = float(np.hypot(extent[0], extent[1]))
        xy, radius = spot(footprint, top)
        extent[:2] *= radius / footprint
        yaw = rng.uniform(0.3, 1.2) if index == 1 else 0.0
        objects.append(Box(np.array([*xy, extent[2]]), extent, yaw, material(), f"box{index}"))
        if index == 0:
            r = min(r, extent[0], extent[1])
            sphere_centre = np.array([*xy, 2 * extent[2] + r])
            objects.append(Sphere(sphere_centre, r, material(), name="sphere_on_box0"))
    for index in range(2):
        height = rng.uniform(0.4, 1.6)
        xy, r = spot(rng.uniform(0.1, 0.3), height)
        objects.append(Cylinder(xy, r, 0.0, height, material(), name=f"cylinder{index}"))
    for index in range(2):
        radius = rng.uniform(0.15, 0.35)
        xy, r = spot(radius, 2 * radius)
        objects.append(Sphere(np.array([*xy, r]), r, material(), name=f"sphere{index}"))
    for index in range(2):
        extent = np.array([rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5), rng.uniform(0.15, 0.35)])
        axis, side = int(rng.integers(2)), int(rng.integers(2))
        extent[axis] = rng.uniform(0.06, 0.15)
        for _ in range(200):
            centre = rng.uniform(-half + extent + WALL_GAP, half - extent - WALL_GAP)
            centre[2] = rng.uniform(0.9 + extent[2], size[2] - 0.2 - extent[2])
            centre[axis] = (half[axis] - extent[axis]) * (1.0 if side else -1.0)
            lo, hi = centre - extent, centre + extent
            if _free(lo, hi, boxes):
                boxes.append((lo, hi))
                cabinet = Box(
                    centre, extent, 0.0, material(), f"wall_box{index}", (2 * axis + side,)
                )
                objects.append(cabinet)
                break
    return Scene(
        (room, *objects),
        np.array([-camera_half[0], -camera_half[1], 1.3]),
        np.array([camera_half[0], camera_half[1], 1.7]),
    )
