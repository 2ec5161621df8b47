"""Keyframes: a compact image store, and which frames become keyframes.

Every mapped frame becomes a keyframe (docs/method.md section 5); :class:`KeyframeSchedule`
decides which frames are mapped. The store keeps colour
as uint8 and depth as uint16 with :data:`DEPTH_UNITS_PER_METRE` units per metre, i.e.
5 bytes a pixel: 500 keyframes of 1200 x 680 take 500 * 680 * 1200 * 5 bytes = 2.0 GB
on the store's device (``mapping.keyframe_device``; put them on the CPU when the GPU is
short of memory). Buffers grow by doubling, so while growing from C to 2C keyframes
the old and new buffers coexist for a moment (3C keyframes' worth); pass ``capacity``
when the count is known in advance to avoid it.
The policies choosing a mapping call's window are in :mod:`eslam.slam.mapping.windows`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from eslam.slam.trajectory import Trajectory
from eslam.types import Frame, Intrinsics

DEPTH_UNITS_PER_METRE = 5000.0
"""Stored depth units per metre: 0.2 mm steps (error <= 0.1 mm), at most 65535 / 5000
= 13.107 m. Farther depths are stored as 0 (invalid) and counted in
``KeyframeStore.far_depth_pixels``: storing them clipped at 13.1 m would put a false
surface there. RGB-D sensors and our datasets stay well below (Replica <= 10 m)."""
_MAX_DEPTH_CODE = 65535


class KeyframeStore:
    """Keyframe images (compressed) and the frames they come from.

    The store does not own poses: a keyframe's pose is its frame's entry in the run's
    :class:`~eslam.slam.trajectory.Trajectory` (which mapping refines), read through
    :attr:`poses`.

    Args:
        intrinsics: the camera of every keyframe.
        trajectory: the run's pose estimates, indexed by frame.
        device: where the images live.
        capacity: keyframes to allocate room for at first (grows by doubling).
        depth_units_per_metre: depth quantisation (default :data:`DEPTH_UNITS_PER_METRE`).

    Attributes:
        intrinsics: the camera.
        trajectory: the pose estimates the keyframes' poses are read from.
        device: the store's device.
        depth_units_per_metre: stored depth units per metre.
        far_depth_pixels: depth pixels beyond the storable range, stored as invalid.
    """

    def __init__(
        self,
        intrinsics: Intrinsics,
        trajectory: Trajectory,
        device: torch.device | str = "cpu",
        capacity: int = 16,
        depth_units_per_metre: float = DEPTH_UNITS_PER_METRE,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        if not depth_units_per_metre > 0:
            raise ValueError(f"depth_units_per_metre must be > 0, got {depth_units_per_metre}")
        self.intrinsics = intrinsics
        self.trajectory = trajectory
        self.device = torch.device(device)
        self.depth_units_per_metre = float(depth_units_per_metre)
        self.far_depth_pixels = 0
        self._count = 0
        self._frame_indices: list[int] = []
        self._rgb, self._depth = self._allocate(capacity)

    def _allocate(self, capacity: int) -> tuple[torch.Tensor, torch.Tensor]:
        h, w = self.intrinsics.height, self.intrinsics.width
        return (
            torch.empty((capacity, h, w, 3), dtype=torch.uint8, device=self.device),
            torch.empty((capacity, h, w), dtype=torch.uint16, device=self.device),
        )

    def _reserve(self, needed: int) -> None:
        """Make room for ``needed`` keyframes, at least doubling (amortised O(1) add)."""
        if needed <= self.capacity:
            return
        rgb, depth = self._allocate(max(needed, 2 * self.capacity))
        n = self._count
        rgb[:n] = self._rgb[:n]
        depth[:n] = self._depth[:n]
        self._rgb, self._depth = rgb, depth

    def __len__(self) -> int:
        return self._count

    @property
    def capacity(self) -> int:
        """Keyframes the current buffers hold before they grow."""
        return self._rgb.shape[0]

    @property
    def nbytes(self) -> int:
        """Bytes held by the image buffers (capacity, not just the keyframes stored)."""
        return sum(t.element_size() * t.nelement() for t in (self._rgb, self._depth))

    @property
    def poses(self) -> torch.Tensor:
        """(K, 4, 4) float32 camera-to-world poses of the keyframes (from the trajectory),
        on the store's device."""
        index = torch.tensor(self._frame_indices, dtype=torch.int64)
        return self.trajectory.poses[index.to(self.trajectory.device)].to(self.device)

    @property
    def frame_indices(self) -> tuple[int, ...]:
        """Trajectory index of the frame behind each keyframe."""
        return tuple(self._frame_indices)

    def _check_id(self, k: int) -> int:
        if not 0 <= k < self._count:
            raise IndexError(f"keyframe {k} out of range (the store holds {self._count})")
        return k

    def _encode_depth(self, depth: np.ndarray) -> torch.Tensor:
        metres = np.nan_to_num(depth.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        codes = np.rint(metres * self.depth_units_per_metre)
        far = codes > _MAX_DEPTH_CODE
        self.far_depth_pixels += int(far.sum())
        codes[far | (codes < 0)] = 0
        return torch.from_numpy(codes.astype(np.uint16))

    def add(self, frame: Frame, index: int) -> int:
        """Store ``frame``, whose pose is trajectory entry ``index``; return its keyframe id.

        Depth is quantised to 1 / depth_units_per_metre (nearest); NaN, infinite,
        negative and too-far depths become 0 (invalid).

        Raises:
            ValueError: a frame of another size, or no finite pose at ``index``.
        """
        h, w = self.intrinsics.height, self.intrinsics.width
        if frame.rgb.shape != (h, w, 3) or frame.depth.shape != (h, w):
            raise ValueError(
                f"frame {index} is {frame.depth.shape[1]}x{frame.depth.shape[0]}, "
                f"the keyframes are {w}x{h}"
            )
        if not 0 <= index < len(self.trajectory) or not bool(
            torch.isfinite(self.trajectory.poses[index]).all()
        ):
            raise ValueError(f"frame {index} has no finite pose in the trajectory")
        k = self._count
        self._reserve(k + 1)
        rgb = np.array(frame.rgb, order="C")  # a writable copy: a reader's may be read-only
        self._rgb[k] = torch.from_numpy(rgb).to(self.device)
        self._depth[k] = self._encode_depth(frame.depth).to(self.device)
        self._frame_indices.append(int(index))
        self._count = k + 1
        return k

    def truncate(self, count: int) -> None:
        """Forget the keyframes from id ``count`` on (a frame whose processing failed)."""
        self._count = min(self._count, count)
        del self._frame_indices[self._count :]

    def rgb(self, k: int, device: torch.device | str | None = None) -> torch.Tensor:
        """(H, W, 3) float32 colour in [0, 1] of keyframe ``k`` on ``device`` (default: store's)."""
        image = self._rgb[self._check_id(k)].to(self.device if device is None else device)
        return image.to(torch.float32) / 255.0

    def depth(self, k: int, device: torch.device | str | None = None) -> torch.Tensor:
        """(H, W) float32 depth in metres of keyframe ``k`` (0 = invalid) on ``device``."""
        codes = self._depth[self._check_id(k)].to(self.device if device is None else device)
        return codes.to(torch.float32) / self.depth_units_per_metre

    @property
    def depth_codes(self) -> torch.Tensor:
        """(K, H, W) uint16 stored depth, a view: metres = codes / depth_units_per_metre."""
        return self._depth[: self._count]

    def state_dict(self) -> dict:
        """Compact CPU copies of the keyframe images (tensors and plain numbers only).

        Loads with ``torch.load(weights_only=True)``; see :meth:`from_state_dict`. The
        poses are the trajectory's, saved with it.
        """
        n = self._count
        return {
            "rgb": self._rgb[:n].to("cpu", copy=True),
            "depth": self._depth[:n].to("cpu", copy=True),
            "frame_indices": torch.tensor(self._frame_indices, dtype=torch.int64),
            "intrinsics": dataclasses.asdict(self.intrinsics),
            "depth_units_per_metre": self.depth_units_per_metre,
            "far_depth_pixels": self.far_depth_pixels,
        }

    @classmethod
    def from_state_dict(
        cls, state: dict, trajectory: Trajectory, device: torch.device | str = "cpu"
    ) -> KeyframeStore:
        """Rebuild a store saved by :meth:`state_dict` on ``device``, over ``trajectory``.

        Raises:
            KeyError: a missing entry.
            ValueError: entries whose shapes disagree with each other or the camera, or
                frame indices the trajectory does not hold.
        """
        intrinsics = Intrinsics(**state["intrinsics"])
        rgb, depth = state["rgb"], state["depth"]
        indices = [int(i) for i in state["frame_indices"]]
        n, h, w = len(indices), intrinsics.height, intrinsics.width
        expected = {"rgb": (n, h, w, 3), "depth": (n, h, w)}
        for name, tensor in (("rgb", rgb), ("depth", depth)):
            if tuple(tensor.shape) != expected[name]:
                raise ValueError(
                    f"keyframe {name} has shape {tuple(tensor.shape)}, expected {expected[name]}"
                )
        if any(not 0 <= i < len(trajectory) for i in indices):
            raise ValueError(f"keyframe frame indices {indices} outside the trajectory")
        store = cls(
            intrinsics, trajectory, device, max(n, 1), float(state["depth_units_per_metre"])
        )
        store._rgb[:n] = rgb.to(store.device, torch.uint8)
        store._depth[:n] = depth.to(store.device, torch.uint16)
        store._frame_indices = indices
        store._count = n
        store.far_depth_pixels = int(state["far_depth_pixels"])
        return store


@dataclass(frozen=True)
class KeyframeSchedule:
    """Which frames become keyframes (and are mapped): the paper's fixed interval.

    Frame ``i`` is a keyframe when ``i % every == 0``, when no keyframe exists yet (the
    first frame with depth), and at the end of the stream (its last frame, unless it is
    one already). Frames without valid depth never are.

    Attributes:
        every: the interval k (paper: 4 Replica, 4 ScanNet, 1 TUM).
    """

    every: int

    def __post_init__(self) -> None:
        if self.every < 1:
            raise ValueError(f"every must be >= 1, got {self.every}")

    def is_keyframe(self, index: int, has_depth: bool, keyframes: int) -> bool:
        """Whether frame ``index`` is mapped as it arrives (``keyframes`` exist so far)."""
        return has_depth and (keyframes == 0 or index % self.every == 0)
