"""Held-out errors of a field: which points a frame observed, and that both figures are
0 for an exact map and equal a known shift of the surface."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eslam.render.held_out import held_out_errors, observed_mask
from eslam.types import FieldOutput, Frame, Intrinsics

CAMERA = Intrinsics(width=32, height=24, fx=20.0, fy=20.0, cx=15.5, cy=11.5)
TRUNCATION = 0.06
WALL_X = 4.0


def facing_wall(x: float, y: float, index: int) -> Frame:
    """A frame at (x, y, 1.25) looking along +x (OpenCV axes) at the wall x = 4."""
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    pose[:3, 3] = (x, y, 1.25)
    depth = np.full((CAMERA.height, CAMERA.width), WALL_X - x, dtype=np.float32)
    rgb = np.zeros((CAMERA.height, CAMERA.width, 3), dtype=np.uint8)
    return Frame(index, rgb, depth, CAMERA, pose_gt=pose)


class WallField:
    """A field whose TSDF is that of a wall at x = ``wall`` (free space at x < wall)."""

    truncation = TRUNCATION

    def __init__(self, wall: float) -> None:
        self.wall = wall
        self.beta = torch.tensor(10.0)
        self.bound = torch.tensor([[0.0, 4.5], [-2.0, 5.0], [-1.0, 3.5]])

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        sdf = ((self.wall - points[:, 0]) / TRUNCATION).clamp(-1.0, 1.0)
        return FieldOutput(sdf=sdf, rgb=torch.zeros(len(points), 3) if with_rgb else None)


def test_observed_mask() -> None:
    frame = facing_wall(3.0, 1.5, 0)
    points = torch.tensor(
        [
            [4.0, 1.5, 1.25],  # on the wall, in view
            [4.0, 1.9, 1.0],  # on the wall, in view
            [3.9, 1.5, 1.25],  # in front of the measured surface (10 cm off its depth)
            [4.0, 9.0, 1.25],  # on the wall, outside the image
            [2.0, 1.5, 1.25],  # behind the camera
        ],
        dtype=torch.float64,
    )
    assert observed_mask(points, frame).tolist() == [True, True, False, False, False]


def test_exact_and_shifted_maps() -> None:
    fitted_to = facing_wall(3.0, 1.5, 0)
    held_out = [facing_wall(3.2, 1.6, 1), facing_wall(3.1, 1.4, 2)]
    exact = held_out_errors(WallField(WALL_X), held_out, observed_by=fitted_to)
    assert exact.pixels > 0
    assert exact.surface_sdf_m == pytest.approx(0.0, abs=1e-6)
    assert exact.depth_l1_m == pytest.approx(0.0, abs=1e-5) and exact.missed == 0.0
    shifted = held_out_errors(WallField(WALL_X + 0.01), held_out, observed_by=fitted_to)
    assert shifted.surface_sdf_m == pytest.approx(0.01, abs=1e-5)
    assert shifted.depth_l1_m == pytest.approx(0.01, abs=1e-5)


def test_a_map_without_the_surface_misses() -> None:
    fitted_to = facing_wall(3.0, 1.5, 0)
    beyond_the_box = held_out_errors(
        WallField(4.8), [facing_wall(3.2, 1.6, 1)], observed_by=fitted_to
    )
    assert beyond_the_box.missed == 1.0 and np.isnan(beyond_the_box.depth_l1_m)


def test_nothing_to_score_is_an_error() -> None:
    far_away = facing_wall(3.0, 40.0, 0)  # sees none of the held-out frame's wall
    with pytest.raises(ValueError, match="no held-out pixel"):
        held_out_errors(WallField(WALL_X), [facing_wall(3.0, 1.5, 1)], observed_by=far_away)
