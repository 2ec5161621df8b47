"""What the tracking front end tries when the tracker fails a frame
(``tracking.recovery``; docs/tracking.md, "Recovery").

A frame fails when too few of its points fit the map, or they fit it badly, from the
motion model's guess: the guess is too far (a jerk, a stretch without depth), or the
view is new. A failed frame is no keyframe and the next guess holds still, so once the
camera has moved on nothing brings the track back. :class:`Recovery` tries, in order, until one try
passes the tracker's own tests (inlier fraction, residual, reach from its start) with
at least ``min_inlier_fraction`` inliers (a stricter test than a frame tracked from
the guess passes: a try from another pose can fit part of a view at a wrong pose):

1. ``start``: other starting poses, each on the whole frame: the last pose held still
   and the poses of the ``keyframe_starts`` keyframes nearest the guess; the try that
   passes with the most inliers is taken;
2. ``relocalised``: once ``relocalise_after`` frames in a row failed (this one
   included), the ``candidates`` keyframes that look most like the frame
   (:class:`~eslam.slam.places.index.PlaceIndex`) are verified one by one by tracking
   the whole frame from the pose their feature matches give (a rigid fit of the
   matched features' depth points), or from their own
   pose when too few matches agree; the best passing try is taken.

The first try of a frame after a failed or untracked one (no depth, a view filter
emptied it) starts from a guess no tracked frame backs, so it too must reach
``min_inlier_fraction`` (:meth:`Recovery.doubts`), else the tries above follow: after
a stretch without depth the tracker otherwise settles on a wrong pose with half its
points on the floor. A frame started from its features (``tracking.start: features``)
is not doubted: its start comes from points matched to the last frame with features
or to a keyframe, not from the failed frame's guess, and the tracker's own tests judge
it as any other frame (in real time the stricter test failed frames the map held,
and the track drifted while their features carried them: docs/results.md).

A failed frame whose start came from its features (``tracking.start: features``)
keeps that pose: its features carry the camera. The tries above run for it too on
recorded data; in real time (``carried``: null, the default) they are skipped, since
the frames the camera sends while they run are dropped, and the tries start from
poses no better than the features' (the last pose, keyframes' poses, feature matches
to keyframes verified against the same map; what that measured: docs/results.md).

A recovered frame is reported with how (:attr:`TrackingQuality.recovery`) and is made
a keyframe by the back end, so the map grows into what it sees. A frame that fits
nothing keeps the guess, as before. Every try draws its points from the run's
generator, so only runs with a failed frame change.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from eslam.config import RecoveryConfig
from eslam.geometry.pose import pose_distance
from eslam.slam.context import RunContext
from eslam.slam.places.index import Place, PlaceMatch, Places, describe
from eslam.slam.state import SLAMState, failed_row, failed_stretch, untracked_row
from eslam.slam.tracking.base import Recovery as How
from eslam.slam.tracking.base import Tracker, TrackingQuality, judged
from eslam.slam.views import View
from eslam.types import Frame

Start = tuple[torch.Tensor, int | None]
"""A starting pose (4, 4) and the frame index of the keyframe it is the pose of (None
for the last pose)."""

SAME_START_M = 1e-3
"""Starting poses closer than this (metres, and radians of turn) to one already tried
are not tried again."""


@dataclass(frozen=True, eq=False)
class Recovered:
    """A passing try: the frame's pose and the tracker's judgement, with how it was found."""

    pose: torch.Tensor
    quality: TrackingQuality


class Recovery:
    """The tries of the module doc, for one run.

    Args:
        context: the run (``tracking.recovery`` from its config).
        tracker: the front end's tracker.
        places: the run's place index (shared with the front end's feature start).
    """

    def __init__(self, context: RunContext, tracker: Tracker, places: Places | None = None) -> None:
        self.context = context
        self.settings: RecoveryConfig = context.config.tracking.recovery
        self.tracker = tracker
        self.places = Places(context.config.tracking.features) if places is None else places
        carried = self.settings.carried
        # whether a failed frame carried by its features is tried too (module doc)
        self.tries_carried = not context.real_time if carried is None else carried

    def recover(
        self,
        frame: Frame,
        view: View,
        guess: torch.Tensor,
        state: SLAMState,
        place: Place | None = None,
    ) -> Recovered | None:
        """The first of the module doc's tries that passes for ``frame`` (``view``: its
        images, no filter applied), whose try from ``guess`` failed; None when none
        passes. ``place``: the frame already described (the feature start's), else it
        is described when relocalising."""
        best = None
        for start, keyframe in self.starts(guess, state):
            found = self.attempt(view, start, state)
            if found is not None and (best is None or better(found, best[0])):
                best = (found, keyframe)
        if best is not None:
            return tagged(best[0], "start", best[1])
        lost = failed_stretch(state.tracking_quality) + 1
        if self.settings.relocalise_after and lost >= self.settings.relocalise_after:
            return self.relocalise(frame, view, state, place)
        return None

    def doubts(self, state: SLAMState) -> bool:
        """Whether the next frame's guess rests on no tracked frame: the last frame
        failed, or was not tracked (after frame 0, which starts at its own pose)."""
        rows = state.tracking_quality
        if not rows:
            return False
        return failed_row(rows[-1]) or (len(rows) > 1 and untracked_row(rows[-1]))

    def attempt(self, view: View, start: torch.Tensor, state: SLAMState) -> Recovered | None:
        """The tracker from ``start`` on ``view``; None unless it passes (:meth:`passes`)."""
        found = self.tried(view, start, state)
        return found if found is not None and self.passes(found.quality) else None

    def tried(self, view: View, start: torch.Tensor, state: SLAMState) -> Recovered | None:
        """:meth:`attempt`'s try, passing or not (None: the tracker gave no judgement)."""
        assert state.field is not None
        result = self.tracker.track(state.field, view, start, state.generator)
        pose, quality = judged(result, start)
        return None if quality is None else Recovered(pose, quality)

    def passes(self, quality: TrackingQuality) -> bool:
        """Whether a try's judgement is good enough to take: the tracker's own tests,
        and at least ``min_inlier_fraction`` inliers."""
        return not quality.failed and quality.inlier_fraction >= self.settings.min_inlier_fraction

    def starts(self, guess: torch.Tensor, state: SLAMState) -> list[Start]:
        """Starting poses other than ``guess``: the last pose, then the poses of the
        ``keyframe_starts`` keyframes nearest ``guess`` (metres plus radians), each with
        the frame index of its keyframe (None for the last pose); near-duplicates dropped."""
        store = state.keyframes
        candidates: list[Start] = [(state.trajectory.poses[-1], None)]
        if self.settings.keyframe_starts and len(store):
            poses = store.poses.to(guess)
            translation, rotation = pose_distance(guess[None], poses)
            order = torch.argsort(translation + rotation, stable=True)
            frames = store.frame_indices
            for k in order[: self.settings.keyframe_starts].tolist():
                candidates.append((poses[k], frames[k]))
        tried = [guess]
        chosen = []
        for pose, keyframe in candidates:
            pose = pose.to(guess)
            if not any(near(pose, other) for other in tried):
                chosen.append((pose, keyframe))
                tried.append(pose)
        return chosen

    def relocalise(
        self, frame: Frame, view: View, state: SLAMState, place: Place | None = None
    ) -> Recovered | None:
        """Step 2 of the module doc: the most alike keyframes, verified by tracking
        (each refused candidate is logged)."""
        store = state.keyframes
        places = self.places.of(store)
        query = describe(frame.rgb, frame.depth, store, places.orb) if place is None else place
        best = None
        for k, similarity in places.alike(query, self.settings.candidates):
            match = places.locate(query, k, self.settings.min_matches, seed=state.next_frame)
            if match is not None:
                start = torch.from_numpy(match.pose).to(view.depth)
            else:
                start = store.poses[k].to(view.depth)
            found = self.tried(view, start, state)
            keyframe = store.frame_indices[k]
            if found is None or not self.passes(found.quality):
                self.refused(state.next_frame, keyframe, similarity, match, found)
            elif best is None or better(found, best[0]):
                best = (found, keyframe)
        if best is None:
            return None
        return tagged(best[0], "relocalised", best[1])

    def refused(
        self,
        index: int,
        keyframe: int,
        similarity: float,
        match: PlaceMatch | None,
        found: Recovered | None,
    ) -> None:
        """Log a relocalisation candidate that did not fit the map."""
        matches = (
            "too few matches agree on a pose"
            if match is None
            else (f"{match.inliers} matches agree on a pose")
        )
        fit = (
            "no judgement"
            if found is None
            else (
                f"{100.0 * found.quality.inlier_fraction:.0f}% inliers, residual "
                f"{1000.0 * found.quality.residual_m:.1f} mm"
            )
        )
        self.context.logger.info(
            "frame %d looks like keyframe frame %d (similarity %.2f, %s) but does not fit"
            " the map from there (%s): refused",
            index,
            keyframe,
            similarity,
            matches,
            fit,
        )


def near(a: torch.Tensor, b: torch.Tensor, reach: float = SAME_START_M) -> bool:
    """Whether two poses are within ``reach`` (metres, and radians of turn)."""
    translation, rotation = pose_distance(a, b)
    return bool((translation < reach) & (rotation < reach))


def better(a: Recovered, b: Recovered) -> bool:
    """Whether try ``a`` fits better than ``b``: more inliers (then a smaller residual)."""
    qa, qb = a.quality, b.quality
    return (qa.inlier_fraction, -qa.residual_m) > (qb.inlier_fraction, -qb.residual_m)


def tagged(found: Recovered, how: How, keyframe: int | None) -> Recovered:
    """``found`` with its quality saying how it was recovered (and from which keyframe)."""
    return Recovered(found.pose, replace(found.quality, recovery=how, recovered_from=keyframe))
