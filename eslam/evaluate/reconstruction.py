"""Mesh reconstruction metrics: accuracy, completion, completion ratio, precision/recall/F1.

The ESLAM protocol (docs/method.md section 6; release ``src/tools/eval_recon.py``,
``calc_3d_metric``): sample 450,000 points on each mesh, area-weighted; accuracy is the
mean distance from reconstruction samples to their nearest GT sample, completion the
mean distance from GT samples to their nearest reconstruction sample, and the completion
ratio the percentage of GT samples closer than 5 cm. The nearest-sample distance has a
floor set by the sample spacing, so the sample count is always reported with the numbers.

The exact mode keeps the samples but measures each one's distance to the OTHER mesh's
surface (closest point on its triangles, :mod:`eslam.evaluate.surface_distance`): no
sampling floor, and a mesh against itself scores exactly 0 cm / 0 cm / 100 %.

Precision / recall / F1 at 1 cm follow the protocol Gaussian-splatting SLAM papers
use: precision = % of reconstruction samples within 1 cm of the GT, recall = % of GT
samples within 1 cm of the reconstruction, F1 their harmonic mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from eslam.evaluate.sampling import sample_surface
from eslam.evaluate.surface_distance import build_surface_index, distance_to_surface
from eslam.types import TriangleMesh

RELEASE_SAMPLES = 450_000
"""Points sampled per mesh (ESLAM release, eval_recon.py ``calc_3d_metric(num_points=450000)``)."""
COMPLETION_THRESHOLD_M = 0.05
"""Completion ratio threshold, 5 cm (ESLAM release, eval_recon.py ``completion_ratio``)."""
F_SCORE_THRESHOLD_M = 0.01
"""Precision / recall / F1 threshold, 1 cm (the Gaussian-splatting SLAM papers' protocol)."""


@dataclass(frozen=True)
class ReconstructionOptions:
    """How to score a reconstructed mesh against a ground-truth mesh.

    Attributes:
        samples: points sampled on each mesh (the numbers depend on it).
        seed: seed of the one generator all samples come from (reconstruction first).
        exact: measure sample-to-surface distances instead of sample-to-sample.
        completion_threshold_m: completion ratio threshold, metres.
        f_score_threshold_m: precision / recall threshold, metres.
    """

    samples: int = RELEASE_SAMPLES
    seed: int = 0
    exact: bool = False
    completion_threshold_m: float = COMPLETION_THRESHOLD_M
    f_score_threshold_m: float = F_SCORE_THRESHOLD_M

    def __post_init__(self) -> None:
        if self.samples < 1:
            raise ValueError(f"samples must be positive, got {self.samples}")
        if not (self.completion_threshold_m > 0 and self.f_score_threshold_m > 0):
            raise ValueError("thresholds must be positive")


@dataclass(frozen=True)
class ReconstructionResult:
    """Reconstruction metrics (centimetres and percent) and how they were measured.

    Attributes:
        accuracy_cm: mean distance, reconstruction samples to the GT.
        completion_cm: mean distance, GT samples to the reconstruction.
        completion_ratio_pct: % of GT samples within the completion threshold (5 cm).
        precision_pct: % of reconstruction samples within the F-score threshold (1 cm).
        recall_pct: % of GT samples within the F-score threshold.
        f1_pct: harmonic mean of precision and recall (0 when both are 0).
        samples: points sampled per mesh.
        exact: True when distances are to the other surface, not its samples.
    """

    accuracy_cm: float
    completion_cm: float
    completion_ratio_pct: float
    precision_pct: float
    recall_pct: float
    f1_pct: float
    samples: int
    exact: bool

    def as_dict(self) -> dict[str, float | int | bool]:
        """The metrics under the keys of metrics.json (README.md lists them)."""
        return {
            "accuracy_cm": self.accuracy_cm,
            "completion_cm": self.completion_cm,
            "completion_ratio_pct": self.completion_ratio_pct,
            "precision_pct": self.precision_pct,
            "recall_pct": self.recall_pct,
            "f1_pct": self.f1_pct,
            "samples": self.samples,
            "exact": self.exact,
        }


@dataclass(frozen=True, eq=False)
class SampleDistances:
    """Distances of each mesh's samples to the other mesh, metres.

    Attributes:
        reconstruction_to_gt: (N,) float64, one per reconstruction sample.
        gt_to_reconstruction: (N,) float64, one per GT sample.
    """

    reconstruction_to_gt: np.ndarray
    gt_to_reconstruction: np.ndarray


def _check_mesh(mesh: TriangleMesh, name: str) -> None:
    if len(mesh.faces) == 0:
        raise ValueError(f"the {name} mesh has no triangles")


def sample_distances(
    reconstruction: TriangleMesh, ground_truth: TriangleMesh, options: ReconstructionOptions
) -> SampleDistances:
    """Sample both meshes and measure each sample's distance to the other mesh.

    Args:
        reconstruction: the mesh to score (metres, same world frame as the GT).
        ground_truth: the reference mesh.
        options: sample count, seed and mode.

    Returns:
        Both distance arrays.

    Raises:
        ValueError: a mesh without triangles or without area.
    """
    _check_mesh(reconstruction, "reconstructed")
    _check_mesh(ground_truth, "ground-truth")
    rng = np.random.default_rng(options.seed)
    rec_points = sample_surface(reconstruction.vertices, reconstruction.faces, options.samples, rng)
    gt_points = sample_surface(ground_truth.vertices, ground_truth.faces, options.samples, rng)
    if options.exact:
        gt_surface = build_surface_index(ground_truth.vertices, ground_truth.faces)
        rec_surface = build_surface_index(reconstruction.vertices, reconstruction.faces)
        to_gt = distance_to_surface(gt_surface, rec_points)
        to_rec = distance_to_surface(rec_surface, gt_points)
    else:
        to_gt, _ = cKDTree(gt_points).query(rec_points, k=1, workers=-1)
        to_rec, _ = cKDTree(rec_points).query(gt_points, k=1, workers=-1)
    return SampleDistances(reconstruction_to_gt=to_gt, gt_to_reconstruction=to_rec)


def metrics_from_distances(
    distances: SampleDistances, options: ReconstructionOptions
) -> ReconstructionResult:
    """The metrics of :class:`ReconstructionResult` from sample distances (pure)."""
    to_gt, to_rec = distances.reconstruction_to_gt, distances.gt_to_reconstruction
    precision = 100.0 * float(np.mean(to_gt < options.f_score_threshold_m))
    recall = 100.0 * float(np.mean(to_rec < options.f_score_threshold_m))
    f1 = 2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return ReconstructionResult(
        accuracy_cm=100.0 * float(np.mean(to_gt)),
        completion_cm=100.0 * float(np.mean(to_rec)),
        completion_ratio_pct=100.0 * float(np.mean(to_rec < options.completion_threshold_m)),
        precision_pct=precision,
        recall_pct=recall,
        f1_pct=f1,
        samples=options.samples,
        exact=options.exact,
    )


def evaluate_reconstruction(
    reconstruction: TriangleMesh,
    ground_truth: TriangleMesh,
    options: ReconstructionOptions | None = None,
) -> ReconstructionResult:
    """Accuracy, completion, completion ratio, precision, recall and F1 of a mesh.

    Args:
        reconstruction: the mesh to score, metres, in the GT's world frame (no
            alignment is done; the ESLAM release's optional ICP is left out).
        ground_truth: the reference mesh (culled the same way, for the paper protocol).
        options: defaults to the ESLAM protocol (450,000 samples, seed 0, sampled mode).

    Returns:
        The metrics in cm and %, with the sample count and mode.
    """
    options = options or ReconstructionOptions()
    return metrics_from_distances(sample_distances(reconstruction, ground_truth, options), options)
