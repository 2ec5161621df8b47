"""`eslam recon REC GT`: the errors of a reconstructed mesh against a ground-truth mesh.

Accuracy, completion, completion ratio, precision / recall / F1
(:mod:`eslam.evaluate.reconstruction`) and, when asked, the depth L1 over random
virtual views (:mod:`eslam.evaluate.depth_l1`) of two mesh files or run folders
(:func:`eslam.io.mesh_files.find_mesh`). See docs/evaluation.md. The CLI prints the
result; this module computes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from eslam.errors import ConfigError, InputError
from eslam.evaluate.depth_l1 import RELEASE_VIEWS, DepthL1Options, DepthL1Result
from eslam.evaluate.depth_l1 import depth_l1 as measure_depth_l1
from eslam.evaluate.reconstruction import (
    RELEASE_SAMPLES,
    ReconstructionOptions,
    ReconstructionResult,
    evaluate_reconstruction,
)
from eslam.io.mesh_files import find_mesh, read_mesh


@dataclass(frozen=True)
class MeshErrors:
    """The errors of a reconstruction against the ground truth, and what was compared.

    Attributes:
        rec: the reconstructed mesh's file (a run folder's mesh_culled.ply or mesh.ply).
        gt: the ground-truth mesh's file.
        reconstruction: accuracy, completion, ratio, precision / recall / F1.
        depth_l1: the depth L1 (None when not asked for).
    """

    rec: Path
    gt: Path
    reconstruction: ReconstructionResult
    depth_l1: DepthL1Result | None = None

    def as_dict(self) -> dict[str, object]:
        """The metrics under the keys of metrics.json (the depth L1's last, if any)."""
        metrics: dict[str, object] = dict(self.reconstruction.as_dict())
        if self.depth_l1 is not None:
            metrics.update(self.depth_l1.as_dict())
        return metrics


def mesh_errors(
    rec: str | Path,
    gt: str | Path,
    *,
    samples: int = RELEASE_SAMPLES,
    seed: int = 0,
    exact: bool = False,
    depth_l1: bool = False,
    views: int = RELEASE_VIEWS,
    gt_uncut: str | Path | None = None,
) -> MeshErrors:
    """Score the mesh ``rec`` against the mesh ``gt`` (no alignment).

    Args:
        rec: reconstructed mesh file, or a run folder (mesh_culled.ply, else mesh.ply).
        gt: ground-truth mesh file or run folder, in the reconstruction's world frame.
        samples: points sampled per mesh (area-weighted; the ESLAM protocol's 450,000).
        seed: seed of the samples and of the depth L1's views.
        exact: distances to the other mesh's triangles instead of its samples.
        depth_l1: also measure the depth L1 (slower; needs the [eval] extra).
        views: virtual views of the depth L1.
        gt_uncut: the GT mesh before culling: depth L1 views that see culled-away space
            are redrawn.

    Raises:
        InputError: a missing mesh, a run folder without one, an unreadable file or a
            mesh without triangles.
        ConfigError: ``depth_l1`` without the depth L1's ray caster installed.
    """
    rec_path, gt_path = find_mesh(rec), find_mesh(gt)
    reconstruction, ground_truth = read_mesh(rec_path), read_mesh(gt_path)
    options = ReconstructionOptions(samples=samples, seed=seed, exact=exact)
    try:
        scores = evaluate_reconstruction(reconstruction, ground_truth, options)
    except ValueError as error:
        raise InputError(rec_path, str(error), "check both meshes have triangles") from None
    depth = None
    if depth_l1:
        uncut = read_mesh(gt_uncut) if gt_uncut else None
        depth_options = DepthL1Options(views=views, seed=seed)
        try:
            depth = measure_depth_l1(reconstruction, ground_truth, depth_options, uncut)
        except ImportError as error:
            raise ConfigError(f"--depth-l1: {error}") from None
    return MeshErrors(rec_path, gt_path, scores, depth)
