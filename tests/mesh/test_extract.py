"""Block-wise mesh extraction: accuracy on a known TSDF, seams, observed space, memory."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from eslam.mesh.extract import ExtractOptions, ObservedViews, extract_mesh
from eslam.mesh.grid import make_grid
from eslam.types import FieldOutput, Intrinsics

TRUNCATION = 0.06


class SpheresField:
    """A TSDF of a union of spheres (exact distance / T, clipped to [-1, 1]).

    Colour is a known function of position; ``largest_query`` records the biggest batch.
    """

    def __init__(self, spheres: list[tuple[tuple[float, float, float], float]], bound) -> None:
        self.centres = torch.tensor([c for c, _ in spheres], dtype=torch.float32)
        self.radii = torch.tensor([r for _, r in spheres], dtype=torch.float32)
        self.bound = torch.tensor(bound, dtype=torch.float32)
        self.truncation = TRUNCATION
        self.largest_query = 0

    def distance(self, points: torch.Tensor) -> torch.Tensor:
        gaps = torch.cdist(points.float(), self.centres) - self.radii
        return gaps.min(dim=1).values

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        self.largest_query = max(self.largest_query, points.shape[0])
        sdf = (self.distance(points) / self.truncation).clamp(-1, 1)
        rgb = colour_of(points) if with_rgb else None
        return FieldOutput(sdf=sdf, rgb=rgb)


def colour_of(points: torch.Tensor) -> torch.Tensor:
    return ((points + 1.0) / 2.0).clamp(0, 1)


def _edge_counts(faces: np.ndarray) -> np.ndarray:
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    return np.unique(edges, axis=0, return_counts=True)[1]


def _area(vertices: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / 2)


CENTRE = (0.03, -0.02, 0.01)
RADIUS = 0.3
BOX = [[-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5]]


def test_sphere_vertices_on_the_surface_watertight_and_coloured() -> None:
    field = SpheresField([(CENTRE, RADIUS)], BOX)
    resolution = 0.02
    mesh = extract_mesh(field, resolution, options=ExtractOptions(block_cells=8))
    radii = np.linalg.norm(mesh.vertices - np.array(CENTRE), axis=1)
    assert np.abs(radii - RADIUS).max() < 0.05 * resolution
    assert abs(_area(mesh.vertices, mesh.faces) / (4 * np.pi * RADIUS**2) - 1) < 0.01
    # 1000 cells of 8^3 in 13^3 blocks: seams everywhere, yet every edge has two faces
    assert set(_edge_counts(mesh.faces).tolist()) == {2}
    expected = colour_of(torch.from_numpy(mesh.vertices)).numpy() * 255
    assert np.abs(mesh.colours - expected).max() <= 1.0


@pytest.mark.parametrize(("resolution", "block_cells"), [(0.02, 8), (0.01, 12)])
def test_blockwise_equals_a_dense_single_block(resolution: float, block_cells: int) -> None:
    field = SpheresField([(CENTRE, RADIUS), ((-0.3, 0.3, 0.2), 0.12)], BOX)
    blockwise = extract_mesh(field, resolution, options=ExtractOptions(block_cells=block_cells))
    dense = extract_mesh(field, resolution, options=ExtractOptions(block_cells=10**6))
    grid = make_grid(np.full(3, -0.5), np.full(3, 0.5), resolution, TRUNCATION / 2, block_cells)
    assert grid.blocks[0] > 2, "the block-wise pass must really be cut into blocks"
    assert len(blockwise.vertices) == len(dense.vertices)
    assert len(blockwise.faces) == len(dense.faces)

    # same vertices (one to one, up to order) ...
    distance, match = cKDTree(dense.vertices).query(blockwise.vertices)
    assert distance.max() < 1e-4 * resolution
    assert len(np.unique(match)) == len(match)
    # ... joined by the same faces
    faces = {tuple(f) for f in np.sort(match[blockwise.faces], axis=1)}
    assert faces == {tuple(f) for f in np.sort(dense.faces, axis=1)}


def test_marching_cubes_mask_is_read_at_the_upper_corner() -> None:
    """Extraction relies on this: scikit-image meshes cell (x, y, z) when mask[x+1, y+1, z+1]."""
    from skimage.measure import marching_cubes

    axes = np.arange(8, dtype=np.float32)
    grid = np.stack(np.meshgrid(axes, axes, axes, indexing="ij"), -1)
    sdf = np.linalg.norm(grid - 3.3, axis=-1) - 2.5
    mask = np.zeros(sdf.shape, dtype=bool)
    mask[2, 2, 2] = True  # the cell from (1, 1, 1) to (2, 2, 2), which the sphere crosses
    vertices, _, _, _ = marching_cubes(sdf, 0.0, mask=mask, allow_degenerate=False)
    assert len(vertices) > 0
    assert vertices.min() >= 1.0 and vertices.max() <= 2.0


def _camera() -> Intrinsics:
    return Intrinsics(width=64, height=48, fx=40.0, fy=40.0, cx=31.5, cy=23.5)


def _depth_of_spheres(field: SpheresField, pose: torch.Tensor, k: Intrinsics) -> torch.Tensor:
    """(H, W) depth along the optical axis of the spheres seen from ``pose`` (0 = miss)."""
    u, v = torch.meshgrid(torch.arange(k.width), torch.arange(k.height), indexing="xy")
    rays = torch.stack(((u - k.cx) / k.fx, (v - k.cy) / k.fy, torch.ones_like(u * 1.0)), -1)
    directions = rays.reshape(-1, 3) @ pose[:3, :3].T  # unit z in the camera
    origin = pose[:3, 3]
    best = torch.full((directions.shape[0],), float("inf"))
    for centre, radius in zip(field.centres, field.radii, strict=True):
        oc = origin - centre
        a = (directions**2).sum(1)
        b = 2 * directions @ oc
        c = oc @ oc - radius**2
        disc = b**2 - 4 * a * c
        t = (-b - disc.clamp(min=0).sqrt()) / (2 * a)
        best = torch.where((disc > 0) & (t > 0) & (t < best), t, best)
    depth = torch.where(torch.isfinite(best), best, torch.zeros_like(best))
    return depth.reshape(k.height, k.width)  # t along a unit-z ray is the depth


def _views(field: SpheresField, position: tuple[float, float, float]) -> ObservedViews:
    """One camera at ``position`` looking along +z."""
    pose = torch.eye(4)
    pose[:3, 3] = torch.tensor(position)
    depth = _depth_of_spheres(field, pose, _camera())
    return ObservedViews(
        poses=pose[None], depths=depth[None], intrinsics=_camera(), margin=TRUNCATION
    )


def test_unobserved_space_produces_no_surface() -> None:
    seen = ((0.0, 0.0, 1.0), 0.25)
    hidden = ((0.0, 0.0, 1.6), 0.15)  # straight behind the seen sphere
    outside = ((0.0, 0.0, -0.6), 0.2)  # behind the camera
    field = SpheresField([seen, hidden, outside], [[-1.0, 1.0], [-1.0, 1.0], [-1.0, 2.0]])
    views = _views(field, (0.0, 0.0, 0.0))
    resolution = 0.02
    mesh = extract_mesh(field, resolution, views)

    def near(mesh, sphere) -> np.ndarray:
        gap = np.linalg.norm(mesh.vertices - np.array(sphere[0]), axis=1) - sphere[1]
        return np.abs(gap) < 2 * resolution

    assert near(mesh, seen).all()
    assert not near(mesh, hidden).any() and not near(mesh, outside).any()
    # the cap facing the camera is there; the far side, never observed, is not
    front = mesh.vertices[:, 2] < seen[0][2]
    assert front.all() and len(mesh.vertices) > 200
    everything = extract_mesh(field, resolution)
    assert near(everything, hidden).any() and near(everything, outside).any()


def test_memory_stays_bounded_for_a_huge_bound() -> None:
    """40 m cube at 1 cm: a dense grid would be 6.4e10 points (256 GB of float32)."""
    field = SpheresField([((0.0, 0.0, 1.0), 0.2)], [[-20.0, 20.0], [-20.0, 20.0], [-20.0, 20.0]])
    views = _views(field, (0.0, 0.0, 0.0))
    options = ExtractOptions(block_cells=48, chunk=50_000)
    tracemalloc.start()
    try:
        mesh = extract_mesh(field, 0.01, views, options)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(mesh.faces) > 1000
    radii = np.linalg.norm(mesh.vertices - np.array([0.0, 0.0, 1.0]), axis=1)
    assert np.abs(radii - 0.2).max() < 0.005
    assert peak < 64 * 2**20, f"numpy peak {peak / 2**20:.0f} MB"
    assert field.largest_query <= options.chunk


def test_no_keyframes_or_no_surface_gives_an_empty_mesh() -> None:
    field = SpheresField([((5.0, 5.0, 5.0), 0.1)], BOX)  # far outside the bound
    assert len(extract_mesh(field, 0.05).faces) == 0
    views = _views(SpheresField([(CENTRE, RADIUS)], BOX), (0.0, 0.0, -2.0))
    empty = ObservedViews(views.poses[:0], views.depths[:0], views.intrinsics, TRUNCATION)
    assert len(extract_mesh(SpheresField([(CENTRE, RADIUS)], BOX), 0.05, empty).faces) == 0
