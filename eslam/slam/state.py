"""The state of a run, and its checkpoint (map.pt): everything needed to resume.

map.pt holds the field (planes, decoders, beta, bound), the trajectory so far (poses,
timestamps, ground truth), the keyframes (compact images and frame indices), the random
generator's state and the timings. No optimiser state is needed: tracking and mapping
make fresh optimisers per call (as the release does), so a run resumed after frame i
continues exactly as an uninterrupted one would.

The state changes only at frame boundaries as far as anyone outside the loop can tell:
:meth:`SLAMState.mark` notes where a frame starts and :meth:`SLAMState.rollback` undoes
a frame that failed half way (the field is restored from a copy taken before mapping),
so a checkpoint written after a failure holds exactly the completed frames.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch

from eslam.config import ESLAMConfig
from eslam.errors import InputError
from eslam.field.plane_sampling import PLANE_SAMPLINGS
from eslam.field.scene_field import SceneField
from eslam.io.checkpoint import load_checkpoint, save_checkpoint
from eslam.mesh.observed import ObservedViews
from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.mapping.windows import WindowStrategy, make_window_strategy
from eslam.slam.tracking.base import RECOVERIES, TrackingQuality
from eslam.slam.trajectory import Trajectory
from eslam.types import Intrinsics


@dataclass(eq=False)
class SLAMState:
    """Mutable state of a run between frames.

    Attributes:
        field: the scene field (on the run's device); None until the first frame with
            depth fixes the bound (when ``scene.bound`` is not set).
        trajectory: every frame's pose estimate, timestamp and ground truth so far.
        keyframes: the keyframe store (poses read from ``trajectory``).
        window: the keyframe window strategy.
        generator: the run's random generator (on the run's device).
        tracking_time / mapping_time: seconds per processed frame.
        tracking_quality: per processed frame, a row of :data:`TRACKING_COLUMNS` from
            trackers that judge themselves, NaNs otherwise.
        last_mapped: whether the last processed frame needs no mapping at the end of the
            stream (it is a keyframe, or has no depth, or no frame was processed).
        components: the state of the run's components (the mapping back end's, a
            custom front end's, ...) by component name: plain values (numbers, strings,
            lists, dicts, tensors), checkpointed and rolled back with the frame.
    """

    field: SceneField | None
    trajectory: Trajectory
    keyframes: KeyframeStore
    window: WindowStrategy
    generator: torch.Generator
    tracking_time: list[float] = field(default_factory=list)
    mapping_time: list[float] = field(default_factory=list)
    tracking_quality: list[list[float]] = field(default_factory=list)
    last_mapped: bool = True
    components: dict[str, dict] = field(default_factory=dict)

    @property
    def next_frame(self) -> int:
        """Index of the next frame to process (= frames processed so far)."""
        return len(self.trajectory)

    def observed_views(self) -> ObservedViews:
        """The keyframes as observed space for mesh extraction.

        The depth maps stay in the store (uint16 codes on the keyframe device, no copy);
        observed space reaches T (the field's truncation) behind each measured depth.
        """
        if self.field is None:
            raise ValueError("no frame with depth was mapped: there is no observed space")
        store = self.keyframes
        return ObservedViews(
            poses=store.poses.clone(),
            depths=store.depth_codes,
            intrinsics=store.intrinsics,
            margin=self.field.truncation,
            depth_scale=1.0 / store.depth_units_per_metre,
        )

    def mark(self) -> FrameMark:
        """Where the next frame starts, to :meth:`rollback` to if it fails half way."""
        return FrameMark(
            frames=len(self.trajectory),
            keyframes=len(self.keyframes),
            generator=self.generator.get_state(),
            last_mapped=self.last_mapped,
            components=copy.deepcopy(self.components),
        )

    def component(self, name: str) -> dict:
        """The state dict of component ``name`` (created empty on first use)."""
        return self.components.setdefault(name, {})

    def rollback(self, mark: FrameMark, field_before: SceneField | None) -> None:
        """Undo everything after ``mark``; ``field_before`` is the field as it was then
        (a copy taken before mapping changed it), or None when the field was untouched."""
        self.trajectory.truncate(mark.frames)
        self.keyframes.truncate(mark.keyframes)
        self.generator.set_state(mark.generator)
        del self.tracking_time[mark.frames :]
        del self.mapping_time[mark.frames :]
        del self.tracking_quality[mark.frames :]
        self.last_mapped = mark.last_mapped
        self.components = copy.deepcopy(mark.components)
        if field_before is not None:
            self.field = field_before


@dataclass(frozen=True, eq=False)
class FrameMark:
    """The state's sizes and generator at the start of a frame (see SLAMState.mark)."""

    frames: int
    keyframes: int
    generator: torch.Tensor
    last_mapped: bool
    components: dict[str, dict]


TRACKING_COLUMNS = (
    "tracking_iterations",
    "tracking_inlier_fraction",
    "tracking_residual_m",
    "tracking_failed",
    "tracking_information",
    "tracking_degenerate_directions",
    "tracking_recovery",
    "tracking_recovered_from",
    "tracking_start_matches",
    "tracking_start_shift_m",
    "tracking_overruled",
)
"""The columns of :attr:`SLAMState.tracking_quality` (the fields of
:class:`~eslam.slam.tracking.base.TrackingQuality`; failed and overruled as 1/0;
recovery as 0 when the first try passed or nothing recovered the frame, else 1 + its
place in :data:`~eslam.slam.tracking.base.RECOVERIES`), also the names of timings.json's
per-frame lists."""


def quality_row(quality: TrackingQuality | None) -> list[float]:
    """A frame's :attr:`SLAMState.tracking_quality` row (NaNs without a judgement)."""
    if quality is None:
        return [float("nan")] * len(TRACKING_COLUMNS)
    return [
        float(quality.iterations),
        quality.inlier_fraction,
        quality.residual_m,
        float(quality.failed),
        quality.information,
        float("nan") if quality.degenerate_directions is None else quality.degenerate_directions,
        0.0 if quality.recovery is None else 1.0 + RECOVERIES.index(quality.recovery),
        float("nan") if quality.recovered_from is None else float(quality.recovered_from),
        float("nan") if quality.start_matches is None else float(quality.start_matches),
        float("nan") if quality.start_shift_m is None else quality.start_shift_m,
        float(quality.overruled),
    ]


_FAILED = TRACKING_COLUMNS.index("tracking_failed")
_RECOVERY = TRACKING_COLUMNS.index("tracking_recovery")
_RECOVERED_FROM = TRACKING_COLUMNS.index("tracking_recovered_from")
_DEGENERATE = TRACKING_COLUMNS.index("tracking_degenerate_directions")
_OVERRULED = TRACKING_COLUMNS.index("tracking_overruled")


def failed_row(row: list[float]) -> bool:
    """Whether a quality row is a frame its tracker judged failed."""
    return row[_FAILED] == 1


def untracked_row(row: list[float]) -> bool:
    """Whether a quality row is a frame with no judgement (no depth, emptied by a view
    filter, frame 0, or a tracker that does not judge itself)."""
    return row[_FAILED] != row[_FAILED]  # NaN


def recovery_of(row: list[float]) -> tuple[str, int | None] | None:
    """How a quality row's frame was recovered and from which keyframe's frame
    (:data:`~eslam.slam.tracking.base.RECOVERIES`), or None (not recovered, not judged,
    or a map saved before recovery existed)."""
    code = row[_RECOVERY]
    if not code >= 1:  # NaN: not judged
        return None
    source = row[_RECOVERED_FROM]
    return RECOVERIES[int(code) - 1], (int(source) if source == source else None)


def degenerate_row(row: list[float]) -> bool:
    """Whether a quality row is a tracked, not failed frame with a degenerate direction
    (NaN compares false: frames not judged or not tested are not degenerate)."""
    return row[_DEGENERATE] > 0 and row[_FAILED] == 0


def _trailing(rows: list[list[float]], test: Callable[[list[float]], bool]) -> int:
    """How many of the last ``rows`` pass ``test``, counted back from the newest."""
    count = 0
    for row in reversed(rows):
        if not test(row):
            break
        count += 1
    return count


def failed_stretch(rows: list[list[float]]) -> int:
    """How many of the last ``rows`` are failed frames: how long the camera is lost."""
    return _trailing(rows, failed_row)


def overruled_row(row: list[float]) -> bool:
    """Whether a quality row is a frame whose start of features overruled the tracker
    (NaN, in a map saved before the column existed, is not)."""
    return row[_OVERRULED] == 1


def overruled_stretch(rows: list[list[float]]) -> int:
    """How many of the last ``rows`` are overruled frames, in a row."""
    return _trailing(rows, overruled_row)


def longest_failed_run(rows: list[list[float]]) -> int:
    """The most consecutive failed frames among ``rows``."""
    longest = current = 0
    for row in rows:
        current = current + 1 if failed_row(row) else 0
        longest = max(longest, current)
    return longest


def degenerate_stretch(rows: list[list[float]]) -> int:
    """How many of the last ``rows`` are degenerate frames (:func:`degenerate_row`)."""
    return _trailing(rows, degenerate_row)


def quality_rows(saved: list[list[float]]) -> list[list[float]]:
    """Checkpointed quality rows at today's width: a map saved before the information
    (or the start's) columns existed has 4 (or 8) per row; the missing ones read NaN
    (not computed)."""
    width = len(TRACKING_COLUMNS)
    return [list(row) + [float("nan")] * (width - len(row)) for row in saved]


def run_generator(config: ESLAMConfig, device: torch.device) -> torch.Generator:
    """The run's random generator on ``device``, seeded with ``config.seed``."""
    generator = torch.Generator(device=device)
    generator.manual_seed(config.seed)
    return generator


def new_field(config: ESLAMConfig, bound: torch.Tensor, device: torch.device) -> SceneField:
    """A fresh field over ``bound``, its features drawn from a CPU generator seeded with
    ``config.seed`` (no global random state is read or changed)."""
    generator = torch.Generator().manual_seed(config.seed)
    return SceneField(config.field, bound, generator).to(device)


def initial_state(config: ESLAMConfig, intrinsics: Intrinsics, device: torch.device) -> SLAMState:
    """A fresh state: no frames, no keyframes, seeded generator; the field is built now
    over ``scene.bound`` when it is set, else from the first frame with depth."""
    trajectory = Trajectory(device)
    keyframe_device = torch.device(config.mapping.keyframe_device or device)
    bound = config.scene.bound
    return SLAMState(
        field=None if bound is None else new_field(config, torch.tensor(bound), device),
        trajectory=trajectory,
        keyframes=KeyframeStore(intrinsics, trajectory, keyframe_device),
        window=make_window_strategy(config.mapping),
        generator=run_generator(config, device),
    )


def save_state(path: Path, state: SLAMState) -> None:
    """Write the checkpoint ``path`` (atomically)."""
    field_state = None
    if state.field is not None:
        field_state = {k: v.detach().cpu() for k, v in state.field.state_dict().items()}
    save_checkpoint(
        path,
        {
            "field": field_state,
            "trajectory": state.trajectory.state_dict(),
            "keyframes": state.keyframes.state_dict(),
            "generator": state.generator.get_state(),
            "tracking_time": list(state.tracking_time),
            "mapping_time": list(state.mapping_time),
            "tracking_quality": [list(row) for row in state.tracking_quality],
            "last_mapped": state.last_mapped,
            "components": state.components,
        },
    )


def load_state(path: Path, config: ESLAMConfig, device: torch.device) -> SLAMState:
    """Read the checkpoint ``path`` back into a state on ``device``.

    Raises:
        ConfigError: ``field.plane_sampling: triton`` on a device it cannot run on.
        InputError: a map written by another configuration or format version.
    """
    PLANE_SAMPLINGS.check(config.field.plane_sampling, device)
    saved = load_checkpoint(path, map_location="cpu")
    try:
        field_ = None
        if saved["field"] is not None:
            field_ = SceneField.from_state(config.field, saved["field"]).to(device)
        trajectory = Trajectory.from_state_dict(saved["trajectory"], device)
        keyframe_device = torch.device(config.mapping.keyframe_device or device)
        keyframes = KeyframeStore.from_state_dict(saved["keyframes"], trajectory, keyframe_device)
        generator = torch.Generator(device=device)
        generator.set_state(saved["generator"])
        return SLAMState(
            field=field_,
            trajectory=trajectory,
            keyframes=keyframes,
            window=make_window_strategy(config.mapping),
            generator=generator,
            tracking_time=list(saved["tracking_time"]),
            mapping_time=list(saved["mapping_time"]),
            tracking_quality=quality_rows(saved["tracking_quality"]),
            last_mapped=bool(saved["last_mapped"]),
            components=dict(saved.get("components", {})),  # none before they were saved
        )
    except (KeyError, RuntimeError, ValueError) as error:
        raise InputError(
            path, f"map does not match this run's configuration ({error})", "start a new run"
        ) from None
