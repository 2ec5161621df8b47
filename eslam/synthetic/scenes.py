"""Scene builders by name, and what synth.json records of a scene (primitives, bound)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from eslam.synthetic.corridor import build_corridor
from eslam.synthetic.primitives import RoomBox, Scene
from eslam.synthetic.room import build_room

SCENES: dict[str, Callable[[np.random.Generator], Scene]] = {
    "room": build_room,
    "corridor": build_corridor,
}
"""Scene builders by name; each takes a seeded numpy Generator."""


def scene_builder(name: str) -> Callable[[np.random.Generator], Scene]:
    """The builder of scene ``name`` (ValueError listing the choices for an unknown name)."""
    if name not in SCENES:
        raise ValueError(
            f"unknown synthetic scene '{name}' (choose one of: {', '.join(sorted(SCENES))})"
        )
    return SCENES[name]


def build_scene(name: str, seed: int) -> Scene:
    """The scene ``name`` for ``seed`` (ValueError listing the choices for an unknown name)."""
    return scene_builder(name)(np.random.default_rng([seed, 0]))


def describe_scene(scene: Scene) -> list[dict]:
    """One JSON-ready line per primitive: name, type and its parameters (m, rad)."""
    lines = []
    for primitive in scene.primitives:
        fields = {"name": primitive.name, "type": type(primitive).__name__}
        for key in ("lo", "hi", "centre", "half", "radius", "yaw", "z0", "z1"):
            value = getattr(primitive, key, None)
            if value is not None:
                fields[key] = np.round(np.asarray(value, dtype=np.float64), 6).tolist()
        lines.append(fields)
    return lines


BOUND_MARGIN = 0.1
"""Margin (m) around the room box in the scene bound written to synth.json."""


def scene_bound(scene: Scene, margin: float = BOUND_MARGIN) -> list[list[float]]:
    """[[xmin, xmax], [ymin, ymax], [zmin, zmax]] of the room box grown by ``margin`` metres."""
    room = next(p for p in scene.primitives if isinstance(p, RoomBox))
    return [
        [float(lo) - margin, float(hi) + margin] for lo, hi in zip(room.lo, room.hi, strict=True)
    ]
