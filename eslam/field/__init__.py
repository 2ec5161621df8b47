"""The scene representation: multi-scale feature planes and tiny MLP decoders.

See docs/method.md section 1. :class:`SceneField` is what the renderer, the mapper and the
mesher use; :mod:`eslam.field.planes` holds the plane maths as pure functions.
"""

from eslam.field.decoders import MLPDecoder, appearance_decoder, geometry_decoder
from eslam.field.plane_sampling import sample_planes_fast, sample_planes_reference
from eslam.field.planes import (
    PlaneLevel,
    PlaneSet,
    fit_bound,
    grid_size,
    normalize_points,
    plane_shapes,
)
from eslam.field.scene_field import SceneField

__all__ = [
    "MLPDecoder",
    "PlaneLevel",
    "PlaneSet",
    "SceneField",
    "appearance_decoder",
    "fit_bound",
    "geometry_decoder",
    "grid_size",
    "normalize_points",
    "plane_shapes",
    "sample_planes_fast",
    "sample_planes_reference",
]
