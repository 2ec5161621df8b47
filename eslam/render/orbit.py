"""Camera paths for rendered views that no camera took: an orbit around the scene.

Pure numpy; poses are camera-to-world 4x4, OpenCV axes (x right, y down, z forward).
"""

from __future__ import annotations

import numpy as np

MIN_RADIUS_FRACTION = 0.25
"""Radius of the orbit, as a share of the bound's shortest side, when the run's cameras
stood at the centre (their mean horizontal distance from it is below 1 mm)."""


def look_at_opencv(position: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(4, 4) camera-to-world pose at ``position`` looking at ``target``, image up = ``up``.

    z = (target - position) / |.|; y = -(up - (up . z) z) / |.| (OpenCV's y points down
    the image, so away from ``up``); x = y x z (right-handed: x x y = z).

    Raises:
        ValueError: ``target`` equals ``position`` or the view is parallel to ``up``.
    """
    forward = np.asarray(target, dtype=np.float64) - np.asarray(position, dtype=np.float64)
    length = np.linalg.norm(forward)
    if length < 1e-9:
        raise ValueError("the camera cannot look at its own position")
    z = forward / length
    up = np.asarray(up, dtype=np.float64)
    down = -(up - np.dot(up, z) * z)
    if np.linalg.norm(down) < 1e-9:
        raise ValueError("the viewing direction is parallel to the up direction")
    y = down / np.linalg.norm(down)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([np.cross(y, z), y, z], axis=1)
    pose[:3, 3] = position
    return pose


SPREAD_YAW = 0.05
"""Second-smallest eigenvalue of the cameras' mean x x^T above which their x axes span a
plane (the camera turned) and the up direction is that plane's normal."""


def mean_up(poses: np.ndarray) -> np.ndarray:
    """(3,) unit world direction the cameras held as "up", from (N, 4, 4) poses (finite
    ones only).

    A camera without roll keeps its x axis (image right) horizontal, whatever its pitch:
    when the x axes of the cameras span a plane (the camera turned; the second-smallest
    eigenvalue of mean x x^T exceeds :data:`SPREAD_YAW`), up is that plane's normal, the
    eigenvector of the smallest eigenvalue. Otherwise (one heading only) it is the mean
    of the cameras' -y axes (OpenCV's y points down the image), tilted by their pitch.
    Either way the sign agrees with that mean.
    """
    finite = poses[np.isfinite(poses).all(axis=(1, 2))]
    if len(finite) == 0:
        raise ValueError("no finite pose to find the up direction from")
    image_up = -finite[:, :3, 1].mean(axis=0)
    rights = finite[:, :3, 0]
    values, vectors = np.linalg.eigh(rights.T @ rights / len(rights))
    up = vectors[:, 0] if values[1] > SPREAD_YAW else image_up
    norm = np.linalg.norm(up)
    if norm < 1e-6:
        raise ValueError("the cameras' up directions cancel out")
    up = up / norm
    return up if np.dot(up, image_up) >= 0 else -up


def orbit_poses(bound: np.ndarray, poses: np.ndarray, count: int) -> np.ndarray:
    """(count, 4, 4) cameras on a circle around the centre of ``bound``, looking at it.

    The circle lies in the plane perpendicular to the cameras' mean up direction
    (:func:`mean_up` of ``poses``, the run's trajectory), at their mean height above the
    centre along it and their mean horizontal distance from it (where the run's cameras
    were, so the orbit sees what they saw); it starts at the first camera's bearing and
    turns by 2 pi / count per view. Every view looks at the centre.

    Args:
        bound: (3, 2) scene box [[xmin, xmax], ...], metres.
        poses: (N, 4, 4) the run's camera-to-world poses (NaN rows: missing, ignored).
        count: views on the circle.
    """
    if count < 1:
        raise ValueError(f"an orbit needs at least one view, got {count}")
    bound = np.asarray(bound, dtype=np.float64)
    centre = bound.mean(axis=1)
    up = mean_up(poses)
    finite = poses[np.isfinite(poses).all(axis=(1, 2))]
    offsets = finite[:, :3, 3] - centre
    heights = offsets @ up
    horizontal = offsets - heights[:, None] * up
    distances = np.linalg.norm(horizontal, axis=1)
    radius = float(distances.mean())
    if radius < 1e-3:
        radius = MIN_RADIUS_FRACTION * float((bound[:, 1] - bound[:, 0]).min())
    first = horizontal[0]
    if np.linalg.norm(first) < 1e-6:  # any direction perpendicular to up
        first = np.cross(up, np.eye(3)[int(np.argmin(np.abs(up)))])
    e1 = first / np.linalg.norm(first)
    e2 = np.cross(up, e1)
    lift = float(heights.mean()) * up
    angles = 2.0 * np.pi * np.arange(count) / count
    return np.stack(
        [
            look_at_opencv(centre + lift + radius * (np.cos(a) * e1 + np.sin(a) * e2), centre, up)
            for a in angles
        ]
    )
