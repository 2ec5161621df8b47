"""Helpers for tests: writers of the dataset layouts eslam reads, one module per layout.

Tests render frames (``eslam.synthetic``) and write them with these to check each
reader against exact ground truth. The readers never use them; the Replica writer,
which ``eslam synth`` uses, stays in :mod:`eslam.data.replica`. Recordings (ROS bags,
RealSense ``.db3``/``.bag``) and Open3D folders: :mod:`eslam.testing.recordings`.
"""

from eslam.testing.folder import write_folder_sequence
from eslam.testing.recordings import (
    write_realsense_bag,
    write_realsense_recording,
    write_redwood_folder,
    write_ros_bag,
)
from eslam.testing.scannet import write_scannet_sequence
from eslam.testing.sevenscenes import write_sevenscenes_sequence
from eslam.testing.tum import write_tum_sequence

__all__ = [
    "write_folder_sequence",
    "write_realsense_bag",
    "write_realsense_recording",
    "write_redwood_folder",
    "write_ros_bag",
    "write_scannet_sequence",
    "write_sevenscenes_sequence",
    "write_tum_sequence",
]
