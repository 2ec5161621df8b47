"""The ground-truth mesh of a synthetic scene, in its world frame."""

from __future__ import annotations

import numpy as np

from eslam.synthetic.materials import shading
from eslam.synthetic.primitives import Scene
from eslam.synthetic.tessellation import merge_surfaces
from eslam.types import TriangleMesh


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
