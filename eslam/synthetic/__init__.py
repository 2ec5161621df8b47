"""Synthetic RGB-D sequences with exact ground truth: a procedural room, ray cast exactly.

A seeded scene (:mod:`~eslam.synthetic.room`, built from the analytic primitives of
:mod:`~eslam.synthetic.primitives` with the materials of
:mod:`~eslam.synthetic.materials`) is ray cast exactly (:mod:`~eslam.synthetic.render`)
along a smooth hand-held-like camera path (:mod:`~eslam.synthetic.trajectory`), with
optional sensor flaws (:mod:`~eslam.synthetic.sensor`). The frames come in memory
(:mod:`~eslam.synthetic.sequence`) or on disk in the Replica layout with the
ground-truth mesh (:mod:`~eslam.synthetic.mesh`) and ``synth.json``
(:mod:`~eslam.synthetic.files`). World frame: metres, z up, floor at z = 0; poses
camera-to-world, OpenCV camera axes.
"""

from eslam.synthetic.config import FPS, SynthConfig, synthetic_intrinsics
from eslam.synthetic.files import read_synthetic_bound, write_synthetic_sequence
from eslam.synthetic.mesh import scene_mesh
from eslam.synthetic.primitives import Scene
from eslam.synthetic.render import render_frame, render_view
from eslam.synthetic.scenes import SCENES, build_scene, scene_bound
from eslam.synthetic.sequence import SyntheticSequence, generate_sequence
from eslam.synthetic.trajectory import camera_trajectory

__all__ = [
    "FPS",
    "SCENES",
    "Scene",
    "SynthConfig",
    "SyntheticSequence",
    "build_scene",
    "camera_trajectory",
    "generate_sequence",
    "read_synthetic_bound",
    "render_frame",
    "render_view",
    "scene_bound",
    "scene_mesh",
    "synthetic_intrinsics",
    "write_synthetic_sequence",
]
