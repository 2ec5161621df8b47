"""How far from one mapped keyframe can the SDF tracker hold a frame?

Maps the sequence's first frame alone (``CONFIG`` and its overrides, one frame: e.g.
``mapping.first_iterations=10`` for what a real-time run's first call does), then, for
each frame ``--frames`` ahead of it, looks at the frame from its reference pose (the
ground truth, expressed in the run's frame 0): the share of its pixels in space the
first frame observed, the share of its points that fit the map there (the tracker's
inliers, ``tracking.sdf``'s band and robust scale), and where the SDF tracker goes
when started at that reference, on the whole view and on its observed part only
(``tracking.observed_only``): inliers, failed or not, and its distance from the
reference. Where the inlier share at the reference falls below the failure threshold,
no start can make the frame pass; where the tracker walks off the reference, the map
there no longer pins the pose. A live run on a CPU whose frames outrun its mapper
lives in these rows (docs/results.md, "Live").

    python benchmarks/keyframe_reach.py --config sevenscenes/redkitchen_cpu \\
        --data ../shared/data/7scenes-redkitchen --out /tmp/reach --frames 15,30,45,63,87 \\
        mapping.first_iterations=10

Prints a markdown table only.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np
import torch

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import pose_distance
from eslam.render.rays import camera_directions
from eslam.slam.session import run_slam
from eslam.slam.state import load_state
from eslam.slam.tracking.observed_view import observed_pixels
from eslam.slam.tracking.sdf import SdfTracker, quality, sdf_points
from eslam.slam.tracking.sdf_system import linearise
from eslam.slam.views import View, make_view, restrict_view, upload_frame

HEADER = (
    "| frames on | observed share | inliers at the reference "
    "| tracked from it: inliers / off (mm, deg) / failed "
    "| on observed space: inliers / off (mm, deg) / failed |\n"
    "|---:|---:|---:|---|---|"
)


def tracked(tracker: SdfTracker, field: SceneField, view: View, reference: torch.Tensor) -> str:
    """One cell: the SDF tracker started at ``reference`` on ``view``."""
    result = tracker.track(field, view, reference, torch.Generator().manual_seed(1))
    assert result.quality is not None
    translation, rotation = pose_distance(result.pose, reference)
    return (
        f"{result.quality.inlier_fraction:.2f} / {1000 * float(translation):.1f}, "
        f"{math.degrees(float(rotation)):.2f} / {'yes' if result.quality.failed else 'no'}"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", required=True, help="config file or packaged name")
    parser.add_argument("--data", type=Path, required=True, help="a sequence with ground truth")
    parser.add_argument("--out", type=Path, required=True, help="folder for the one-frame run")
    parser.add_argument(
        "--frames", required=True, help="frames ahead of the first, comma-separated: 15,30,45"
    )
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("overrides", nargs="*", help="config overrides, key=value")
    args = parser.parse_args(argv)
    args.frames = [int(text) for text in args.frames.split(",")]
    torch.set_num_threads(args.threads)
    settings = [f"data.path={args.data}", *args.overrides, "output.progress=false"]
    config = load_config(args.config, settings)
    run_slam(
        dataclasses.replace(config, data=dataclasses.replace(config.data, max_frames=1)),
        args.out,
        overwrite=True,
    )
    sequence = open_sequence(config.data)
    truth = sequence.gt_poses()
    if truth is None or max(args.frames) >= len(sequence):
        raise SystemExit(f"{args.data}: needs ground truth and {max(args.frames) + 1} frames")
    state = load_state(args.out / "map.pt", config, torch.device("cpu"))
    field, views = state.field, state.observed_views()  # frame 0 mapped, as observed space
    assert field is not None
    field.requires_grad_(False)
    start = state.trajectory.poses[0].double().numpy()
    first = start @ np.linalg.inv(truth[0])  # ground truth -> the run's frame
    directions = camera_directions(sequence.intrinsics)
    settings_sdf = config.tracking.sdf
    geometric = dataclasses.replace(settings_sdf, colour_weight=0.0)
    tracker = SdfTracker(geometric)
    print(HEADER)
    for ahead in args.frames:
        frame = sequence[ahead]
        rgb, depth = upload_frame(frame.rgb, frame.depth, "cpu")
        view = make_view(rgb, depth, directions, config.tracking.border)
        reference = torch.from_numpy(first @ truth[ahead]).float()
        points, _ = sdf_points(view, max(settings_sdf.levels), torch.Generator().manual_seed(0))
        inliers, _ = quality(linearise(field, points, reference, geometric), geometric)
        observed = restrict_view(view, observed_pixels(view, reference, views))
        share = observed.sampleable_pixels() / max(view.sampleable_pixels(), 1)
        print(
            f"| {ahead} | {share:.2f} | {inliers:.2f} | {tracked(tracker, field, view, reference)} "
            f"| {tracked(tracker, field, observed, reference)} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
