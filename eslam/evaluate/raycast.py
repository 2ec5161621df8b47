"""Depth images of a triangle mesh by CPU ray casting (Embree through ``embreex``).

``embreex`` is an optional dependency (the ``[eval]`` extra), imported when a caster
is built. Both faces of every triangle are hit (the release renders with back faces).
"""

from __future__ import annotations

import numpy as np

from eslam.types import Intrinsics

EVAL_EXTRA_HINT = 'install the evaluation extra: pip install -e ".[eval]" (embreex)'
"""What to tell a user whose environment lacks the ray caster."""


def pixel_rays(intrinsics: Intrinsics) -> np.ndarray:
    """Camera-frame ray directions through every pixel centre, z component 1.

    Pixel (u, v) = (column, row) looks along ((u - cx) / fx, (v - cy) / fy, 1) in
    OpenCV camera axes, so the ray parameter t at a hit is the hit's depth (z).

    Returns:
        (H * W, 3) float64, row-major over the image.
    """
    v, u = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width].astype(np.float64)
    x = (u - intrinsics.cx) / intrinsics.fx
    y = (v - intrinsics.cy) / intrinsics.fy
    return np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)


class MeshRaycaster:
    """A triangle mesh loaded into an Embree scene, for depth rendering.

    Vertices are stored relative to the mesh's bounding-box centre: Embree works in
    float32, and small coordinates keep its rounding near 1e-7 of the scene size.

    Args:
        vertices: (V, 3) float, metres.
        faces: (F, 3) int vertex indices, F >= 1.

    Raises:
        ImportError: ``embreex`` is not installed (the message names the extra).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        try:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh as EmbreeMesh
        except ImportError:
            raise ImportError(f"depth rendering needs embreex: {EVAL_EXTRA_HINT}") from None
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces)
        if len(faces) == 0:
            raise ValueError("cannot ray cast a mesh without triangles")
        self.centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        self._scene = rtcore_scene.EmbreeScene()
        EmbreeMesh(
            scene=self._scene,
            vertices=(vertices - self.centre).astype(np.float32),
            indices=faces.astype(np.int32),
        )

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Ray parameter t of the first hit along origin + t * direction.

        Args:
            origins: (N, 3) float, metres.
            directions: (N, 3) float (not necessarily unit length).

        Returns:
            (N,) float64 t of the first hit, ``inf`` where the ray misses.
        """
        result = self._scene.run(
            np.ascontiguousarray(origins - self.centre, dtype=np.float32),
            np.ascontiguousarray(directions, dtype=np.float32),
            output=1,
        )
        t = result["tfar"].astype(np.float64)
        t[result["primID"] < 0] = np.inf
        return t

    def depth(
        self, camera_to_world: np.ndarray, intrinsics: Intrinsics, rays: np.ndarray | None = None
    ) -> np.ndarray:
        """Depth image of the mesh seen by a pinhole camera.

        Args:
            camera_to_world: (4, 4) pose, OpenCV camera axes, metres.
            intrinsics: the camera.
            rays: :func:`pixel_rays` of ``intrinsics`` (pass it to reuse it across views).

        Returns:
            (H, W) float64 depth along the optical axis, metres; 0 where no surface.
        """
        if rays is None:
            rays = pixel_rays(intrinsics)
        pose = np.asarray(camera_to_world, dtype=np.float64)
        directions = rays @ pose[:3, :3].T
        origins = np.broadcast_to(pose[:3, 3], directions.shape)
        t = self.cast(origins, directions)
        t[~np.isfinite(t)] = 0.0
        return t.reshape(intrinsics.height, intrinsics.width)
