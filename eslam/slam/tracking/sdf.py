"""The SDF tracker (``tracking.method: sdf``): Levenberg-Marquardt on the map's signed
distance, on the systems of :mod:`eslam.slam.tracking.sdf_system` (the formulas).

Each frame gets a quality figure: the inlier fraction (points inside the band with
|r| at most the robust scale c) and the robust RMS residual of the inliers. A frame with
too few inliers or too large a residual is reported as failed (the loop keeps the
motion model's pose and makes it no keyframe). A view that fits the map but pins the
pose down in fewer than six directions (one wall and the floor: sliding along both fits
as well) fits as well as a good one, so the quality also holds the smallest eigenvalue
of the normalised information and the number of directions below ``degeneracy``
(:func:`~eslam.slam.tracking.sdf_system.constrained_directions`): such a frame is
counted and logged as degenerate, not failed (its pose is measured along the other
directions).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from eslam.config import SdfTrackerConfig
from eslam.geometry.pose import pose_distance, se3_exp
from eslam.render.renderer import SceneFieldLike
from eslam.slam.tracking.base import TrackingQuality, TrackingResult
from eslam.slam.tracking.render import frozen
from eslam.slam.tracking.sdf_system import (
    Linearisation,
    constrained_directions,
    damped_step,
    information_figures,
    linearise,
)
from eslam.slam.views import View, pixels_from_uniforms

MIN_POINTS = 6
"""Points inside the band needed for a step (a pose has 6 degrees of freedom)."""

MAX_STEP = 0.5
"""A step longer than this (metres, or radians of turn) is rejected as implausible for
one frame's correction (a near-singular system), like a step that raises the cost."""


def plausible(step: torch.Tensor) -> torch.Tensor:
    """0-d bool: whether a (6,) step is finite and within :data:`MAX_STEP`."""
    return (
        torch.isfinite(step).all() & (step[:3].norm() <= MAX_STEP) & (step[3:].norm() <= MAX_STEP)
    )


MAX_CORRECTION = 0.5
"""A frame's pose may move at most this far from the motion model's guess (metres, and
radians of turn); farther counts as failed: the solver ran off, whatever it fits."""


def within_reach(initial: torch.Tensor, pose: torch.Tensor) -> bool:
    """Whether ``pose`` is finite and within :data:`MAX_CORRECTION` of ``initial``."""
    if not bool(torch.isfinite(pose).all()):
        return False
    translation, rotation = pose_distance(initial.to(pose), pose)
    return bool((translation <= MAX_CORRECTION) & (rotation <= MAX_CORRECTION))


def sdf_points(
    view: View, count: int, generator: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """A seeded subset of ``count`` sampleable pixels of ``view`` (with replacement),
    back-projected: (count, 3) camera points q = d * D and their pixel indices."""
    uniforms = torch.rand(count, generator=generator, device=view.depth.device)
    pixels = pixels_from_uniforms(view, uniforms)
    return view.directions[pixels] * view.depth[pixels, None], pixels


def quality(system: Linearisation, config: SdfTrackerConfig) -> tuple[float, float]:
    """(inlier fraction, robust RMS residual of the inliers in metres) at a linearisation."""
    inliers = system.valid & (system.residual.abs() <= config.robust_scale)
    count = int(inliers.sum())
    fraction = count / max(len(system.residual), 1)
    if count == 0:
        return fraction, float("inf")
    rms = float(system.residual[inliers].square().mean().sqrt())
    return fraction, rms


@dataclass(frozen=True, eq=False)
class Solver:
    """The Levenberg-Marquardt iterate of one level, all on the device.

    Attributes:
        pose: (4, 4) the current pose.
        system: the linearisation at ``pose``.
        damping: 0-d float64 lambda.
        running: 0-d bool, false once the level converged or had too few points.
        iterations: 0-d int64 iterations taken (a step tried while running).
    """

    pose: torch.Tensor
    system: Linearisation
    damping: torch.Tensor
    running: torch.Tensor
    iterations: torch.Tensor


def choose(flag: torch.Tensor, a: Linearisation, b: Linearisation) -> Linearisation:
    """``a`` where the 0-d bool ``flag`` holds, else ``b``, field by field (no host read)."""
    return Linearisation(
        *(
            torch.where(flag, getattr(a, name), getattr(b, name))
            for name in ("residual", "weight", "cost", "hessian", "gradient", "valid", "centre")
        )
    )


def lm_step(
    field: SceneFieldLike,
    points: torch.Tensor,
    colours: torch.Tensor | None,
    settings: SdfTrackerConfig,
    solver: Solver,
) -> Solver:
    """One Levenberg-Marquardt iteration (module doc) with no host read: a step is
    tried while the level runs and has at least :data:`MIN_POINTS` points in the band;
    it is accepted (lambda halves) when it is plausible and does not raise the cost, else
    rejected (lambda times 4); a small accepted step ends the level. A solver that no
    longer runs comes back unchanged, so a fixed number of calls gives the result of
    stopping at convergence."""
    system, pose = solver.system, solver.pose
    active = solver.running & (system.valid.sum() >= MIN_POINTS)
    projector, _ = constrained_directions(system, settings.degeneracy)
    step = projector @ damped_step(system, solver.damping)
    tried = active & plausible(step)
    safe = torch.where(tried, step, torch.zeros_like(step))
    candidate = se3_exp(safe.to(pose.dtype)) @ pose
    trial = linearise(field, points, candidate, settings, colours)
    better = tried & (trial.cost <= system.cost)
    small = (step[:3].norm() < settings.converged_translation) & (
        step[3:].norm() < settings.converged_rotation
    )
    damping = torch.where(
        better, solver.damping * 0.5, torch.where(active, solver.damping * 4.0, solver.damping)
    )
    return Solver(
        pose=torch.where(better, candidate, pose),
        system=choose(better, trial, system),
        damping=damping,
        running=active & ~(small & better),
        iterations=solver.iterations + active.long(),
    )


def track_sdf(
    field: SceneFieldLike,
    view: View,
    initial_pose: torch.Tensor,
    config: SdfTrackerConfig,
    generator: torch.Generator,
    poll: bool | None = None,
) -> TrackingResult:
    """Pose of ``view`` by Levenberg-Marquardt on SDF residuals (module doc).

    Each level takes ``config.iterations`` calls of :func:`lm_step` (no host read). With
    ``poll`` (default: on a CPU, where reading a value costs nothing) a level stops as
    soon as it no longer runs: the same result, since the remaining calls would change
    nothing. The quality and the information are read once, at the end.
    """
    points_cam, pixels = sdf_points(view, max(config.levels), generator)
    colours = view.rgb[pixels] if config.colour_weight > 0 else None
    pose = initial_pose.detach().clone()
    iterations = torch.zeros((), dtype=torch.int64, device=pose.device)
    system = None
    if poll is None:
        poll = pose.device.type == "cpu"
    # colour_when: degenerate starts geometric and adds colour if the first linearisation
    # (at the guess, coarsest level) leaves a direction below the degeneracy threshold
    settings = config
    if colours is not None and config.colour_when == "degenerate":
        settings = replace(config, colour_weight=0.0)
    for level, count in enumerate(config.levels):
        level_points = points_cam[:count]
        level_colours = colours[:count] if colours is not None else None
        system = linearise(field, level_points, pose, settings, level_colours)
        if level == 0 and settings is not config:
            if information_figures(system, config.degeneracy)[1]:
                settings = config
                system = linearise(field, level_points, pose, settings, level_colours)
        solver = Solver(
            pose=pose,
            system=system,
            damping=torch.tensor(config.damping, dtype=torch.float64, device=pose.device),
            running=torch.ones((), dtype=torch.bool, device=pose.device),
            iterations=iterations,
        )
        for _ in range(config.iterations):
            solver = lm_step(field, level_points, level_colours, settings, solver)
            if poll and not bool(solver.running):
                break
        pose, system, iterations = solver.pose, solver.system, solver.iterations
    assert system is not None
    inlier_fraction, residual = quality(system, config)
    information, degenerate = information_figures(system, config.degeneracy)
    failed = (
        inlier_fraction < config.min_inlier_fraction
        or residual > config.max_residual
        or not within_reach(initial_pose, pose)
    )
    return TrackingResult(
        pose=pose,
        loss=system.cost.detach(),
        quality=TrackingQuality(
            iterations=int(iterations),
            inlier_fraction=inlier_fraction,
            residual_m=residual,
            failed=failed,
            information=information,
            degenerate_directions=degenerate,
        ),
    )


@dataclass(frozen=True)
class SdfTracker:
    """The SDF tracker behind the :class:`~eslam.slam.tracking.base.Tracker` protocol."""

    config: SdfTrackerConfig

    def track(
        self,
        field: SceneFieldLike,
        view: View,
        initial_pose: torch.Tensor,
        generator: torch.Generator,
    ) -> TrackingResult:
        """Pose of ``view`` from ``initial_pose`` by :func:`track_sdf` (field frozen)."""
        with frozen(field):  # type: ignore[arg-type]
            return track_sdf(field, view, initial_pose, self.config, generator)
