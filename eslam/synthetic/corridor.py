"""The procedural corridor: a long, empty box, whose views are only walls, floor and ceiling."""

from __future__ import annotations

import numpy as np

from eslam.synthetic.materials import random_material
from eslam.synthetic.primitives import RoomBox, Scene


def build_corridor(rng: np.random.Generator) -> Scene:
    """A closed, empty corridor (8-10 x 1.8-2.2 x 2.4-2.7 m) for testing degenerate views.

    Every view holds at most the two side walls, the floor, the ceiling and an end wall:
    while no end wall is in view, the planes' normals leave the motion along the corridor
    unseen by the geometry (a depth-only tracker cannot tell how far the camera moved),
    and only the surfaces' textures show it. Each of the six faces has its own material
    with a distinct hue. The camera box is the middle third of the length, 0.2 m wide, at
    1.3-1.7 m height, so depth stays >= 0.8 m.
    """
    size = np.array([rng.uniform(8.0, 10.0), rng.uniform(1.8, 2.2), rng.uniform(2.4, 2.7)])
    half = size / 2
    slots = rng.permutation(6)
    looks = [(slot / 6 + rng.uniform(), 0.58 if slot % 2 == 0 else 0.82) for slot in slots]
    room = RoomBox(
        np.array([-half[0], -half[1], 0.0]),
        np.array([half[0], half[1], size[2]]),
        tuple(random_material(rng, hue, value, rng.uniform(0.35, 0.55)) for hue, value in looks),
    )
    return Scene(
        (room,),
        np.array([-size[0] / 6, -0.1, 1.3]),
        np.array([size[0] / 6, 0.1, 1.7]),
    )
