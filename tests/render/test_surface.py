"""Surface depth of novel views: zero crossing on the no-depth samples, then bisection."""

from __future__ import annotations

import numpy as np
import torch

from eslam.config import RenderConfig
from eslam.render.orbit import look_at_opencv, mean_up, orbit_poses
from eslam.render.surface import first_zero_crossing, render_novel_view
from eslam.types import FieldOutput, Intrinsics
from eslam.viz.depth_images import turbo


class PlaneField:
    """A wall at world z = ``wall`` seen from z < wall: TSDF = (wall - z) / T, clamped."""

    def __init__(self, wall: float, truncation: float = 0.06) -> None:
        self.wall = wall
        self.truncation = truncation
        self.beta = torch.tensor(10.0)
        self.bound = torch.tensor([[-4.0, 4.0], [-4.0, 4.0], [-1.0, 4.0]])

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        sdf = ((self.wall - points[:, 2]) / self.truncation).clamp(-1.0, 1.0)
        rgb = torch.full((len(points), 3), 0.5) if with_rgb else None
        return FieldOutput(sdf=sdf, rgb=rgb)


def test_first_zero_crossing_finds_the_first_sign_change() -> None:
    sdf = torch.tensor([[0.5, 0.2, -0.3, 0.4, -0.1], [1.0, 1.0, 1.0, 1.0, 1.0]])
    index, hit = first_zero_crossing(torch.arange(5.0).expand(2, 5), sdf)
    assert index[0] == 1 and hit.tolist() == [True, False]


def test_novel_view_depth_is_the_surface_not_the_volume_rendered_depth() -> None:
    """A wall 2.5 m ahead: 64 coarse samples over 5 m are ~8 cm apart, beyond the
    truncation band; the depth found is still the wall's to a tenth of a millimetre."""
    field = PlaneField(wall=2.5)
    intrinsics = Intrinsics(8, 6, 4.0, 4.0, 3.5, 2.5)
    depth, rgb = render_novel_view(field, intrinsics, torch.eye(4), RenderConfig())
    np.testing.assert_allclose(depth.numpy(), 2.5, atol=1e-4)
    assert torch.allclose(rgb, torch.tensor(0.5), atol=0.02)
    behind = torch.eye(4)
    behind[:3, :3] = torch.diag(torch.tensor([1.0, -1.0, -1.0]))  # looking away: no wall
    depth, rgb = render_novel_view(field, intrinsics, behind, RenderConfig())
    assert (depth == 0).all() and (rgb == 0).all()


def test_orbit_circles_the_centre_upright_at_the_cameras_height() -> None:
    bound = np.array([[-2.0, 2.0], [-1.0, 3.0], [0.0, 3.0]])  # centre (0, 1, 1.5), z up
    first = look_at_opencv(np.array([1.5, 1.0, 1.7]), np.array([0.0, 1.0, 1.2]), [0, 0, 1])
    second = look_at_opencv(np.array([-1.5, 1.0, 1.7]), np.array([0.0, 2.0, 1.0]), [0, 0, 1])
    poses = np.stack([first, second])  # both pitched down, different headings
    np.testing.assert_allclose(mean_up(poses), [0, 0, 1], atol=1e-9)
    orbit = orbit_poses(bound, poses, 8)
    centre = np.array([0.0, 1.0, 1.5])
    offsets = orbit[:, :3, 3] - centre
    np.testing.assert_allclose(np.linalg.norm(offsets[:, :2], axis=1), 1.5, atol=1e-9)
    np.testing.assert_allclose(offsets[:, 2], 0.2, atol=1e-9)
    np.testing.assert_allclose(orbit[0, :3, 3], [1.5, 1.0, 1.7], atol=1e-9)
    towards = -offsets / np.linalg.norm(offsets, axis=1, keepdims=True)
    np.testing.assert_allclose(orbit[:, :3, 2], towards, atol=1e-9)
    assert (orbit[:, 2, 1] < 0).all(), "image y points down, away from up"
    for pose in orbit:
        np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-9)
        assert np.linalg.det(pose[:3, :3]) > 0


def test_turbo_runs_from_dark_blue_to_dark_red() -> None:
    low, middle, high = turbo(np.array([0.1, 0.5, 0.9]))
    assert low[2] > low[0] and high[0] > high[2] and middle[1] > 200
