"""Whether a registration between two keyframes can be trusted (``mapping.loops``):
the tests a loop's ICP (:mod:`eslam.slam.loops.icp`) must pass, shared by the loop
candidates and the measured odometry edges (docs/loops.md, steps 2 and 3)."""

from __future__ import annotations

from eslam.config.schema import LoopClosureConfig
from eslam.slam.loops.icp import IcpResult


def refusal(result: IcpResult, config: LoopClosureConfig) -> str | None:
    """Why a registration is not trusted (the first of the loops' tests it fails:
    inliers, residual, a direction unconstrained, colour), or None when it passes."""
    if result.inlier_fraction < config.min_inlier_fraction:
        return (
            f"{result.inlier_fraction:.0%} of the points on the candidate's surface "
            f"(needs {config.min_inlier_fraction:.0%})"
        )
    if result.residual > config.max_residual:
        return (
            f"residual {result.residual * 1000:.1f} mm (at most "
            f"{config.max_residual * 1000:.1f} mm)"
        )
    if result.min_eigenvalue < config.min_eigenvalue:
        return (
            f"a direction is not constrained (eigenvalue {result.min_eigenvalue:.2g} < "
            f"{config.min_eigenvalue:.2g}: a plane or a corridor)"
        )
    if not result.colour_agreement >= config.min_colour_agreement:
        return (
            f"the surfaces fit but {result.colour_agreement:.0%} of their colours agree "
            f"(needs {config.min_colour_agreement:.0%}): another place of the same shape"
        )
    return None
