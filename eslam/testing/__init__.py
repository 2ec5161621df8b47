"""Helpers for tests: writers of the dataset layouts eslam reads, one module per layout.

Tests render frames (``eslam.synthetic``) and write them with these to check each
reader against exact ground truth. The readers never use them; the Replica writer,
which ``eslam synth`` uses, stays in :mod:`eslam.data.replica`.
"""

from eslam.testing.folder import write_folder_sequence
from eslam.testing.scannet import write_scannet_sequence
from eslam.testing.sevenscenes import write_sevenscenes_sequence
from eslam.testing.tum import write_tum_sequence

__all__ = [
    "write_folder_sequence",
    "write_scannet_sequence",
    "write_sevenscenes_sequence",
    "write_tum_sequence",
]
