"""The state of a run, and its checkpoint (map.pt): everything needed to resume.

map.pt holds the field (planes, decoders, beta, bound), every pose estimated so far,
the keyframes (compact) with their refined poses, the random generator's state and the
timings. No optimiser state is needed: tracking and mapping make fresh optimisers per
call (as the release does), so a run resumed after frame i continues exactly as an
uninterrupted one would.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import torch

from eslam.config import ESLAMConfig
from eslam.data import RGBDSequence
from eslam.errors import InputError
from eslam.field.scene_field import SceneField
from eslam.io.checkpoint import load_checkpoint, save_checkpoint
from eslam.mesh.observed import ObservedViews
from eslam.slam.bounds_policy import initial_bound
from eslam.slam.keyframes import KeyframeStore, make_window_strategy


@dataclass(eq=False)
class SLAMState:
    """Mutable state of a run between frames.

    Attributes:
        field: the scene field (on the run's device).
        keyframes: the keyframe store.
        window: the keyframe window strategy.
        poses: (N, 4, 4) float32 camera-to-world estimates; rows >= next_frame unset.
        next_frame: index of the next frame to process.
        generator: the run's random generator (on the run's device).
        tracking_time / mapping_time: seconds per processed frame.
        bound_warned: whether the run warned about depth points outside the bound
            (once per run; not saved, so a resumed run may warn once more).
    """

    field: SceneField
    keyframes: KeyframeStore
    window: object
    poses: torch.Tensor
    next_frame: int
    generator: torch.Generator
    tracking_time: list[float] = field(default_factory=list)
    mapping_time: list[float] = field(default_factory=list)
    bound_warned: bool = False

    def observed_views(self) -> ObservedViews:
        """The keyframes as observed space for mesh extraction.

        The depth maps stay in the store (uint16 codes on the keyframe device, no copy);
        observed space reaches T (the field's truncation) behind each measured depth.
        """
        store = self.keyframes
        return ObservedViews(
            poses=store.poses.clone(),
            depths=store.depth_codes,
            intrinsics=store.intrinsics,
            margin=self.field.truncation,
            depth_scale=1.0 / store.depth_units_per_metre,
        )


def _generator(config: ESLAMConfig, device: torch.device) -> torch.Generator:
    generator = torch.Generator(device=device)
    generator.manual_seed(config.seed)
    return generator


def initial_state(config: ESLAMConfig, sequence: RGBDSequence, device: torch.device) -> SLAMState:
    """A fresh state for ``sequence``: new field, no keyframes, seeded generator.

    The field covers ``config.scene.bound``, or a bound estimated from frame 0
    (:func:`~eslam.slam.bounds_policy.initial_bound`).
    """
    torch.manual_seed(config.seed)
    field_ = SceneField(config.field, initial_bound(config.scene, sequence)).to(device)
    keyframe_device = torch.device(config.mapping.keyframe_device or device)
    return SLAMState(
        field=field_,
        keyframes=KeyframeStore(sequence.intrinsics, keyframe_device),
        window=make_window_strategy(config.mapping),
        poses=torch.full((len(sequence), 4, 4), float("nan"), device=device),
        next_frame=0,
        generator=_generator(config, device),
    )


def save_state(path: Path, state: SLAMState) -> None:
    """Write the checkpoint ``path`` (atomically)."""
    save_checkpoint(
        path,
        {
            "field": {k: v.detach().cpu() for k, v in state.field.state_dict().items()},
            "keyframes": state.keyframes.state_dict(),
            "poses": state.poses.detach().cpu(),
            "next_frame": state.next_frame,
            "generator": state.generator.get_state(),
            "tracking_time": list(state.tracking_time),
            "mapping_time": list(state.mapping_time),
        },
    )


def load_state(path: Path, config: ESLAMConfig, device: torch.device) -> SLAMState:
    """Read the checkpoint ``path`` back into a state on ``device``."""
    saved = load_checkpoint(path, map_location="cpu")
    try:
        field_ = SceneField.from_state(config.field, saved["field"]).to(device)
        keyframe_device = torch.device(config.mapping.keyframe_device or device)
        keyframes = KeyframeStore.from_state_dict(saved["keyframes"], keyframe_device)
        generator = torch.Generator(device=device)
        generator.set_state(saved["generator"])
        return SLAMState(
            field=field_,
            keyframes=keyframes,
            window=make_window_strategy(config.mapping),
            poses=saved["poses"].to(device),
            next_frame=int(saved["next_frame"]),
            generator=generator,
            tracking_time=list(saved["tracking_time"]),
            mapping_time=list(saved["mapping_time"]),
        )
    except (KeyError, RuntimeError, ValueError) as error:
        raise InputError(
            path, f"map does not match this run's configuration ({error})", "start a new run"
        ) from None
