"""Mesh culling for evaluation: keep what the cameras saw (docs/method.md section 6).

Two protocols, applied alike to a reconstruction (with its estimated poses) and to the
ground-truth mesh (with the ground-truth poses):

- ``"eslam"`` (the ESLAM paper): a vertex is visible in a frame when it lies in front of
  the camera, projects inside the image and its depth is at most the observed depth at
  that pixel + T; faces seen in no frame (outside every frustum or occluded in all
  frames) are removed.
- ``"nice"`` (NICE-SLAM): frustum only (in front of the camera and inside the image);
  depth maps are not needed.

A face is kept when ANY of its vertices is visible in some frame, and vertices no kept
face uses are dropped: this follows the authors' ``src/tools/cull_mesh.py`` in both
idiap/ESLAM and cvg/nice-slam, which remove a face when all its vertices are unseen
(``whole_mask[faces].all(axis=1)``). Deviations from those scripts, all small: the
observed depth is read at the nearest pixel (ESLAM samples it bilinearly), "inside the
image" is the pixel-centre convention u in [-0.5, W - 0.5) (the scripts use
0 < u < W), and a pixel without depth (0) sees nothing (the ESLAM script compares
against 0 there, so it keeps vertices within T of the camera).

Frames are streamed: depth maps come from any iterable (e.g. a generator reading a
sequence) and are read once, in order, so memory does not grow with the number of
frames; only vertices not yet seen are tested against each further frame.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch

from eslam.config.device import resolve_device
from eslam.errors import ConfigError
from eslam.mesh.subdivide import subdivide_long_edges
from eslam.types import Intrinsics, TriangleMesh

CullProtocol = Literal["eslam", "nice"]

ESLAM_TRUNCATION = 0.06
"""T of the ESLAM release's Replica and ScanNet configs (model.truncation), metres; the
depth tolerance of the "eslam" protocol. Pass the run's field.truncation to match it."""


@dataclass(frozen=True, eq=False)
class CullCameras:
    """The frames a mesh is culled against.

    Attributes:
        poses: (K, 4, 4) camera-to-world poses, OpenCV axes.
        intrinsics: the camera of every frame.
        depths: K depth maps, each (H, W) metres (0 = invalid), in the order of
            ``poses``; any iterable, read once (needed by the "eslam" protocol only).
    """

    poses: np.ndarray
    intrinsics: Intrinsics
    depths: Iterable[np.ndarray] | None = None


@dataclass(frozen=True)
class CullOptions:
    """Culling settings.

    Attributes:
        truncation: T, the depth tolerance of the "eslam" protocol, metres.
        max_edge: subdivide faces with longer edges (metres) before culling; None = no.
        device: where the projections run (cpu, cuda, ...).
    """

    truncation: float = ESLAM_TRUNCATION
    max_edge: float | None = None
    device: str = "cpu"

    def __post_init__(self) -> None:
        if not self.truncation >= 0:
            raise ValueError(f"truncation must be >= 0, got {self.truncation}")
        if self.max_edge is not None and not self.max_edge > 0:
            raise ValueError(f"max_edge must be > 0 or None, got {self.max_edge}")


def _visible_in_frame(
    points: torch.Tensor,
    pose: torch.Tensor,
    intrinsics: Intrinsics,
    depth: torch.Tensor | None,
    truncation: float,
) -> torch.Tensor:
    """(M,) bool: which (M, 3) world points the camera at ``pose`` sees (see module doc)."""
    local = (points - pose[:3, 3]) @ pose[:3, :3]
    z = local[:, 2]
    safe = torch.where(z > 0, z, torch.ones_like(z))
    u = (intrinsics.fx * local[:, 0] / safe + intrinsics.cx).round()
    v = (intrinsics.fy * local[:, 1] / safe + intrinsics.cy).round()
    seen = (z > 0) & (u >= 0) & (u <= intrinsics.width - 1)
    seen &= (v >= 0) & (v <= intrinsics.height - 1)
    if depth is None:
        return seen
    columns = u.clamp(0, intrinsics.width - 1).long()
    rows = v.clamp(0, intrinsics.height - 1).long()
    measured = depth[rows, columns]
    return seen & (measured > 0) & (z <= measured + truncation)


def _frames(cameras: CullCameras, protocol: CullProtocol) -> Iterator[tuple[np.ndarray, object]]:
    """(pose, depth or None) per frame; checks that there is one depth map per pose."""
    if protocol == "nice":
        for pose in cameras.poses:
            yield pose, None
        return
    if cameras.depths is None:
        raise ConfigError(
            "the 'eslam' culling protocol needs depth maps (give CullCameras.depths, "
            "or use protocol 'nice')"
        )
    count = 0
    for depth in cameras.depths:
        if count == len(cameras.poses):
            raise ValueError(f"more depth maps than the {len(cameras.poses)} poses")
        yield cameras.poses[count], depth
        count += 1
    if count != len(cameras.poses):
        raise ValueError(f"{count} depth maps for {len(cameras.poses)} poses")


def visible_vertices(
    vertices: np.ndarray,
    cameras: CullCameras,
    protocol: CullProtocol,
    options: CullOptions = CullOptions(),
) -> np.ndarray:
    """(V,) bool: whether some frame sees each of the (V, 3) vertices under ``protocol``."""
    if protocol not in ("eslam", "nice"):
        raise ConfigError(f"unknown culling protocol '{protocol}' (use 'eslam' or 'nice')")
    device = resolve_device(options.device)
    points = torch.as_tensor(np.asarray(vertices), dtype=torch.float32, device=device)
    seen = torch.zeros(points.shape[0], dtype=torch.bool, device=device)
    remaining = torch.arange(points.shape[0], device=device)
    shape = (cameras.intrinsics.height, cameras.intrinsics.width)
    for pose, depth in _frames(cameras, protocol):
        if remaining.numel() == 0:
            continue  # still read every depth map: the count is checked
        pose_t = torch.as_tensor(np.asarray(pose), dtype=torch.float32, device=device)
        depth_t = None
        if depth is not None:
            if tuple(np.shape(depth)) != shape:
                raise ValueError(f"depth map is {np.shape(depth)}, the camera is {shape}")
            depth_t = torch.as_tensor(np.asarray(depth), dtype=torch.float32, device=device)
        hit = _visible_in_frame(
            points[remaining], pose_t, cameras.intrinsics, depth_t, options.truncation
        )
        seen[remaining[hit]] = True
        remaining = remaining[~hit]
    return seen.cpu().numpy()


def keep_faces(mesh: TriangleMesh, faces_kept: np.ndarray) -> TriangleMesh:
    """The mesh with only the faces set in the (F,) bool ``faces_kept``, vertices no kept
    face uses dropped (the others keep their order)."""
    faces = mesh.faces[faces_kept]
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[faces.reshape(-1)] = True
    new_index = np.cumsum(used) - 1
    return TriangleMesh(
        vertices=mesh.vertices[used],
        faces=new_index[faces].astype(np.int64),
        colours=mesh.colours[used],
    )


def cull_mesh(
    mesh: TriangleMesh,
    cameras: CullCameras,
    protocol: CullProtocol,
    options: CullOptions = CullOptions(),
) -> TriangleMesh:
    """Remove the faces no frame sees (see the module docstring for the protocols).

    Args:
        mesh: the mesh (unchanged).
        cameras: poses, camera and (for "eslam") depth maps, streamed.
        protocol: "eslam" (frustum + occlusion) or "nice" (frustum only).
        options: depth tolerance T, optional long-edge subdivision, device.

    Returns:
        The culled mesh: faces with at least one visible vertex, and their vertices.
    """
    if options.max_edge is not None:
        mesh = subdivide_long_edges(mesh, options.max_edge)
    visible = visible_vertices(mesh.vertices, cameras, protocol, options)
    return keep_faces(mesh, visible[mesh.faces].any(axis=1))
