"""The shared renderer on an analytic plane field (z = z0, camera at the origin looking down +z).

ESLAM's alpha ignores the sample spacing, so with a sharp beta the rendered depth is the
first sample at (or a hair in front of) the surface: it is quantised by the sample
spacing. With beta = 10 (the initial value) every free-space sample leaks
10 * sigmoid(-10) = 4.5e-4 of opacity, which pulls the depth towards the camera; ESLAM
learns beta, which grows during training.
"""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.config import LossConfig, LossWeights, RenderConfig
from eslam.losses import compute_losses
from eslam.render import (
    camera_directions,
    rays_from_pixels,
    render_image,
    render_rays,
    render_rays_without_depth,
)
from eslam.types import FieldOutput, Intrinsics, RayBatch

T = 0.06
Z0 = 2.0
K = Intrinsics(width=8, height=6, fx=6.0, fy=6.0, cx=3.5, cy=2.5)


class PlaneField:
    """TSDF of the plane z = z0 (free space at z < z0), colour varying with x."""

    def __init__(self, z0: float = Z0, beta: float = 200.0) -> None:
        self.z0 = z0
        self.beta = torch.tensor(beta)
        self.truncation = T
        self.bound = torch.tensor([[-2.0, 2.0], [-2.0, 2.0], [-0.5, 3.0]])
        self.calls: list[tuple[int, bool]] = []

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        self.calls.append((points.shape[0], with_rgb))
        sdf = (self.z0 - points[:, 2]).clamp(-T, T) / T
        if not with_rgb:
            return FieldOutput(sdf=sdf, rgb=None)
        red = torch.sigmoid(points[:, 0])
        rgb = torch.stack((red, torch.full_like(red, 0.25), torch.full_like(red, 0.75)), dim=1)
        return FieldOutput(sdf=sdf, rgb=rgb)


def plane_rays(count: int = 5, depth: float = Z0) -> RayBatch:
    directions = torch.tensor(
        [[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, -0.2, 1.0], [0.3, 0.3, 1.0], [-0.4, 0.1, 1.0]]
    )[:count]
    return RayBatch(
        origins=torch.zeros(count, 3),
        directions=directions,
        depth=torch.full((count,), depth),
        rgb=torch.zeros(count, 3),
    )


def test_sharp_beta_depth_is_the_first_sample_behind_the_plane() -> None:
    field = PlaneField(beta=200.0)
    output = render_rays(field, plane_rays(), RenderConfig(), perturb=False)
    # Surface samples 1.91 + 0.18 j / 7: the first behind z0 = 2 is j = 4 (1.3 cm behind).
    first_behind = 1.91 + 0.18 * 4 / 7
    torch.testing.assert_close(output.depth, torch.full((5,), first_behind), atol=1e-4, rtol=0)
    torch.testing.assert_close(output.weights.sum(dim=1), torch.ones(5), atol=1e-4, rtol=0)
    assert output.z_vals.shape == output.sdf.shape == output.weights.shape == (5, 40)


def test_sharp_beta_with_dense_surface_samples_is_within_a_centimetre() -> None:
    field = PlaneField(beta=200.0)
    config = RenderConfig(samples_surface=32)  # spacing 0.18 / 31 = 5.8 mm
    output = render_rays(field, plane_rays(), config, perturb=False)
    assert torch.all((output.depth - Z0).abs() < 0.006)
    perturbed = render_rays(field, plane_rays(), config, True, torch.Generator().manual_seed(0))
    assert torch.all((perturbed.depth - Z0).abs() < 0.01)


def test_initial_beta_is_biased_towards_the_camera() -> None:
    output = render_rays(PlaneField(beta=10.0), plane_rays(), RenderConfig(), perturb=False)
    assert torch.all(output.depth < Z0 - 0.01)
    assert torch.all(output.depth > Z0 - 0.03)


def test_colour_is_the_surface_colour() -> None:
    rays = plane_rays()
    output = render_rays(PlaneField(beta=200.0), rays, RenderConfig(), perturb=False)
    hit = rays.directions * output.depth[:, None]
    torch.testing.assert_close(output.rgb[:, 0], torch.sigmoid(hit[:, 0]), atol=2e-3, rtol=0)
    torch.testing.assert_close(output.rgb[:, 1:], torch.tensor([0.25, 0.75]).expand(5, 2))


def test_field_is_queried_once_on_all_points() -> None:
    field = PlaneField()
    render_rays(field, plane_rays(), RenderConfig(), perturb=True, generator=torch.Generator())
    assert field.calls == [(5 * 40, True)]
    field.calls.clear()
    output = render_rays(field, plane_rays(), RenderConfig(render_colour=False), perturb=False)
    assert field.calls == [(5 * 40, False)]
    assert output.rgb is None


def test_density_bell_option() -> None:
    config = RenderConfig(density="bell", samples_surface=32)
    output = render_rays(PlaneField(beta=20.0), plane_rays(), config, perturb=False)
    torch.testing.assert_close(output.weights.sum(dim=1), torch.ones(5), atol=1e-5, rtol=0)
    assert torch.all((output.depth - Z0).abs() < 0.01)


def test_render_rays_rejects_rays_without_depth() -> None:
    rays = plane_rays()
    bad = dataclasses.replace(rays, depth=torch.tensor([2.0, 0.0, 2.0, 2.0, 2.0]))
    with pytest.raises(ValueError, match="render_rays_without_depth"):
        render_rays(PlaneField(), bad, RenderConfig(), perturb=False)


def test_without_depth_recovers_the_plane() -> None:
    field = PlaneField(beta=200.0)
    rays = plane_rays()
    output = render_rays_without_depth(field, rays.origins, rays.directions, RenderConfig())
    assert torch.all((output.depth - Z0).abs() < 0.01)
    assert output.z_vals.shape == (5, 64 + 8)
    assert torch.all(output.z_vals[:, 1:] >= output.z_vals[:, :-1])
    # One coarse query without colour, then one final query on every sample.
    assert field.calls == [(5 * 64, False), (5 * 72, True)]


def test_without_depth_importance_count_and_misses() -> None:
    field = PlaneField(beta=200.0)
    origins = torch.tensor([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])  # the second misses the box
    directions = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    output = render_rays_without_depth(field, origins, directions, RenderConfig(), n_importance=16)
    assert output.z_vals.shape == (2, 80)
    assert abs(output.depth[0].item() - Z0) < 0.01
    assert output.depth[1] == 0 and torch.all(output.rgb[1] == 0)
    coarse = render_rays_without_depth(field, origins, directions, RenderConfig(), n_importance=0)
    assert coarse.z_vals.shape == (2, 64)


def test_render_image_with_and_without_depth() -> None:
    field = PlaneField(beta=200.0)
    c2w = torch.eye(4)
    config = RenderConfig(samples_surface=32)
    depth_map = torch.full((K.height, K.width), Z0)
    depth_map[0, 0] = 0.0  # rendered without depth
    depth, rgb = render_image(field, K, c2w, config, depth=depth_map, chunk=7)
    assert depth.shape == (6, 8) and rgb is not None and rgb.shape == (6, 8, 3)
    assert torch.all((depth - Z0).abs() < 0.01)
    assert not depth.requires_grad
    free, _ = render_image(field, K, c2w, config, chunk=1000)
    assert torch.all((free - Z0).abs() < 0.01)
    _, none = render_image(field, K, c2w, RenderConfig(render_colour=False))
    assert none is None


def test_loss_gradient_reaches_the_pose_through_the_renderer() -> None:
    field = PlaneField(beta=10.0)
    c2w = torch.eye(4)
    c2w[2, 3] = 0.03  # the camera is 3 cm too far forward for the measured depth
    c2w.requires_grad_(True)
    directions = camera_directions(K)[:10]
    rays = rays_from_pixels(directions, c2w, torch.full((10,), Z0), torch.zeros(10, 3))
    output = render_rays(field, rays, RenderConfig(), perturb=False)
    terms = compute_losses(output, rays, LossWeights(), T, LossConfig())
    terms.total.backward()
    assert c2w.grad is not None and torch.isfinite(c2w.grad).all()
    assert c2w.grad[2, 3] > 0  # gradient descent moves the camera back
