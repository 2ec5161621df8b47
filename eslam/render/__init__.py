"""Rendering: ray sampling, SDF volume rendering and the shared renderer (docs/method.md section 2).

Pure maths in ``sampling``, ``volume`` and ``rays``; ``renderer`` puts them together
around any field that satisfies :class:`SceneFieldLike`.
"""

from eslam.render.rays import camera_directions, rays_from_pixels, sample_pixels
from eslam.render.renderer import (
    DEFAULT_CHUNK,
    SceneFieldLike,
    importance_bins,
    render_image,
    render_rays,
    render_rays_without_depth,
    weights_from_sdf,
)
from eslam.render.sampling import (
    PDF_EPSILON,
    depth_guided_samples,
    importance_samples,
    midpoint_edges,
    ray_box_exit,
    ray_box_intersection,
    stratified_offsets,
    uniform_samples,
)
from eslam.render.volume import (
    BELL_EPSILON,
    TRANSMITTANCE_EPSILON,
    alpha_to_weights,
    bell_weights,
    composite,
    sdf_to_alpha,
    sdf_to_weights,
)

__all__ = [
    "BELL_EPSILON",
    "DEFAULT_CHUNK",
    "PDF_EPSILON",
    "TRANSMITTANCE_EPSILON",
    "SceneFieldLike",
    "alpha_to_weights",
    "bell_weights",
    "camera_directions",
    "composite",
    "depth_guided_samples",
    "importance_bins",
    "importance_samples",
    "midpoint_edges",
    "ray_box_exit",
    "ray_box_intersection",
    "rays_from_pixels",
    "render_image",
    "render_rays",
    "render_rays_without_depth",
    "sample_pixels",
    "sdf_to_alpha",
    "sdf_to_weights",
    "stratified_offsets",
    "uniform_samples",
    "weights_from_sdf",
]
