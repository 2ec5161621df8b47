"""Loop closure after a keyframe's mapping call: find, verify, solve, and let the map follow.

:class:`LoopCloser` (``mapping.loops``, docs/loops.md) runs inside the mapping back end,
after each keyframe is mapped:

1. **Candidates**: earlier keyframes far enough back that may see the same place, by
   pose and by appearance (:mod:`eslam.slam.loops.candidates`).
2. **Verification**: the new keyframe's depth registered to each candidate's by
   projective point-to-plane ICP (:mod:`eslam.slam.loops.icp`) from the candidate's
   guess; accepted only with ``min_inlier_fraction`` of its points on the candidate's
   surface, an RMS residual of at most ``max_residual`` and every direction constrained.
   Every candidate and its decision is recorded (``loops.json``).
3. **Pose graph**: when the best accepted loop disagrees with the estimate by more than
   ``min_correction`` / ``min_correction_deg``, the keyframes' poses are solved with
   odometry edges (each consecutive pair's relative pose as estimated now, or with
   ``odometry: icp`` as ICP measures it) and every loop edge so far (robust),
   keyframe 0 held (:mod:`eslam.slam.loops.pose_graph`);
   every frame moves with the latest keyframe at or before it.
4. **The map follows**: the back end fits the field again at the corrected poses
   (``mapping.loops.map``).
5. **At the end** (``final_passes``, :meth:`LoopCloser.refine`): passes over every
   keyframe with the poses optimised too, once per run.

State lives in the run's ``components["loops"]`` (loop edges by frame index, the record
of every candidate, counts), so it is checkpointed, rolled back with a failed frame and
resumed: a resumed run ends as an uninterrupted one. The places (descriptors, features)
are described again from the keyframe store after a resume. Its random draws use a
generator of its own, seeded by the frame: the run's random stream is the same with
loop closure on as off until a loop is closed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import torch

from eslam.slam.context import RunContext
from eslam.slam.loops.candidates import Candidate, by_appearance, by_pose, far_enough
from eslam.slam.loops.icp import IcpResult, IcpSettings, register
from eslam.slam.loops.pose_graph import (
    Edge,
    anchors,
    carry_poses,
    import_gtsam,
    solve_pose_graph,
)
from eslam.slam.loops.verify import refusal
from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.places.index import PlaceIndex
from eslam.slam.state import SLAMState

REFIT_SHIFT = (0.005, 0.25)
"""A correction that moves a keyframe at least this far (metres) or turns it this much
(degrees) refits the map at it; keyframes that moved less keep what they mapped."""

COMPONENT = "loops"
"""The key of the loop closer's state in ``SLAMState.components``."""


def pose_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(metres, degrees) between two poses: |t| and the angle of a^-1 b."""
    delta = np.linalg.solve(a, b)
    cosine = np.clip((np.trace(delta[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.linalg.norm(delta[:3, 3])), math.degrees(math.acos(cosine))


class LoopCloser:
    """Loop closure for one run (module doc).

    Args:
        context: the run's settings and log.
        refit: fits the map again at the corrected poses of the keyframes (ids) given
            (the back end's).
    """

    def __init__(self, context: RunContext, refit: Callable[[SLAMState, list[int]], None]) -> None:
        import_gtsam()  # a missing extra is named before the first frame
        self.context = context
        self.config = context.config.mapping.loops
        self.refit = refit
        self.icp = IcpSettings()
        self.places: PlaceIndex | None = None

    def own(self, state: SLAMState) -> dict:
        """The loop closer's state in ``state`` (module doc), created on first use."""
        own = state.component(COMPONENT)
        own.setdefault("edges", [])
        own.setdefault("entries", [])
        own.setdefault("corrections", 0)
        return own

    def after_keyframe(self, index: int, current: int, state: SLAMState) -> None:
        """Keyframe ``current`` (frame ``index``) was just mapped: look for a loop."""
        own = self.own(state)
        store = state.keyframes
        started = time.perf_counter()
        positions = store.poses[:, :3, 3].detach().cpu().double().numpy()
        eligible = far_enough(positions, current, self.config)
        if not eligible:
            own["seconds"] = own.get("seconds", 0.0) + time.perf_counter() - started
            return
        if self.places is None or self.places.store is not store:
            self.places = PlaceIndex(store, self.context.config.tracking.features)
        generator = torch.Generator().manual_seed(index)
        candidates = by_pose(store, current, eligible, self.config, generator)
        taken = {c.keyframe for c in candidates}
        unseen = [k for k in eligible if k not in taken]
        alike, unmatched = by_appearance(self.places, current, unseen, self.config, index)
        candidates += alike
        for k, similarity in unmatched:
            own["entries"].append(self._entry(index, store, k, "appearance", None, similarity))
        accepted = []
        for candidate in candidates:
            result = self._verify(store, current, candidate)
            entry = self._entry(
                index, store, candidate.keyframe, candidate.found_by, result, candidate.score
            )
            own["entries"].append(entry)
            if entry["accepted"]:
                accepted.append((result.inlier_fraction, candidate, result, entry))
        if accepted:
            self._close(index, current, state, max(accepted, key=lambda a: a[0]))
        own["seconds"] = own.get("seconds", 0.0) + time.perf_counter() - started

    def refine(self, state: SLAMState, run_passes: Callable[[SLAMState, int], None]) -> None:
        """The global refinement at the end of a run (``final_passes`` > 0): that many
        passes over every keyframe with their poses optimised (``run_passes``, the back
        end's), once per run (a resumed run that already did it does not repeat it),
        timed (metrics.json ``loops_refinement_s``) and logged."""
        passes = self.config.final_passes
        if passes <= 0:  # off: no loop state is made for it
            return
        own = self.own(state)
        if own.get("final"):
            return
        started = time.perf_counter()
        run_passes(state, passes)
        own["final"] = True
        own["refinement_seconds"] = time.perf_counter() - started
        self.context.logger.info(
            "global refinement: %d passes over %d keyframes (poses and map) in %.1f s",
            passes,
            len(state.keyframes),
            own["refinement_seconds"],
        )

    def _verify(self, store: KeyframeStore, current: int, candidate: Candidate) -> IcpResult:
        """ICP of keyframe ``current``'s depth onto the candidate's, from its guess."""
        target = store.poses[candidate.keyframe].detach().cpu().double().numpy()
        return self._register(
            store, current, candidate.keyframe, np.linalg.solve(target, candidate.guess)
        )

    def _register(
        self, store: KeyframeStore, source: int, target: int, initial: np.ndarray
    ) -> IcpResult:
        """ICP of keyframe ``source``'s depth onto keyframe ``target``'s from
        ``initial`` (source camera to target camera), with their colours."""
        greys = tuple(store.rgb(k, "cpu").mean(dim=-1).double().numpy() for k in (source, target))
        return register(
            store.depth(source, "cpu").numpy(),
            store.depth(target, "cpu").numpy(),
            store.intrinsics,
            initial,
            self.icp,
            greys,
        )

    def _entry(
        self,
        index: int,
        store: KeyframeStore,
        k: int,
        found_by: str,
        result: IcpResult | None,
        score: float,
    ) -> dict:
        """One record of loops.json: the pair, how it was found, the registration and
        the decision (why not, when refused)."""
        entry = {
            "frame": index,
            "candidate_frame": store.frame_indices[k],
            "found_by": found_by,
            "score": round(score, 4),
            "relative_pose": None,
            "inlier_fraction": None,
            "residual_m": None,
            "colour_agreement": None,
            "accepted": False,
            "why_not": None,
        }
        if result is None:
            entry["why_not"] = "too few feature matches for a first relative pose"
            return entry
        entry["relative_pose"] = np.round(result.pose, 6).tolist()
        entry["inlier_fraction"] = round(result.inlier_fraction, 4)
        entry["residual_m"] = round(result.residual, 6) if math.isfinite(result.residual) else None
        entry["colour_agreement"] = round(result.colour_agreement, 4)
        entry["why_not"] = refusal(result, self.config)
        entry["accepted"] = entry["why_not"] is None
        return entry

    def _close(
        self,
        index: int,
        current: int,
        state: SLAMState,
        best: tuple[float, Candidate, IcpResult, dict],
    ) -> None:
        """Add the best accepted loop's edge (``best``: inlier share, candidate, its
        registration, its loops.json entry); solve and refit when it corrects enough."""
        _, candidate, result, entry = best
        own = self.own(state)
        store = state.keyframes
        frames = store.frame_indices
        own["edges"].append([frames[candidate.keyframe], index, *np.ravel(result.pose).tolist()])
        poses = store.poses.detach().cpu().double().numpy()
        estimated = np.linalg.solve(poses[candidate.keyframe], poses[current])
        metres, degrees = pose_difference(estimated, result.pose)
        entry["correction_cm"] = round(100 * metres, 3)
        entry["correction_deg"] = round(degrees, 4)
        if metres < self.config.min_correction and degrees < self.config.min_correction_deg:
            entry["closed"] = False
            return
        last = own.get("last_closed")
        if last is not None and current - last < self.config.min_keyframes_between:
            entry["closed"] = False
            entry["why_not_closed"] = f"closed {current - last} keyframes ago"
            return
        own["last_closed"] = current
        started = time.perf_counter()
        anchor = anchor_sigmas(self.config.anchor_sigma, metres, degrees)
        solved, moved = self._solve(state, own, anchor)
        shift, turn = pose_difference(poses[current], solved[current])
        entry["keyframes_refit"] = len(moved)
        own["corrections"] += 1
        entry["closed"] = True
        self.context.logger.info(
            "loop closed: frame %d with frame %d (%.0f %% inliers, %.1f mm residual): the "
            "estimate was %.1f cm / %.2f deg off; frame %d moved %.1f cm / %.2f deg; pose "
            "graph and map %s %.1f s",
            index,
            frames[candidate.keyframe],
            100 * result.inlier_fraction,
            1000 * result.residual,
            100 * metres,
            degrees,
            index,
            100 * shift,
            turn,
            self.config.map,
            time.perf_counter() - started,
        )

    def _solve(
        self, state: SLAMState, own: dict, anchor: tuple[float, float] | None
    ) -> tuple[np.ndarray, list[int]]:
        """Solve the pose graph over the keyframes (priors of sigmas ``anchor``), move
        every frame with its keyframe and let the map follow; the solved keyframe poses
        and the keyframes the map was refitted at."""
        store = state.keyframes
        poses = store.poses.detach().cpu().double().numpy()
        solution = solve_pose_graph(poses, self._edges(poses, store, own), anchor=anchor)
        trajectory = state.trajectory
        count = state.next_frame
        before = trajectory.poses[:count].detach().cpu().double().numpy()
        carried = carry_poses(before, anchors(store.frame_indices, count), poses, solution.poses)
        trajectory.set_poses(list(range(count)), torch.from_numpy(carried))
        moved = [
            k
            for k in range(len(poses))
            if max(*np.divide(pose_difference(poses[k], solution.poses[k]), REFIT_SHIFT)) >= 1
        ]
        self.refit(state, moved)
        return solution.poses, moved

    def _edges(self, poses: np.ndarray, store: KeyframeStore, own: dict) -> list[Edge]:
        """Odometry edges between consecutive keyframes (``mapping.loops.odometry``: as
        estimated now, or measured by ICP) and the loop edges whose keyframes are in
        the store."""
        frames = store.frame_indices
        measured = self._odometry(poses, store, own)
        rotation, translation = self.config.odometry_sigma
        edges = [
            Edge(
                k,
                k + 1,
                measured.get((frames[k], frames[k + 1]), np.linalg.solve(poses[k], poses[k + 1])),
                rotation,
                translation,
            )
            for k in range(len(poses) - 1)
        ]
        loops = own["edges"]
        rotation, translation = self.config.loop_sigma
        node = {frame: k for k, frame in enumerate(frames)}
        for a, b, *relative in loops:
            if a in node and b in node:
                edges.append(
                    Edge(
                        node[a],
                        node[b],
                        np.reshape(relative, (4, 4)),
                        rotation,
                        translation,
                        robust=True,
                        robust_k=self.config.robust_k,
                    )
                )
        return edges

    def _odometry(
        self, poses: np.ndarray, store: KeyframeStore, own: dict
    ) -> dict[tuple[int, int], np.ndarray]:
        """With ``odometry: icp``, the relative pose of each pair of consecutive
        keyframes (by frame index) measured by ICP of the later one's depth onto the
        earlier one's, from the estimate: measured once (kept in the loop state) and
        used where it passes the loops' tests; {} otherwise."""
        if self.config.odometry != "icp":
            return {}
        frames = store.frame_indices
        record = own.setdefault("odometry", {})
        measured = {}
        for k in range(len(frames) - 1):
            key = f"{frames[k]}-{frames[k + 1]}"
            if key not in record:
                result = self._register(store, k + 1, k, np.linalg.solve(poses[k], poses[k + 1]))
                passed = refusal(result, self.config) is None
                record[key] = np.ravel(result.pose).tolist() if passed else None
            if record[key] is not None:
                measured[frames[k], frames[k + 1]] = np.reshape(record[key], (4, 4))
        return measured


def anchor_sigmas(
    anchor: tuple[float, float] | None, metres: float, degrees: float
) -> tuple[float, float] | None:
    """The anchors' sigmas (rad, m) for a loop that finds the estimate ``metres`` and
    ``degrees`` off: ``anchor`` (``mapping.loops.anchor_sigma``), widened to twice the
    correction. A keyframe's tracked pose is trusted to within twice what the loop shows
    the tracker can be off: a correction within the anchors stays near the loop (the
    tracker's error did not add up along the chain), a larger one (drift that did add
    up) bends the chain nearly as a graph without anchors would, instead of being
    outvoted by every anchor and refused by the loop edge's robust kernel."""
    if anchor is None:
        return None
    return max(anchor[0], 2 * math.radians(degrees)), max(anchor[1], 2 * metres)


def loop_metrics(state: SLAMState) -> dict:
    """metrics.json's loop figures: candidates accepted and refused, loops closed, and
    the seconds loop closure took (search, verification, graph and map refits); with
    ``odometry: icp`` the odometry edges measured and those refused (the estimate's
    used); those of the global refinement at the end when it ran."""
    own = state.components.get(COMPONENT)
    if own is None:
        return {}
    entries = own.get("entries", [])
    accepted = sum(1 for e in entries if e["accepted"])
    odometry = list(own.get("odometry", {}).values())
    return {
        "loops_accepted": accepted,
        "loops_rejected": len(entries) - accepted,
        "loops_closed": int(own.get("corrections", 0)),
        "loops_time_s": float(own.get("seconds", 0.0)),
        **(
            {
                "loops_odometry_measured": sum(1 for o in odometry if o is not None),
                "loops_odometry_refused": sum(1 for o in odometry if o is None),
            }
            if odometry
            else {}
        ),
        **(
            {"loops_refinement_s": float(own["refinement_seconds"])}
            if "refinement_seconds" in own
            else {}
        ),
    }
