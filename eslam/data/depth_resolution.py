"""``data.depth_downsample``: depth at a lower resolution than colour (suppl. Tab. 1).

The paper's robustness experiment (supplementary Sec. 2, "Robustness to Depth
Quality", Tab. 1) downsamples the input depths of Replica room0 "to 1/8 of the
original resolution" and says no more. Here the factor applies to each image side
(1/8 of the width and of the height) by keeping every k-th depth pixel (nearest, no
blending: a mixed depth would lie on neither surface), and the kept depths are shown
at the full size again by nearest neighbour, so colour, intrinsics and every pixel
a ray is drawn from stay as they were: only the depth carries 1/k of the detail, as
from a depth sensor of 1/k the resolution registered to a full-resolution colour
camera. Invalid depth (0) stays invalid.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from eslam.data.base import RGBDSequence
from eslam.types import Frame, Intrinsics


def downsample_depth(depth: np.ndarray, factor: int) -> np.ndarray:
    """Depth with 1/``factor`` of its resolution per side, at its original size.

    D'(v, u) = D(k floor(v / k), k floor(u / k)) with k = ``factor``: the top-left pixel
    of every k x k block stands for the whole block (strided subsampling, then
    nearest-neighbour upsampling; module docstring for why).

    Args:
        depth: (H, W) float32 metres, 0 = invalid.
        factor: k >= 1; 1 returns ``depth`` unchanged.

    Returns:
        (H, W) float32 metres.
    """
    if factor < 1:
        raise ValueError(f"depth_downsample must be >= 1, got {factor}")
    if factor == 1:
        return depth
    height, width = depth.shape
    kept = depth[::factor, ::factor]
    full = np.repeat(np.repeat(kept, factor, axis=0), factor, axis=1)
    return np.ascontiguousarray(full[:height, :width])


class DepthDownsampled:
    """Every frame of ``sequence`` with its depth passed through :func:`downsample_depth`.

    An :class:`~eslam.data.base.RGBDSequence` over any reader (``open_sequence`` wraps
    the reader when ``data.depth_downsample`` > 1); frame files, poses and timestamps
    are the reader's.
    """

    def __init__(self, sequence: RGBDSequence, factor: int) -> None:
        if factor < 1:
            raise ValueError(f"depth_downsample must be >= 1, got {factor}")
        self.sequence = sequence
        self.factor = factor
        self.root: Path = sequence.root
        self.intrinsics: Intrinsics = sequence.intrinsics

    def __len__(self) -> int:
        return len(self.sequence)

    def __getitem__(self, index: int) -> Frame:
        frame = self.sequence[index]
        return dataclasses.replace(frame, depth=downsample_depth(frame.depth, self.factor))

    def gt_poses(self) -> np.ndarray | None:
        """The reader's ground-truth poses."""
        return self.sequence.gt_poses()

    def timestamps(self) -> np.ndarray:
        """The reader's timestamps."""
        return self.sequence.timestamps()

    def frame_files(self, index: int) -> tuple[Path, Path]:
        """The reader's (colour, depth) files of frame ``index``.

        Raises:
            AttributeError: the reader does not read frames from files.
        """
        return self.sequence.frame_files(index)  # type: ignore[attr-defined]

    def depth_path(self, index: int) -> Path:
        """The reader's depth image of frame ``index``.

        Raises:
            AttributeError: the reader does not read frames from files.
        """
        return self.sequence.depth_path(index)  # type: ignore[attr-defined]
