"""Tracking on observed space only (eslam.slam.tracking.observed_view)."""

from __future__ import annotations

import torch

from eslam.mesh.observed import ObservedViews
from eslam.render.rays import camera_directions
from eslam.slam.tracking.observed_view import observed_pixels
from eslam.slam.views import View, make_view, restrict_view, sample_view_pixels, sampleable_mask
from eslam.types import Intrinsics

CAMERA = Intrinsics(width=40, height=30, fx=30.0, fy=30.0, cx=19.5, cy=14.5)


def wall_view(depth_m: float = 2.0, border: int = 0) -> tuple[View, torch.Tensor]:
    """A view of a wall ``depth_m`` in front of the camera, and its (H, W) depth."""
    depth = torch.full((CAMERA.height, CAMERA.width), depth_m)
    rgb = torch.zeros(CAMERA.height, CAMERA.width, 3)
    return make_view(rgb, depth, camera_directions(CAMERA), border), depth


def translated(x: float, z: float = 0.0) -> torch.Tensor:
    pose = torch.eye(4)
    pose[0, 3], pose[2, 3] = x, z
    return pose


def test_restrict_view_keeps_only_the_sampleable_pixels_asked_for() -> None:
    view, _ = wall_view(border=2)
    keep = torch.zeros(CAMERA.height * CAMERA.width, dtype=torch.bool)
    keep[: CAMERA.width * 10] = True  # the top ten rows, two of them in the border
    restricted = restrict_view(view, keep)
    expected = sampleable_mask(view) & keep
    assert torch.equal(sampleable_mask(restricted), expected)
    assert restricted.sampleable_pixels() == 8 * (CAMERA.width - 4)
    drawn = sample_view_pixels(restricted, 500, torch.Generator().manual_seed(0))
    assert bool(expected[drawn].all())


def test_pixels_outside_every_keyframe_view_are_not_observed() -> None:
    """A keyframe at the origin saw the wall; the frame, 0.5 m to the right, sees a strip
    of it that lies outside the keyframe's image."""
    _, depth = wall_view()
    keyframes = ObservedViews(translated(0.0)[None], depth[None], CAMERA, margin=0.1)
    view, _ = wall_view()
    observed = observed_pixels(view, translated(0.5), keyframes, stride=1)
    columns = observed.reshape(CAMERA.height, CAMERA.width).all(dim=0)
    # the keyframe's image ends at x = 2 m * 20 / 30 = 1.33 m; the frame's column u sees
    # x = 0.5 + 2 (u - 19.5) / 30, beyond 1.33 from u = 32
    assert bool(columns[:32].all()) and not bool(columns[32:].any())


def test_space_further_behind_the_keyframe_depth_than_the_margin_is_not_observed() -> None:
    _, depth = wall_view(2.0)
    keyframes = ObservedViews(translated(0.0)[None], depth[None], CAMERA, margin=0.1)
    behind, _ = wall_view(2.3)  # a surface the keyframe's wall hid
    assert not bool(observed_pixels(behind, translated(0.0), keyframes).any())
    near, _ = wall_view(2.05)  # within the margin, or in front: observed
    assert bool(observed_pixels(near, translated(0.0), keyframes).all())
    front, _ = wall_view(1.0)
    assert bool(observed_pixels(front, translated(0.0), keyframes).all())


def test_any_keyframe_observing_a_pixel_is_enough_and_the_grid_spreads_the_answer() -> None:
    _, depth = wall_view()
    poses = torch.stack([translated(0.0), translated(1.0)])
    keyframes = ObservedViews(poses, torch.stack([depth, depth]), CAMERA, margin=0.1)
    view, _ = wall_view()
    exact = observed_pixels(view, translated(0.5), keyframes, stride=1)
    assert bool(exact.all())  # the two keyframes' images cover the frame's between them
    only_first = ObservedViews(poses[:1], depth[None], CAMERA, margin=0.1)
    exact = observed_pixels(view, translated(0.5), only_first, stride=1)
    coarse = observed_pixels(view, translated(0.5), only_first, stride=4)
    # each pixel takes the answer of the grid point at the top left of its 4 x 4 block
    grid = exact.reshape(CAMERA.height, CAMERA.width)[::4, ::4]
    spread = grid.repeat_interleave(4, 0).repeat_interleave(4, 1)[: CAMERA.height, : CAMERA.width]
    assert torch.equal(coarse.reshape(CAMERA.height, CAMERA.width), spread)


def test_a_grid_point_without_depth_keeps_its_block() -> None:
    _, depth = wall_view()
    keyframes = ObservedViews(translated(0.0)[None], depth[None], CAMERA, margin=0.1)
    view, frame_depth = wall_view(3.0)  # all hidden behind the keyframe's wall ...
    frame_depth[0, 0] = 0.0  # ... but the first grid point has no depth
    holed = make_view(torch.zeros(CAMERA.height, CAMERA.width, 3), frame_depth, view.directions)
    observed = observed_pixels(holed, translated(0.0), keyframes, stride=4).reshape(30, 40)
    assert bool(observed[:4, :4].all()) and not bool(observed[4:, :].any())
    assert not bool(observed[:4, 4:].any())


def test_a_run_tracks_each_frame_on_its_observed_part(
    tiny_sequence, tmp_path, monkeypatch, tiny_static_ate_cm: float
) -> None:
    """With ``tracking.observed_only`` every tracked frame's view is restricted (some
    frames lose the pixels that came into view since the last keyframe) and the run
    still tracks the synthetic camera."""
    import eslam.slam.tracking.frontend as frontend
    from eslam.slam.session import run_slam
    from tests.conftest import TINY_FRAMES, tiny_config

    counts: list[tuple[int, int]] = []

    def recording(view: View, keep: torch.Tensor) -> View:
        restricted = restrict_view(view, keep)
        counts.append((view.sampleable_pixels(), restricted.sampleable_pixels()))
        return restricted

    monkeypatch.setattr(frontend, "restrict_view", recording)
    config = tiny_config(tiny_sequence, "tracking.observed_only=true")
    run = run_slam(config, tmp_path / "run")
    assert len(counts) == TINY_FRAMES - 1
    assert all(0 < after <= before for before, after in counts)
    assert any(after < before for before, after in counts)
    assert run.metrics["ate_rmse_cm"] < 0.3 * tiny_static_ate_cm
