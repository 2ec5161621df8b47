"""How far does the tracker go wrong from a correct start on a correct map?

A whole run's ATE mixes two errors: the tracker's own, and the map's, built at poses
that already drifted. This separates them. Frames before ``--switch`` take their
ground-truth poses instead of being tracked (the map is built at those poses, by the
run loop's own mapping: keyframes, window, and, as configured, its refinement of the
keyframe poses); from ``--switch`` on the configured tracker (``tracking.method``) takes
over, from the ground truth's pose and on a map in the ground truth's frame. No
alignment is needed: the error at frame i is the estimate's distance from the ground
truth there.

A stretch where a whole run travels further than the ground truth, and where this too
does, is one where the depth and the map agree with the estimate, not with the
reference; a stretch this tracks to within the run's spread is one where the whole
run's error came from its map.

It writes ``trajectory.txt`` (the run's poses, reference ones included) into ``--out``
and appends a table to docs/benchmarks.md: per ``--segment`` frames from the switch,
how far each trajectory travels (sum of 10-frame displacements, as
``trajectory_consistency.py`` counts it), their ratio, and the estimate's position and
rotation error at the segment's end.

With ``--probe`` every frame keeps its reference pose (the map stays in the reference's
frame throughout) and from the switch on the tracker runs once per frame from the
reference pose, its answer recorded and not used: how far one tracking call pulls away
from the reference, frame by frame, with no drift carried over. A tracker whose
objective agrees with the reference stays within a millimetre or so; a pull ahead along
the motion, frame after frame, is the over-travel a chained run accumulates. Writes the
tracker's answers as ``probed.txt`` beside ``trajectory.txt`` and a table of the pulls
per segment.

    python benchmarks/tracking_from_reference.py --config configs/sevenscenes/redkitchen_cpu.yaml \\
        --data ../shared/data/7scenes-redkitchen --switch 150 --frames 250 --out RUN_FOLDER \\
        [--probe] [mapping.optimise_poses=false]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import (
    DEFAULT_DOCS,
    add_device_argument,
    check_device,
    command_line,
    load_average,
    publish,
    section_head,
)
from trajectory_consistency import net_motion

from eslam.config import load_config
from eslam.config.device import resolve_device
from eslam.data import open_sequence
from eslam.geometry import rotation_angle
from eslam.io.trajectory import write_tum_trajectory
from eslam.slam.context import RunContext
from eslam.slam.loop import RunLoop
from eslam.slam.mapping.backend import make_back_end
from eslam.slam.run.observers import Observers
from eslam.slam.state import SLAMState, initial_state
from eslam.slam.tracking.base import Tracker, TrackingResult
from eslam.slam.tracking.frontend import TrackingFrontEnd
from eslam.slam.tracking.trackers import make_tracker
from eslam.slam.views import View

HOP = 10
"""Frames per displacement when summing how far a trajectory travels (:func:`net_motion`)."""


@dataclass
class ReferenceUntil:
    """A tracker that answers frames before ``switch`` with their reference pose and
    hands the rest to ``then`` (the configured tracker); with ``probe``, every frame
    keeps its reference pose and ``then`` runs from it from ``switch`` on, its answers
    kept in ``probed``.

    Attributes:
        reference: (N, 4, 4) float32 camera-to-world poses on the compute device.
        switch: first frame ``then`` tracks.
        state: the run's state (its ``next_frame`` is the frame being tracked).
        then: the tracker from ``switch`` on.
        probe: track from the reference pose and answer with the reference pose.
        probed: frame index -> the pose ``then`` answered (``probe`` only).
    """

    reference: torch.Tensor
    switch: int
    state: SLAMState
    then: Tracker
    probe: bool = False
    probed: dict[int, torch.Tensor] = dataclasses.field(default_factory=dict)

    def track(
        self, field: object, view: View, initial_pose: torch.Tensor, generator: torch.Generator
    ) -> TrackingResult:
        index = self.state.next_frame
        pose = self.reference[index]
        if index < self.switch:
            return TrackingResult(pose=pose, loss=torch.zeros((), device=pose.device))
        if not self.probe:
            return self.then.track(field, view, initial_pose, generator)  # type: ignore[arg-type]
        result = self.then.track(field, view, pose, generator)  # type: ignore[arg-type]
        self.probed[index] = result.pose.detach()
        return TrackingResult(pose=pose, loss=result.loss)


def drift_rows(estimate: np.ndarray, reference: np.ndarray, switch: int, segment: int) -> list[str]:
    """One markdown row per ``segment`` frames from ``switch - 1`` (the last reference
    pose) to the end: how far each trajectory travels there (:func:`net_motion`), their
    ratio, and the estimate's position error (cm) and rotation error (degrees) at the
    segment's last frame, without alignment."""
    rows = []
    start = switch - 1
    while start < len(estimate) - 1:
        end = min(start + segment, len(estimate) - 1)
        span = slice(start, end + 1)
        truth = net_motion(reference[span], HOP)
        moved = net_motion(estimate[span], HOP)
        position = np.linalg.norm(estimate[end, :3, 3] - reference[end, :3, 3])
        relative = np.linalg.inv(reference[end, :3, :3]) @ estimate[end, :3, :3]
        rotation = np.degrees(float(rotation_angle(torch.from_numpy(relative))))
        ratio = f"{moved / truth:.3f}" if truth > 0 else "-"
        rows.append(
            f"| {start}-{end} | {100 * truth:.1f} | {100 * moved:.1f} | {ratio} "
            f"| {100 * position:.2f} | {rotation:.2f} |"
        )
        start = end
    return rows


def pull_rows(probed: np.ndarray, reference: np.ndarray, switch: int, segment: int) -> list[str]:
    """One markdown row per ``segment`` frames from ``switch``: how far the tracker,
    started at each frame's reference pose, pulls away from it (``probed[k]`` is the
    answer for frame ``switch + k``). Columns: the reference's median step from the
    previous frame (mm), the median and largest pull (mm), the pull along the motion
    as a fraction of the step, sum_i <p_i, s_i / |s_i|> / sum_i |s_i| with p_i the
    pull and s_i the reference's step into frame i (0.1: the tracker's answer lies 10 %
    of a step ahead, the per-frame over-travel a chained run accumulates), and the
    median rotation pull (degrees)."""
    rows = []
    for start in range(switch, len(reference), segment):
        end = min(start + segment, len(reference))
        frames = np.arange(start, end)
        steps = reference[frames, :3, 3] - reference[frames - 1, :3, 3]
        lengths = np.linalg.norm(steps, axis=1)
        pulls = probed[frames - switch, :3, 3] - reference[frames, :3, 3]
        distances = np.linalg.norm(pulls, axis=1)
        moving = lengths > 0
        along = np.sum(pulls[moving] * steps[moving], axis=1) / lengths[moving]
        ahead = f"{along.sum() / lengths.sum():+.3f}" if lengths.sum() > 0 else "-"
        relative = np.linalg.inv(reference[frames, :3, :3]) @ probed[frames - switch, :3, :3]
        angles = np.degrees(rotation_angle(torch.from_numpy(relative)).numpy())
        rows.append(
            f"| {start}-{end - 1} | {1000 * np.median(lengths):.2f} "
            f"| {1000 * np.median(distances):.2f} | {1000 * distances.max():.2f} | {ahead} "
            f"| {np.median(angles):.3f} |"
        )
    return rows


@dataclass(frozen=True)
class ReferenceRun:
    """What :func:`track_from_reference` ran.

    Attributes:
        poses: (N, 4, 4) float64 camera-to-world poses of the run.
        reference: (N, 4, 4) float64 reference poses of the same frames.
        timestamps: (N,) their timestamps.
        seconds: mean seconds per frame (tracking and mapping) from the switch on.
        probed: (N - switch, 4, 4) float64 tracker answers from the reference poses
            (``probe`` only), else None.
    """

    poses: np.ndarray
    reference: np.ndarray
    timestamps: np.ndarray
    seconds: float
    probed: np.ndarray | None


def track_from_reference(
    config_path: Path,
    data: Path,
    switch: int,
    frames: int,
    device_name: str,
    overrides: tuple[str, ...] = (),
    probe: bool = False,
) -> ReferenceRun:
    """Run frames 0..``frames``-1 of ``data`` with reference poses before ``switch``
    and the config's tracker after it, or, with ``probe``, reference poses throughout
    and the tracker probed from each from ``switch`` on (module doc)."""
    config = load_config(config_path, [f"data.path={data}", f"device={device_name}", *overrides])
    sequence = open_sequence(config.data)
    if not 1 <= switch < frames <= len(sequence):
        raise SystemExit(
            f"{data}: need 1 <= --switch < --frames <= {len(sequence)}, got {switch}, {frames}"
        )
    reference = sequence.gt_poses()
    if reference is None or not np.isfinite(reference[:frames]).all():
        raise SystemExit(f"{data}: needs a ground-truth pose for each of its first {frames} frames")
    device = resolve_device(device_name)
    state = initial_state(config, sequence.intrinsics, device)
    context = RunContext.build(
        config, device, sequence.intrinsics, Observers([]), logging.getLogger("eslam"), str(data)
    )
    reference_poses = torch.as_tensor(reference[:frames], dtype=torch.float32, device=device)
    tracker = ReferenceUntil(reference_poses, switch, state, make_tracker(config), probe)
    loop = RunLoop(
        state, TrackingFrontEnd(context, tracker=tracker), make_back_end(context), context.observers
    )
    loop.run((sequence[i] for i in range(frames)), frames, None)
    spent = np.add(state.tracking_time[switch:], state.mapping_time[switch:])
    probed = None
    if probe:
        answers = [tracker.probed[index] for index in range(switch, frames)]
        probed = torch.stack(answers).detach().cpu().double().numpy()
    return ReferenceRun(
        poses=state.trajectory.poses.detach().cpu().double().numpy(),
        reference=reference[:frames],
        timestamps=sequence.timestamps()[:frames],
        seconds=float(np.mean(spent)),
        probed=probed,
    )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--config", type=Path, required=True)
    parser.add_argument("--data", type=Path, required=True, help="the sequence folder")
    parser.add_argument("--switch", type=int, required=True, help="first frame tracked")
    parser.add_argument("--frames", type=int, required=True, help="frames run in all")
    parser.add_argument("--segment", type=int, default=50, help="frames per table row (50)")
    parser.add_argument("--out", type=Path, required=True, help="folder for trajectory.txt")
    parser.add_argument(
        "--probe",
        action="store_true",
        help="reference poses throughout; the tracker runs from each from --switch on",
    )
    parser.add_argument("--threads", type=int, default=0, help="0 = torch's default")
    add_device_argument(parser)
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    parser.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    args = parser.parse_intermixed_args(argv)  # overrides may come before options
    check_device(parser, args)
    if args.segment < 1:
        parser.error("--segment must be >= 1")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    load_start = load_average()
    run = track_from_reference(
        args.config,
        args.data,
        args.switch,
        args.frames,
        args.device,
        tuple(args.overrides),
        args.probe,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    write_tum_trajectory(args.out / "trajectory.txt", run.timestamps, run.poses)
    head = section_head(
        "tracking_from_reference",
        resolve_device(args.device),
        (load_start, load_average()),
        command_line("benchmarks/tracking_from_reference.py", argv),
        f"{args.data}, frames 0-{args.frames - 1}",
        ("overrides", list(args.overrides)),
        args.note,
    )
    if run.probed is not None:
        write_tum_trajectory(args.out / "probed.txt", run.timestamps[args.switch :], run.probed)
        table = [
            f"- ground-truth poses for every frame; from frame {args.switch} the config's "
            f"tracker runs once per frame from the ground-truth pose ({run.seconds:.3f} s "
            "per frame from there, tracking and mapping), its answer recorded, not used",
            "",
            "| frames | ground-truth step, median (mm) | pull, median (mm) | pull, largest "
            "(mm) | pull along the motion / step | rotation pull, median (deg) |",
            "|---|---:|---:|---:|---:|---:|",
            *pull_rows(run.probed, run.reference, args.switch, args.segment),
        ]
    else:
        table = [
            f"- ground-truth poses before frame {args.switch}, then the config's tracker "
            f"({run.seconds:.3f} s per frame from there, tracking and mapping); errors "
            "without alignment",
            "",
            "| frames | ground-truth motion (cm) | estimated motion (cm) | estimate / ground "
            "truth | position error at the end (cm) | rotation error at the end (deg) |",
            "|---|---:|---:|---:|---:|---:|",
            *drift_rows(run.poses, run.reference, args.switch, args.segment),
        ]
    publish("\n".join([*head, *table, ""]), args.docs, args.no_append)


if __name__ == "__main__":
    main()
