"""Mapping passes over the stored keyframes: the map following a loop correction, and
the global refinement at the end of a run (``mapping.loops``, docs/loops.md).

:class:`KeyframePasses` runs mapping calls on windows that together hold each chosen
keyframe once per pass (the back end's mapper and keyframe views), and after a loop
correction either refits the keyframes the correction moved (``map: refit``) or builds a
new field from every keyframe at its corrected pose (``map: rebuild``: the first frame's
TSDF warm start run over all keyframes in turn, :func:`tsdf_warm_start_views`, then the
passes).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import torch

from eslam.slam.context import RunContext
from eslam.slam.cuda_graphs import WindowMapper
from eslam.slam.loops.pose_graph import anchors, carry_poses
from eslam.slam.mapping.keyframe_views import KeyframeViews
from eslam.slam.mapping.mapper import mapping_schedule
from eslam.slam.mapping.warm_start import WarmStart, tsdf_warm_start_views
from eslam.slam.state import SLAMState, new_field


class KeyframePasses:
    """Mapping passes over stored keyframes (module doc).

    Args:
        context: the run's settings.
        mapper: the back end's window mapper.
        views: the back end's keyframe views of a run's state.
    """

    def __init__(
        self,
        context: RunContext,
        mapper: WindowMapper,
        views: Callable[[SLAMState], KeyframeViews],
    ) -> None:
        self.context = context
        self.mapper = mapper
        self.views = views

    def follow_correction(self, state: SLAMState, moved: list[int]) -> None:
        """The map follows a loop correction (``mapping.loops.map``) that moved the
        keyframes ``moved`` (ids): refit = ``refit_passes`` over those keyframes, poses
        held; rebuild = a new field, its TSDF regressed on every keyframe at its
        corrected pose (``rebuild_warm_start`` steps each), then fitted from every
        keyframe."""
        loops = self.context.config.mapping.loops
        if loops.map == "rebuild":
            field = state.field
            if field is None:
                raise RuntimeError("a loop correction before the field exists")
            state.field = new_field(self.context.config, field.bound, self.context.device)
            every = list(range(len(state.keyframes)))
            warmed = loops.rebuild_warm_start > 0
            if warmed:
                config = self.context.config.mapping
                steps = loops.rebuild_warm_start * len(every)
                tsdf_warm_start_views(
                    state.field,
                    self.views(state).views(every),
                    state.keyframes.poses.to(self.context.device),
                    WarmStart(steps, config.first_warm_start_points),
                    config.lr_planes,
                    config.lr_decoders,
                    state.generator,
                )
            self.run(state, 1, optimise_poses=False, first=True, warmed=warmed)
            moved = every
        self.run(state, loops.refit_passes, optimise_poses=False, among=moved)

    def run(
        self,
        state: SLAMState,
        passes: int,
        optimise_poses: bool,
        first: bool = False,
        among: list[int] | None = None,
        warmed: bool = False,
    ) -> None:
        """``passes`` over every keyframe (or the ids ``among``): mapping calls of
        ``mapping.iterations`` steps on windows of ``mapping.window`` keyframes holding
        each once per pass, in an order drawn from the run's generator; keyframe 0's
        pose held, the others' refined with ``optimise_poses``. ``first``: one call with
        the first frame's schedule (the map is new) on the first window instead, without
        its TSDF warm start when ``warmed`` (the map's was run on every keyframe)."""
        field, store = state.field, state.keyframes
        if field is None:
            raise RuntimeError("mapping passes before the field exists")
        config = self.context.config.mapping
        frame_of = store.frame_indices
        generator = state.generator
        count = state.next_frame
        before = state.trajectory.poses[:count].detach().cpu().double().numpy()
        keyframes_before = before[list(frame_of)]
        chosen = list(range(len(store))) if among is None else among
        if not chosen:  # a correction that moved no keyframe far enough to refit
            return
        schedule = mapping_schedule(config, first=first)
        if warmed:
            schedule = replace(schedule, warm_start=None)
        for _ in range(passes):
            order = torch.randperm(len(chosen), generator=generator, device=generator.device)
            windows = torch.split(torch.tensor(chosen)[order.cpu()], config.window)
            for window in windows[:1] if first else windows:
                keyframes = sorted(window.tolist())
                optimise = [optimise_poses and k != 0 for k in keyframes]
                result = self.mapper.map(
                    field,
                    self.views(state).views(keyframes),
                    store.poses[keyframes].to(self.context.device),
                    optimise,
                    schedule,
                    generator=state.generator,
                )
                moved = [i for i, flag in enumerate(optimise) if flag]
                if moved:
                    frames = [frame_of[keyframes[i]] for i in moved]
                    state.trajectory.set_poses(frames, result.poses[moved])
        if optimise_poses:  # every frame moves with the latest keyframe at or before it
            after = state.trajectory.poses[list(frame_of)].detach().cpu().double().numpy()
            moved = carry_poses(before, anchors(frame_of, count), keyframes_before, after)
            state.trajectory.set_poses(list(range(count)), torch.from_numpy(moved))
