"""Convergence of mapping and tracking on a synthetic room with exact depth and poses.

Everything is seeded and runs on the CPU. A module fixture fits a SceneField (the
paper's field settings) to every 4th frame of a short synthetic sequence with the
ground-truth poses held fixed; the tests then check the geometry on held-out frames
and that tracking against the frozen map recovers a perturbed pose.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import pytest
import torch

from eslam.config import ESLAMConfig
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import (
    pose_distance,
    pose_from_quaternion_translation,
    quaternion_translation_from_pose,
    se3_exp,
)
from eslam.losses import compute_losses
from eslam.render.rays import camera_directions, rays_from_pixels
from eslam.render.renderer import render_rays, render_rays_without_depth
from eslam.render.sampling import ray_box_intersection
from eslam.slam.mapping.mapper import MappingSchedule, MappingSettings, map_window
from eslam.slam.tracking.render import TrackingSettings, track_frame
from eslam.slam.tracking.trackers import make_tracker
from eslam.slam.views import View, make_view, sample_view_rays
from eslam.synthetic import SynthConfig, build_scene, generate_sequence, scene_bound
from eslam.types import Frame, RayBatch

pytestmark = pytest.mark.slow  # fits a map over many iterations (still run in CI)

SEQUENCE = SynthConfig(frames=40, width=160, height=120, seed=0)
KEYFRAMES = list(range(0, SEQUENCE.frames, 4))
HELD_OUT = (2, 6, 10)
"""Frames never mapped, each between two keyframes."""
BORDER = 8
"""tracking.border for 160x120 images (the paper's 75 is for 1200x680)."""
MAPPING_RAYS = 1000
"""Rays per mapping step over the whole window (paper 4000): 100 per keyframe here."""
FIRST_ITERATIONS = 150
"""Steps of the first call (one keyframe, learning rates x 5), as the loop's first frame."""
WINDOWS = 6
WINDOW_ITERATIONS = 20
"""Then WINDOWS calls on all keyframes at the paper's learning rates."""


def _view(frame: Frame, directions: torch.Tensor, border: int = 0) -> View:
    rgb = torch.from_numpy(frame.rgb).float() / 255.0
    return make_view(rgb, torch.from_numpy(frame.depth), directions, border)


def _pose(frame: Frame) -> torch.Tensor:
    assert frame.pose_gt is not None
    return torch.from_numpy(frame.pose_gt).float()


def _new_field(config: ESLAMConfig) -> SceneField:
    bound = torch.tensor(scene_bound(build_scene(SEQUENCE.scene, SEQUENCE.seed)))
    return SceneField(config.field, bound)


@dataclass(frozen=True)
class FittedMap:
    config: ESLAMConfig
    field: SceneField
    frames: list[Frame]
    directions: torch.Tensor


@pytest.fixture(scope="module")
def fitted() -> FittedMap:
    """A field mapped from the keyframes with ground-truth (fixed) poses, as the loop maps."""
    torch.manual_seed(0)
    config = ESLAMConfig()
    config.mapping.rays = MAPPING_RAYS
    frames = list(generate_sequence(SEQUENCE))
    directions = camera_directions(frames[0].intrinsics)
    field = _new_field(config)
    views = [_view(frames[k], directions) for k in KEYFRAMES]
    poses = torch.stack([_pose(frames[k]) for k in KEYFRAMES])
    settings = MappingSettings(config.mapping, config.render, config.loss)
    generator = torch.Generator().manual_seed(0)
    first = map_window(
        field,
        views[:1],
        poses[:1],
        [False],
        settings,
        MappingSchedule(FIRST_ITERATIONS, config.mapping.first_lr_factor, MAPPING_RAYS),
        generator,
    )
    assert math.isfinite(float(first.loss))
    for _ in range(WINDOWS):
        result = map_window(
            field,
            views,
            poses,
            [False] * len(views),
            settings,
            MappingSchedule(WINDOW_ITERATIONS, 1.0, MAPPING_RAYS),
            generator,
        )
        assert torch.equal(result.poses, poses)  # nothing flagged: poses stay ground truth
    field.requires_grad_(False)
    return FittedMap(config, field, frames, directions)


def test_gradients_reach_planes_decoders_and_poses() -> None:
    torch.manual_seed(0)
    config = ESLAMConfig()
    tiny = SynthConfig(frames=1, width=32, height=24, seed=0)
    frame = next(iter(generate_sequence(tiny)))
    field = _new_field(config)
    view = _view(frame, camera_directions(frame.intrinsics), border=2)
    quaternion, translation = quaternion_translation_from_pose(_pose(frame))
    quaternion = quaternion.clone().requires_grad_(True)
    translation = translation.clone().requires_grad_(True)
    generator = torch.Generator().manual_seed(0)

    c2w = pose_from_quaternion_translation(quaternion, translation)
    rays = sample_view_rays(view, c2w, 256, generator)
    output = render_rays(field, rays, config.render, perturb=True, generator=generator)
    terms = compute_losses(output, rays, config.mapping.weights, field.truncation, config.loss)
    terms.total.backward()

    named = [(f"plane {i}", p) for i, p in enumerate(field.plane_parameters())]
    named += [(f"geometry_decoder.{n}", p) for n, p in field.geometry_decoder.named_parameters()]
    named += [
        (f"appearance_decoder.{n}", p) for n, p in field.appearance_decoder.named_parameters()
    ]
    named += [("beta", field.beta), ("quaternion", quaternion), ("translation", translation)]
    assert len(field.plane_parameters()) == 4  # geometry and appearance, coarse and fine
    for name, parameter in named:
        assert parameter.grad is not None, name
        assert bool(torch.isfinite(parameter.grad).all()), name
        assert float(parameter.grad.abs().sum()) > 0.0, name


def _surface_depth(field: SceneField, rays: RayBatch, samples: int = 256) -> torch.Tensor:
    """Depth of the first TSDF zero crossing, found without the measured depth.

    ``samples`` uniform samples between the entry and exit of the field's box (about
    3 cm apart, less than the truncation, so no crossing is stepped over), then a
    linear interpolation between the last sample in front and the first behind. This
    is the depth of the surface a mesh of the field would show (the paper's Depth L1
    is measured on the mesh). Rays with no crossing get depth 0.
    """
    near, far = ray_box_intersection(rays.origins, rays.directions, field.bound)
    near = near.clamp(min=0.0)
    t = torch.linspace(0.0, 1.0, samples)
    z = near[:, None] + t[None, :] * (far - near)[:, None]
    points = rays.origins[:, None, :] + z[..., None] * rays.directions[:, None, :]
    sdf = field.query(points.reshape(-1, 3), with_rgb=False).sdf.reshape(z.shape)
    crossing = (sdf[:, :-1] > 0) & (sdf[:, 1:] <= 0)
    found = crossing.any(dim=1)
    first = crossing.float().argmax(dim=1)
    rows = torch.arange(len(z))
    s0, s1 = sdf[rows, first], sdf[rows, first + 1]
    z0, z1 = z[rows, first], z[rows, first + 1]
    depth = z0 + s0 / (s0 - s1).clamp(min=1e-6) * (z1 - z0)
    return torch.where(found, depth, torch.zeros_like(depth))


@torch.no_grad()
def test_mapping_with_ground_truth_poses_reaches_depth_l1_under_2cm(fitted: FittedMap) -> None:
    field, render = fitted.field, fitted.config.render
    errors: dict[str, list[torch.Tensor]] = {"surface": [], "honest": [], "guided": []}
    for index in HELD_OUT:
        assert index not in KEYFRAMES
        frame = fitted.frames[index]
        view = _view(frame, fitted.directions, BORDER)
        pixels = torch.nonzero(view.cumulative.diff(prepend=view.cumulative.new_zeros(1)))
        pixels = pixels.squeeze(1)[::4]  # every 4th sampleable pixel keeps it quick
        rays = rays_from_pixels(
            view.directions[pixels], _pose(frame), view.depth[pixels], view.rgb[pixels]
        )
        honest = render_rays_without_depth(field, rays.origins, rays.directions, render)
        guided = render_rays(field, rays, render, perturb=False)
        errors["surface"].append(_surface_depth(field, rays) - rays.depth)
        errors["honest"].append(honest.depth - rays.depth)
        errors["guided"].append(guided.depth - rays.depth)
    l1 = {name: float(torch.cat(e).abs().mean()) for name, e in errors.items()}
    print(f"depth L1 on frames {HELD_OUT}: " + ", ".join(f"{k} {v:.4f} m" for k, v in l1.items()))
    # The geometry: depth of the field's surface (TSDF zero crossing), found along the
    # ray without the measured depth, as a mesh of the map would show it.
    assert l1["surface"] < 0.02
    # Volume-rendered depth is biased towards the camera by ESLAM's density itself, not
    # by the map: alpha = 1 - exp(-beta sigmoid(-beta s)) does not depend on the sample
    # spacing, and in free space (s = 1, beta = 10) every sample still absorbs 4.5e-4.
    # For an exact planar TSDF 2-3 m away this costs -1.7 to -2.3 cm with the 32 + 8
    # depth-guided samples and -2.5 to -3.4 cm with the 64 + 8 samples to the box exit
    # (more samples: more bias). Hence looser bounds that still catch a broken map.
    assert l1["guided"] < 0.03
    assert l1["honest"] < 0.08


TRACKED = 6
"""The held-out frame tracked from a perturbed pose."""


def _perturbed(truth: torch.Tensor) -> torch.Tensor:
    """``truth`` moved 3 cm (camera frame), then turned 3 degrees about its centre (seeded)."""
    generator = torch.Generator().manual_seed(0)
    direction = torch.randn(3, generator=generator)
    axis = torch.randn(3, generator=generator)
    offset = 0.03 * direction / direction.norm()
    rotation = math.radians(3.0) * axis / axis.norm()
    zero = torch.zeros(3)
    start = truth @ se3_exp(torch.cat((offset, zero))) @ se3_exp(torch.cat((zero, rotation)))
    moved, turned = pose_distance(start, truth)
    assert abs(float(moved) - 0.03) < 1e-5
    assert abs(math.degrees(float(turned)) - 3.0) < 1e-3
    return start


def test_tracking_converges_from_3cm_3deg(fitted: FittedMap) -> None:
    frame = fitted.frames[TRACKED]
    assert TRACKED not in KEYFRAMES
    truth = _pose(frame)
    start = _perturbed(truth)

    # The paper tracks Replica with 8 steps at lr 0.001: Adam moves each parameter by at
    # most about lr per step, enough for the ~1 cm between frames. From 3 cm / 3 degrees
    # (quaternion components ~0.026 off) we need more steps, and a higher lr: the error
    # first collapses into the rotation-translation valley (turning about the centre
    # looks like sliding sideways) and then slides along it slowly; at lr 0.001-0.002
    # 150 steps did not always reach 5 mm, lr 0.003 does in ~100. track_frame returns the
    # iterate with the lowest loss, compared across different random ray batches; the
    # paper's 2000 rays keep that loss noise low enough for the pick to be a converged
    # iterate (with 500-1000 rays it sometimes returned one 7-8 mm off).
    config = fitted.config
    tracking = dataclasses.replace(
        config.tracking.render,
        iterations=120,
        rays=2000,
        lr_translation=0.003,
        lr_rotation=0.003,
    )
    settings = TrackingSettings(tracking, config.render, config.loss)
    view = _view(frame, fitted.directions, BORDER)
    result = track_frame(fitted.field, view, start, settings, torch.Generator().manual_seed(0))

    error_t, error_r = pose_distance(result.pose, truth)
    print(f"tracking error {float(error_t) * 1000:.2f} mm, {math.degrees(float(error_r)):.3f} deg")
    assert float(error_t) < 0.005
    assert math.degrees(float(error_r)) < 0.3


def test_sdf_and_hybrid_tracking_on_a_learned_map(fitted: FittedMap) -> None:
    """On a map learned by ESLAM's own mapping (not an exact SDF), the SDF tracker recovers
    the 3 cm / 3 degree perturbation to under 3 mm / 0.2 degrees (measured: 0.70 mm,
    0.023 degrees in 8 iterations), and the hybrid tracker is no worse than the
    rendering tracker with the paper's settings from the same start."""
    frame = fitted.frames[TRACKED]
    truth = _pose(frame)
    start = _perturbed(truth)
    view = _view(frame, fitted.directions, BORDER)
    config = fitted.config

    def error(method: str) -> tuple[float, float]:
        tracking = dataclasses.replace(config.tracking, method=method)
        tracker = make_tracker(dataclasses.replace(config, tracking=tracking))
        result = tracker.track(fitted.field, view, start, torch.Generator().manual_seed(0))
        assert result.quality is None or not result.quality.failed
        moved, turned = pose_distance(result.pose, truth)
        print(f"{method}: {float(moved) * 1000:.2f} mm, {math.degrees(float(turned)):.3f} deg")
        return float(moved), math.degrees(float(turned))

    sdf_t, sdf_r = error("sdf")
    assert sdf_t < 0.003 and sdf_r < 0.2
    hybrid_t, hybrid_r = error("hybrid")
    render_t, render_r = error("render")
    assert hybrid_t <= render_t and hybrid_r <= render_r
