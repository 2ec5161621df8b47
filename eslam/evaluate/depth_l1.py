"""Depth L1: depth of two meshes rendered from random virtual views inside the scene.

Virtual cameras follow the ESLAM release (``src/tools/eval_recon.py``, ``calc_2d_metric``
and ``get_cam_position``, itself from NICE-SLAM):

- position: uniform in a box built from the oriented bounding box of the GT mesh
  (``trimesh.bounds.oriented_bounds``, extents sorted smallest first) with its extents
  scaled by (0.3, 0.7, 0.7) and its centre raised by 0.4 along world z;
- orientation: looking at a target uniform in [-10^4, 10^4]^3 (the release rounds it to
  0.01; we do not), with "up" = -z: z_cam = normalise(target - origin),
  x_cam = normalise(up x z_cam), y_cam = z_cam x x_cam (OpenCV axes, as Open3D's
  pinhole camera);
- 1000 views of 500 x 500 pixels, focal 300, principal point (249.5, 249.5).

Where we differ from the release, and why:

- The score of a view is the mean |d_gt - d_rec| over pixels where BOTH meshes have
  depth (the release averages over all pixels, a miss counting as depth 0, so one hole
  costs metres). ``count_missing=True`` gives the release's rule. The result is the mean
  of the per-view scores, as in the release, in centimetres.
- Unobserved space: the release rejects (and redraws) a view when any point of the GT
  mesh that no frame saw projects into it (occluded or not). Here, given the uncut GT
  mesh, a pixel sees unobserved space when the uncut GT has a surface along its ray and
  the (culled) GT mesh has none, or has it farther than ``unobserved_tolerance_m``
  behind: the first surface along the ray was culled away. A view with more than
  ``max_unobserved_pixels`` such pixels is redrawn. Unlike the release this respects
  occlusion (culled surface hidden behind kept surface does not count). Without an uncut
  GT mesh no view is rejected for this.
- A view where no pixel has depth in both meshes is redrawn too (it has no score).
- Redrawing stops after ``max_draws`` cameras in total; the result says how many views
  were used and how many were rejected.
- Randomness comes from one seeded numpy generator (the release uses global RNGs).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from eslam.evaluate.raycast import MeshRaycaster, pixel_rays
from eslam.types import Intrinsics, TriangleMesh

RELEASE_VIEWS = 1000
"""Virtual views (ESLAM release, eval_recon.py ``calc_2d_metric(n_imgs=1000)``)."""
RELEASE_IMAGE_SIZE = 500
"""Image width and height, pixels (release ``calc_2d_metric``: H = W = 500)."""
RELEASE_FOCAL = 300.0
"""Focal length, pixels (release ``calc_2d_metric``: focal = 300)."""
RELEASE_BOX_SCALE = (0.3, 0.7, 0.7)
"""Scale of the sorted oriented-bounding-box extents (release ``get_cam_position``)."""
RELEASE_BOX_LIFT_M = 0.4
"""World-z shift of the camera box, metres (release ``get_cam_position``)."""
RELEASE_TARGET_RANGE = 10_000.0
"""Look-at targets are uniform in [-range, range]^3 (release ``calc_2d_metric``)."""
RELEASE_UP = (0.0, 0.0, -1.0)
"""The "up" vector of the virtual cameras' look-at (release ``calc_2d_metric``)."""


@dataclass(frozen=True)
class DepthL1Options:
    """Virtual cameras and rules of the depth L1 metric (see the module docstring).

    Attributes:
        views: views that must be scored.
        width: image width, pixels.
        height: image height, pixels.
        focal: focal length (fx = fy), pixels.
        seed: seed of the generator all cameras come from.
        count_missing: average over all pixels with a miss as depth 0 (the release's
            rule) instead of over pixels where both meshes have depth.
        unobserved_tolerance_m: how far behind the uncut GT surface the culled GT may
            be before a pixel counts as seeing unobserved space, metres.
        max_unobserved_pixels: a view with more such pixels is redrawn (the release:
            none); the pixels of a kept view that see unobserved space are not scored.
        max_draws: cameras drawn at most, in total (default 20 per view).
    """

    views: int = RELEASE_VIEWS
    width: int = RELEASE_IMAGE_SIZE
    height: int = RELEASE_IMAGE_SIZE
    focal: float = RELEASE_FOCAL
    seed: int = 0
    count_missing: bool = False
    unobserved_tolerance_m: float = 1e-3
    max_unobserved_pixels: int = 0
    max_draws: int | None = None

    def __post_init__(self) -> None:
        if self.views < 1 or self.width < 1 or self.height < 1 or not self.focal > 0:
            raise ValueError("views, image size and focal length must be positive")

    def intrinsics(self) -> Intrinsics:
        """The virtual camera: principal point at the image centre (release: W/2 - 0.5)."""
        return Intrinsics(
            width=self.width,
            height=self.height,
            fx=self.focal,
            fy=self.focal,
            cx=self.width / 2.0 - 0.5,
            cy=self.height / 2.0 - 0.5,
        )


@dataclass(frozen=True)
class DepthL1Result:
    """Depth L1 and how many views it took.

    Attributes:
        depth_l1_cm: mean over used views of the per-view mean absolute depth
            difference, centimetres (nan when no view was used).
        views_used: views scored.
        views_rejected: cameras drawn and rejected (unobserved space or no common depth).
    """

    depth_l1_cm: float
    views_used: int
    views_rejected: int

    def as_dict(self) -> dict[str, float | int]:
        """The result under its field names (``depth_l1_cm`` is the metrics.json key)."""
        return {
            "depth_l1_cm": self.depth_l1_cm,
            "views_used": self.views_used,
            "views_rejected": self.views_rejected,
        }


@dataclass(frozen=True)
class CameraBox:
    """The region virtual cameras are drawn from: a box ``transform @ [-e/2, e/2]``.

    Attributes:
        extents: (3,) box side lengths, metres.
        transform: (4, 4) box frame to world.
    """

    extents: np.ndarray
    transform: np.ndarray


def camera_box(ground_truth: TriangleMesh) -> CameraBox:
    """The release's camera region (``get_cam_position``) for a GT mesh."""
    import trimesh

    mesh = trimesh.Trimesh(ground_truth.vertices, ground_truth.faces, process=False)
    to_origin, extents = trimesh.bounds.oriented_bounds(mesh)
    transform = np.linalg.inv(to_origin)
    transform[2, 3] += RELEASE_BOX_LIFT_M
    return CameraBox(extents=np.asarray(extents) * np.array(RELEASE_BOX_SCALE), transform=transform)


def look_at(origin: np.ndarray, direction: np.ndarray, up: np.ndarray) -> np.ndarray | None:
    """Camera-to-world pose at ``origin`` looking along ``direction`` (release ``viewmatrix``).

    Args:
        origin: (3,) camera centre, metres.
        direction: (3,) viewing direction (any length).
        up: (3,) the "up" vector of the look-at (the image's -y side is not forced to it).

    Returns:
        (4, 4) pose in OpenCV axes, or None when ``direction`` is parallel to ``up``.
    """
    z = direction / np.linalg.norm(direction)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-9:
        return None
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([x, y, z], axis=1)
    pose[:3, 3] = origin
    return pose


def draw_camera(box: CameraBox, rng: np.random.Generator) -> np.ndarray:
    """One random virtual camera (camera-to-world, OpenCV axes), as the release draws it."""
    while True:
        local = (rng.random(3) - 0.5) * box.extents
        origin = box.transform[:3, :3] @ local + box.transform[:3, 3]
        target = rng.uniform(-RELEASE_TARGET_RANGE, RELEASE_TARGET_RANGE, size=3)
        pose = look_at(origin, target - origin, np.array(RELEASE_UP))
        if pose is not None:
            return pose


def view_error(
    gt_depth: np.ndarray,
    rec_depth: np.ndarray,
    count_missing: bool,
    scored: np.ndarray | None = None,
) -> float | None:
    """Mean absolute depth difference of one view, metres (None: no pixel to score).

    Args:
        gt_depth, rec_depth: (H, W) depth, 0 where no surface.
        count_missing: average over all pixels, a miss counting as depth 0.
        scored: (H, W) bool, the pixels that may be scored (None = all): pixels that
            see unobserved space are left out.
    """
    if scored is not None:
        gt_depth, rec_depth = gt_depth[scored], rec_depth[scored]
        if gt_depth.size == 0:
            return None
    if count_missing:
        return float(np.abs(gt_depth - rec_depth).mean())
    both = (gt_depth > 0) & (rec_depth > 0)
    if not both.any():
        return None
    return float(np.abs(gt_depth[both] - rec_depth[both]).mean())


def unobserved_pixels(
    gt_depth: np.ndarray, full_depth: np.ndarray, tolerance_m: float
) -> np.ndarray:
    """(H, W) bool: pixels whose first surface in the uncut GT was culled away from the GT.

    Args:
        gt_depth: (H, W) depth of the culled GT mesh, 0 where no surface.
        full_depth: (H, W) depth of the uncut GT mesh, 0 where no surface.
        tolerance_m: allowed excess of ``gt_depth`` over ``full_depth``, metres.
    """
    seen_full = full_depth > 0
    culled = (gt_depth <= 0) | (gt_depth > full_depth + tolerance_m)
    return seen_full & culled


def depth_l1(
    reconstruction: TriangleMesh,
    ground_truth: TriangleMesh,
    options: DepthL1Options | None = None,
    ground_truth_uncut: TriangleMesh | None = None,
    on_view: Callable[[int], None] | None = None,
) -> DepthL1Result:
    """Depth L1 between two meshes over random virtual views (module docstring).

    Args:
        reconstruction: the mesh to score, metres, GT world frame.
        ground_truth: the reference mesh (culled, for the paper protocol); it also
            sets the camera region.
        options: defaults to the release's settings (1000 views, 500 x 500, focal 300).
        ground_truth_uncut: the GT before culling, to reject views of unobserved space.
        on_view: called with the number of views scored so far after each one
            (progress: a thousand views take minutes).

    Returns:
        The depth L1 in cm with the number of views used and rejected.
    """
    options = options or DepthL1Options()
    intrinsics = options.intrinsics()
    rays = pixel_rays(intrinsics)
    rng = np.random.default_rng(options.seed)
    box = camera_box(ground_truth)
    gt_caster = MeshRaycaster(ground_truth.vertices, ground_truth.faces)
    rec_caster = MeshRaycaster(reconstruction.vertices, reconstruction.faces)
    full_caster = None
    if ground_truth_uncut is not None:
        full_caster = MeshRaycaster(ground_truth_uncut.vertices, ground_truth_uncut.faces)
    max_draws = options.max_draws if options.max_draws is not None else 20 * options.views
    errors: list[float] = []
    rejected = 0
    while len(errors) < options.views and len(errors) + rejected < max_draws:
        pose = draw_camera(box, rng)
        gt_depth = gt_caster.depth(pose, intrinsics, rays)
        scored = None
        if full_caster is not None:
            full_depth = full_caster.depth(pose, intrinsics, rays)
            unobserved = unobserved_pixels(gt_depth, full_depth, options.unobserved_tolerance_m)
            if np.count_nonzero(unobserved) > options.max_unobserved_pixels:
                rejected += 1
                continue
            scored = ~unobserved
        error = view_error(
            gt_depth, rec_caster.depth(pose, intrinsics, rays), options.count_missing, scored
        )
        if error is None:
            rejected += 1
            continue
        errors.append(error)
        if on_view is not None:
            on_view(len(errors))
    mean = 100.0 * float(np.mean(errors)) if errors else float("nan")
    return DepthL1Result(depth_l1_cm=mean, views_used=len(errors), views_rejected=rejected)
