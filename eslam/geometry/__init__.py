"""Geometry: SE(3)/SO(3) pose maths, pinhole camera maths, camera axis conventions.

Poses are camera-to-world 4x4 matrices in OpenCV camera axes (x right, y down,
z forward), metres, radians; quaternions are scalar-last (x, y, z, w).
"""

from eslam.geometry.camera import (
    backproject_depth,
    camera_to_world_rays,
    pixel_grid,
    pixels_to_camera_directions,
    project_points,
)
from eslam.geometry.conventions import (
    OPENGL_FROM_OPENCV,
    opencv_to_opengl_pose,
    opengl_to_opencv_pose,
)
from eslam.geometry.pose import (
    compose,
    extrapolate_constant_velocity,
    interpolate_pose,
    invert,
    pose_distance,
    pose_from_quaternion_translation,
    quaternion_translation_from_pose,
    se3_exp,
    se3_log,
)
from eslam.geometry.rotation import (
    matrix_to_quaternion,
    orthonormalize_rotation,
    quaternion_to_matrix,
    renormalise_rotation,
    rotation_angle,
    so3_exp,
    so3_log,
)

__all__ = [
    "OPENGL_FROM_OPENCV",
    "backproject_depth",
    "camera_to_world_rays",
    "compose",
    "extrapolate_constant_velocity",
    "interpolate_pose",
    "invert",
    "matrix_to_quaternion",
    "opencv_to_opengl_pose",
    "opengl_to_opencv_pose",
    "orthonormalize_rotation",
    "pixel_grid",
    "pixels_to_camera_directions",
    "pose_distance",
    "pose_from_quaternion_translation",
    "project_points",
    "quaternion_to_matrix",
    "quaternion_translation_from_pose",
    "renormalise_rotation",
    "rotation_angle",
    "se3_exp",
    "se3_log",
    "so3_exp",
    "so3_log",
]
