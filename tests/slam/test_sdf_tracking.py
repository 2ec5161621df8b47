"""The SDF tracker on an analytic scene with exact ground truth: convergence from small
errors, failure reported (never a silent wrong pose) from large ones or wrong input;
the colour term's Jacobian, and the slide along a plain textured wall it recovers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from torch import nn

from eslam.config import FieldConfig, SdfTrackerConfig
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import pose_distance, se3_exp
from eslam.losses import depth_noise_scale
from eslam.render.rays import camera_directions
from eslam.slam.tracking.sdf import SdfTracker, sdf_points
from eslam.slam.tracking.sdf_system import (
    constrained_directions,
    field_derivatives,
    linearise,
    robust_weights,
    twist_jacobian,
)
from eslam.slam.views import make_view
from eslam.types import FieldOutput, Intrinsics

CAMERA = Intrinsics(width=96, height=72, fx=70.0, fy=70.0, cx=47.5, cy=35.5)
TRUNCATION = 0.06
ROOM = (torch.tensor([0.0, 0.0, 0.0]), torch.tensor([4.0, 3.0, 2.5]))
SPHERE = (torch.tensor([2.4, 1.7, 0.6]), 0.4)
BOX = (torch.tensor([1.0, 0.6, 0.0]), torch.tensor([1.6, 1.2, 0.8]))


def scene_sdf(points: torch.Tensor) -> torch.Tensor:
    """Exact signed distance (m) of a room with a sphere and a box; > 0 in free space."""
    low, high = ROOM
    room = torch.minimum(points - low, high - points).min(dim=-1).values
    centre, radius = SPHERE
    sphere = (points - centre).norm(dim=-1) - radius
    box_low, box_high = BOX
    middle, half = (box_low + box_high) / 2, (box_high - box_low) / 2
    q = (points - middle).abs() - half
    box = q.clamp(min=0).norm(dim=-1) + q.max(dim=-1).values.clamp(max=0)
    return torch.minimum(room, torch.minimum(sphere, box))


def scene_colour(points: torch.Tensor) -> torch.Tensor:
    """(N, 3) smooth texture in [0.2, 0.8]: stripes along y (R), z (G) and a diagonal (B),
    periods 50, 40 and 70 cm (so a plain wall x = const is textured)."""
    x, y, z = points.unbind(dim=-1)
    waves = (
        torch.sin(2 * math.pi * y / 0.5),
        torch.sin(2 * math.pi * z / 0.4),
        torch.sin(2 * math.pi * (x + y - z) / 0.7),
    )
    return 0.5 + 0.3 * torch.stack(waves, dim=-1)


class AnalyticField(nn.Module):
    """A SceneFieldLike whose TSDF is the exact, truncated distance of :func:`scene_sdf`
    and whose colour is :func:`scene_colour`."""

    truncation = TRUNCATION

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("bound", torch.tensor([[-0.2, 4.2], [-0.2, 3.2], [-0.2, 2.7]]))
        self.beta = torch.tensor(10.0)

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        sdf = (scene_sdf(points.double()) / TRUNCATION).clamp(-1.0, 1.0).to(points.dtype)
        rgb = scene_colour(points.double()).to(points.dtype) if with_rgb else None
        return FieldOutput(sdf=sdf, rgb=rgb)


def look_at(position, target) -> torch.Tensor:
    """Camera-to-world pose (OpenCV axes) at ``position`` looking at ``target``, z up."""
    position, target = np.asarray(position, float), np.asarray(target, float)
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, down, forward], axis=1)
    pose[:3, 3] = position
    return torch.from_numpy(pose).float()


def render_depth(pose: torch.Tensor) -> torch.Tensor:
    """(H, W) depth along the optical axis by sphere tracing the exact distance."""
    directions = camera_directions(CAMERA, dtype=torch.float64) @ pose[:3, :3].double().T
    origin = pose[:3, 3].double()
    t = torch.full((directions.shape[0],), 0.05, dtype=torch.float64)
    for _ in range(200):
        t = t + scene_sdf(origin + t[:, None] * directions)
    return t.reshape(CAMERA.height, CAMERA.width).float()


TRUE_POSE = look_at((3.3, 2.5, 1.5), (1.6, 1.0, 0.5))


@pytest.fixture(scope="module")
def view():
    depth = render_depth(TRUE_POSE)
    rgb = torch.zeros(CAMERA.height, CAMERA.width, 3)
    return make_view(rgb, depth, camera_directions(CAMERA), border=2)


def perturbed(translation_m: float, rotation_deg: float, seed: int) -> torch.Tensor:
    """TRUE_POSE moved by ``translation_m`` and turned by ``rotation_deg`` about random axes."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=3)
    w = rng.normal(size=3)
    twist = np.concatenate(
        [translation_m * v / np.linalg.norm(v), math.radians(rotation_deg) * w / np.linalg.norm(w)]
    )
    # rotate about the camera centre: pose' = exp(w) applied in the camera frame, then shift
    delta = se3_exp(torch.tensor([0.0, 0.0, 0.0, *twist[3:]]))
    pose = TRUE_POSE.double() @ delta
    pose[:3, 3] += torch.from_numpy(twist[:3])
    return pose.float()


def test_robust_weights() -> None:
    r = torch.tensor([0.0, 0.005, 0.02, -0.04])
    assert torch.allclose(robust_weights(r, 0.01, "huber"), torch.tensor([1.0, 1.0, 0.5, 0.25]))
    gm = robust_weights(r, 0.01, "geman_mcclure")
    assert float(gm[0]) == pytest.approx(1.0) and bool((gm[1:].diff() < 0).all())
    with pytest.raises(ValueError, match="robust"):
        robust_weights(r, 0.01, "cauchy")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_converges_from_3cm_3deg(view, seed: int) -> None:
    tracker = SdfTracker(SdfTrackerConfig())
    start = perturbed(0.03, 3.0, seed)
    error_t, error_r = pose_distance(start, TRUE_POSE)
    assert float(error_t) > 0.029 and math.degrees(float(error_r)) > 2.9
    result = tracker.track(AnalyticField(), view, start, torch.Generator().manual_seed(seed))
    error_t, error_r = pose_distance(result.pose, TRUE_POSE)
    assert result.quality is not None and not result.quality.failed
    assert float(error_t) < 0.003, f"{float(error_t) * 1000:.2f} mm"
    assert math.degrees(float(error_r)) < 0.2
    assert result.quality.inlier_fraction > 0.9 and result.quality.residual_m < 0.001


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_from_10cm_10deg_converges_or_reports_failure(view, seed: int) -> None:
    tracker = SdfTracker(SdfTrackerConfig())
    result = tracker.track(
        AnalyticField(), view, perturbed(0.10, 10.0, seed), torch.Generator().manual_seed(seed)
    )
    error_t, error_r = pose_distance(result.pose, TRUE_POSE)
    assert result.quality is not None
    if not result.quality.failed:  # never a silent wrong pose
        assert float(error_t) < 0.005 and math.degrees(float(error_r)) < 0.3
    else:  # a failed frame reports why
        assert result.quality.inlier_fraction < 0.5 or result.quality.residual_m > 0.02


def test_depth_that_fits_nothing_is_reported_as_failed() -> None:
    # structureless depth (noise from 0.5 to 3 m): no pose puts it on the surfaces
    noise = 0.5 + 2.5 * torch.rand(
        CAMERA.height, CAMERA.width, generator=torch.Generator().manual_seed(0)
    )
    wrong = make_view(
        torch.zeros(CAMERA.height, CAMERA.width, 3), noise, camera_directions(CAMERA), 2
    )
    config = dataclasses.replace(SdfTrackerConfig(), iterations=5)
    result = SdfTracker(config).track(
        AnalyticField(), wrong, TRUE_POSE, torch.Generator().manual_seed(0)
    )
    assert result.quality is not None and result.quality.failed
    assert result.quality.inlier_fraction < 0.5


WALL_POSE = look_at((3.0, 1.5, 1.25), (4.0, 1.5, 1.25))
"""1 m in front of the wall x = 4, seeing nothing else: only x and the tilts are observable."""


def test_degenerate_directions_of_a_wall_are_found_and_held() -> None:
    wall = make_view(
        torch.zeros(CAMERA.height, CAMERA.width, 3),
        render_depth(WALL_POSE),
        camera_directions(CAMERA),
        2,
    )
    config = dataclasses.replace(SdfTrackerConfig(), degeneracy=0.01)
    points, _ = sdf_points(wall, 2000, torch.Generator().manual_seed(0))
    system = linearise(AnalyticField(), points, WALL_POSE, config)
    projector, degenerate = constrained_directions(system, config.degeneracy)
    # sliding along y and z, and turning about the wall's normal (x), say nothing
    assert degenerate == 3
    along_normal = torch.tensor([1.0, 0, 0, 0, 0, 0], dtype=torch.float64)
    assert torch.allclose(projector @ along_normal, along_normal, atol=1e-6)
    for sliding in ([0, 1.0, 0, 0, 0, 0], [0, 0, 1.0, 0, 0, 0]):
        assert float((projector @ torch.tensor(sliding, dtype=torch.float64)).norm()) < 1e-6
    # a turn about the normal through the points' centroid: omega = e_x, v = -omega x c
    spin = torch.cat(
        (
            -torch.linalg.cross(torch.tensor([1.0, 0, 0]).double(), system.centre),
            torch.tensor([1.0, 0, 0]).double(),
        )
    )
    assert float((projector @ spin).norm()) < 1e-6
    off, none = constrained_directions(system, 0.0)
    assert none == 0 and torch.equal(off, torch.eye(6, dtype=torch.float64))

    # tracking from 2 cm off along the normal and 2 cm along the wall: the normal offset
    # is corrected, the sliding one is kept exactly (the data cannot see it)
    start = WALL_POSE.clone()
    start[:3, 3] += torch.tensor([-0.02, 0.02, 0.0])
    result = SdfTracker(config).track(
        AnalyticField(), wall, start, torch.Generator().manual_seed(0)
    )
    offset = result.pose[:3, 3] - WALL_POSE[:3, 3]
    assert abs(float(offset[0])) < 0.001
    assert float(offset[1]) == pytest.approx(0.02, abs=1e-5)
    # and the frame says so: it fits perfectly, yet three directions were not measured
    assert result.quality is not None and not result.quality.failed
    assert result.quality.inlier_fraction > 0.9
    assert result.quality.degenerate_directions == 3
    assert result.quality.information < 0.01


@pytest.mark.parametrize("degeneracy", [0.0, 0.01])
def test_a_view_of_the_whole_room_reports_no_degenerate_direction(view, degeneracy) -> None:
    config = dataclasses.replace(SdfTrackerConfig(), degeneracy=degeneracy)
    result = SdfTracker(config).track(
        AnalyticField(), view, perturbed(0.01, 1.0, 0), torch.Generator().manual_seed(0)
    )
    assert result.quality is not None
    assert result.quality.information > 0.02  # every direction seen by many normals
    # the count is only made with the test on; off, nothing is claimed either way
    assert result.quality.degenerate_directions == (0 if degeneracy > 0 else None)


def test_the_wall_reports_its_information_with_the_test_off() -> None:
    wall = make_view(
        torch.zeros(CAMERA.height, CAMERA.width, 3),
        render_depth(WALL_POSE),
        camera_directions(CAMERA),
        2,
    )
    result = SdfTracker(SdfTrackerConfig()).track(
        AnalyticField(), wall, WALL_POSE, torch.Generator().manual_seed(0)
    )
    assert result.quality is not None and result.quality.degenerate_directions is None
    assert result.quality.information < 1e-4  # the figure still shows the slide


def textured_view(pose: torch.Tensor):
    """The exact depth at ``pose`` and the colour :func:`scene_colour` of the surface
    points it sees."""
    depth = render_depth(pose)
    directions = camera_directions(CAMERA)
    points = (directions * depth.reshape(-1, 1)) @ pose[:3, :3].T + pose[:3, 3]
    rgb = scene_colour(points.double()).float().reshape(CAMERA.height, CAMERA.width, 3)
    return make_view(rgb, depth, directions, 2)


def colour_twist_jacobian(field, points: torch.Tensor) -> torch.Tensor:
    """(N, 3, 6) d c_k(exp(xi) p) / d xi at xi = 0 from :func:`field_derivatives`."""
    _, _, _, jacobian = field_derivatives(field, points, with_rgb=True)
    assert jacobian is not None
    return torch.stack(
        [twist_jacobian(points, jacobian[:, channel]) for channel in range(3)], dim=1
    )


def finite_difference_jacobian(field, points: torch.Tensor, step: float) -> torch.Tensor:
    """(N, 3, 6) the same by central differences of the decoded colour over left twists."""
    columns = []
    for axis in range(6):
        twist = torch.zeros(6, dtype=points.dtype)
        twist[axis] = step
        plus = se3_exp(twist)
        minus = se3_exp(-twist)
        ahead = field.query(points @ plus[:3, :3].T + plus[:3, 3]).rgb
        behind = field.query(points @ minus[:3, :3].T + minus[:3, 3]).rgb
        columns.append((ahead - behind) / (2 * step))
    return torch.stack(columns, dim=-1)


def test_colour_jacobian_equals_finite_differences() -> None:
    # the analytic texture, and a small random SceneField (its planes and decoder)
    points = 0.5 + 3.0 * torch.rand(64, 3, generator=torch.Generator().manual_seed(0))
    analytic = AnalyticField().double()
    expected = finite_difference_jacobian(analytic, points.double(), 1e-5)
    actual = colour_twist_jacobian(analytic, points.double())
    assert torch.allclose(actual, expected, atol=1e-6, rtol=1e-5)

    torch.manual_seed(0)
    config = FieldConfig(
        channels=4,
        geometry_resolution=(0.24, 0.12),
        appearance_resolution=(0.24, 0.08),
        init_std=0.5,
    )
    learned = SceneField(config, torch.tensor([[0.0, 1.0], [-0.5, 0.0], [0.0, 0.7]])).double()
    learned.requires_grad_(False)
    inside = torch.rand(64, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    inside = inside * torch.tensor([1.0, 0.5, 0.7], dtype=torch.float64)
    inside = inside + torch.tensor([0.0, -0.5, 0.0], dtype=torch.float64)
    expected = finite_difference_jacobian(learned, inside, 1e-7)
    actual = colour_twist_jacobian(learned, inside)
    assert float(actual.abs().max()) > 0.1  # the random field's colour does vary
    assert torch.allclose(actual, expected, atol=1e-5, rtol=1e-4)


COLOUR = dataclasses.replace(SdfTrackerConfig(), colour_weight=0.05)


def test_colour_term_converges_from_3cm_3deg() -> None:
    tracker = SdfTracker(COLOUR)
    start = perturbed(0.03, 3.0, 0)
    result = tracker.track(
        AnalyticField(), textured_view(TRUE_POSE), start, torch.Generator().manual_seed(0)
    )
    error_t, error_r = pose_distance(result.pose, TRUE_POSE)
    assert result.quality is not None and not result.quality.failed
    assert float(error_t) < 0.003, f"{float(error_t) * 1000:.2f} mm"
    assert math.degrees(float(error_r)) < 0.2


def test_colour_term_recovers_the_slide_along_a_textured_wall() -> None:
    # a plain wall: the SDF cannot see a slide along it or a turn about its normal,
    # its texture can
    wall = textured_view(WALL_POSE)
    start = WALL_POSE.clone()
    start[:3, 3] += torch.tensor([-0.02, 0.02, -0.015])
    start[:3, :3] = start[:3, :3] @ se3_exp(torch.tensor([0, 0, 0, 0, 0, 0.02]))[:3, :3]
    errors = {}
    for weight in (0.0, 0.05):
        config = dataclasses.replace(SdfTrackerConfig(), colour_weight=weight)
        result = SdfTracker(config).track(
            AnalyticField(), wall, start, torch.Generator().manual_seed(0)
        )
        assert result.quality is not None and not result.quality.failed
        offset = result.pose[:3, 3] - WALL_POSE[:3, 3]
        _, turn = pose_distance(result.pose, WALL_POSE)
        errors[weight] = (offset, math.degrees(float(turn)))
    # SDF alone: the distance to the wall is fixed, the slide and the spin are not
    sdf_offset, sdf_turn = errors[0.0]
    assert abs(float(sdf_offset[0])) < 0.001
    assert float(sdf_offset[1:].norm()) > 0.015 and sdf_turn > 0.5
    # with the colour term every direction converges
    colour_offset, colour_turn = errors[0.05]
    assert float(colour_offset.norm()) < 0.002, f"{colour_offset.tolist()}"
    assert colour_turn < 0.1


class CountsColourQueries(AnalyticField):
    """The analytic field, counting the queries that decode colour."""

    def __init__(self) -> None:
        super().__init__()
        self.colour_queries = 0

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        self.colour_queries += int(with_rgb)
        return super().query(points, with_rgb)


DEGENERATE_COLOUR = SdfTrackerConfig(colour_weight=0.05, colour_when="degenerate", degeneracy=0.01)


def test_colour_when_degenerate_turns_colour_on_for_a_wall() -> None:
    wall = textured_view(WALL_POSE)
    start = WALL_POSE.clone()
    start[:3, 3] += torch.tensor([-0.02, 0.02, -0.015])
    field = CountsColourQueries()
    result = SdfTracker(DEGENERATE_COLOUR).track(
        field, wall, start, torch.Generator().manual_seed(0)
    )
    assert field.colour_queries > 0
    offset = result.pose[:3, 3] - WALL_POSE[:3, 3]
    # the slide the geometry cannot see (kept whole with degeneracy alone) is found
    assert float(offset.norm()) < 0.002, f"{offset.tolist()}"
    assert result.quality is not None and not result.quality.failed


def test_colour_when_degenerate_leaves_a_structured_view_to_the_geometry() -> None:
    view = textured_view(TRUE_POSE)
    start = perturbed(0.03, 3.0, 0)
    field = CountsColourQueries()
    chosen = SdfTracker(DEGENERATE_COLOUR).track(
        field, view, start, torch.Generator().manual_seed(0)
    )
    geometric = SdfTracker(dataclasses.replace(DEGENERATE_COLOUR, colour_weight=0.0)).track(
        AnalyticField(), view, start, torch.Generator().manual_seed(0)
    )
    assert field.colour_queries == 0  # not one colour decode: the geometric tracker's cost
    assert torch.equal(chosen.pose, geometric.pose)
    assert chosen.quality == geometric.quality


def test_colour_when_degenerate_needs_the_degeneracy_test() -> None:
    with pytest.raises(ValueError, match="colour_when: degenerate needs degeneracy > 0"):
        SdfTrackerConfig(colour_weight=0.05, colour_when="degenerate")
    SdfTrackerConfig(colour_when="degenerate")  # no colour term: nothing to choose


def test_colour_term_needs_colour() -> None:
    class Colourless(AnalyticField):
        def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
            return FieldOutput(sdf=super().query(points, False).sdf, rgb=None)

    points, _ = sdf_points(textured_view(TRUE_POSE), 50, torch.Generator().manual_seed(0))
    with pytest.raises(ValueError, match="colour_weight"):
        linearise(Colourless(), points, TRUE_POSE, COLOUR, torch.zeros(50, 3))
    with pytest.raises(ValueError, match="colour_weight"):
        SdfTrackerConfig(colour_weight=-1.0)


def test_depth_noise_weighting_divides_residuals_and_rows_by_the_noise(view) -> None:
    """With z0 set, J^T W J and J^T W r are those of r_i / (z_i/z0)^2 and J_i / (z_i/z0)^2
    (all Huber weights 1 here), while ``residual`` stays in metres for the quality figures."""
    field = AnalyticField()
    points_cam, _ = sdf_points(view, 500, torch.Generator().manual_seed(3))
    pose = perturbed(0.004, 0.3, 3)
    plain = SdfTrackerConfig(robust_scale=10.0)
    weighted = linearise(
        field, points_cam, pose, dataclasses.replace(plain, noise_reference_depth=1.5)
    )
    reference = linearise(field, points_cam, pose, plain)
    sigma = (points_cam[:, 2] / 1.5).square()
    assert torch.equal(sigma, depth_noise_scale(points_cam[:, 2], 1.5))
    assert float(sigma.max() / sigma.min()) > 4  # the view spans near and far points
    points = points_cam @ pose[:3, :3].T + pose[:3, 3]
    sdf, gradient, _, _ = field_derivatives(field, points, with_rgb=False)
    rows = (TRUNCATION * twist_jacobian(points, gradient)).double() * reference.valid[:, None]
    scaled = rows / sigma.double()[:, None]
    expected_h = scaled.T @ scaled
    expected_g = scaled.T @ (TRUNCATION * sdf / sigma).double()
    torch.testing.assert_close(weighted.hessian, expected_h, rtol=1e-5, atol=1e-9)
    torch.testing.assert_close(weighted.gradient, expected_g, rtol=1e-5, atol=1e-9)
    assert not torch.allclose(reference.hessian, expected_h, rtol=1e-2)
    torch.testing.assert_close(weighted.residual, reference.residual)
    assert torch.equal(depth_noise_scale(points_cam[:, 2], None), torch.ones(500))


def test_depth_noise_weighting_converges_from_3cm_3deg(view) -> None:
    config = SdfTrackerConfig(noise_reference_depth=2.0)
    result = SdfTracker(config).track(
        AnalyticField(), view, perturbed(0.03, 3.0, 0), torch.Generator().manual_seed(0)
    )
    error_t, error_r = pose_distance(result.pose, TRUE_POSE)
    assert result.quality is not None and not result.quality.failed
    assert float(error_t) < 0.003 and math.degrees(float(error_r)) < 0.2
    with pytest.raises(ValueError, match="noise_reference_depth"):
        SdfTrackerConfig(noise_reference_depth=0.0)
