"""The run's trajectory: every frame's pose estimate, timestamp and ground truth, frame by frame.

It is the one owner of the pose estimates: tracking appends a frame's pose, mapping
overwrites the refined poses of its window's keyframes, and the keyframe store reads
its keyframes' poses from here. It grows as frames arrive (doubling its buffer), so a
stream of unknown length needs no preallocation.
"""

from __future__ import annotations

import numpy as np
import torch


class Trajectory:
    """Poses (on the compute device), timestamps and ground truth of the frames so far.

    Args:
        device: where the pose estimates live.
        capacity: frames to allocate room for at first (grows by doubling).
    """

    def __init__(self, device: torch.device | str = "cpu", capacity: int = 64) -> None:
        self.device = torch.device(device)
        self._poses = torch.full((max(capacity, 1), 4, 4), float("nan"), device=self.device)
        self._timestamps: list[float] = []
        self._gt: list[np.ndarray | None] = []

    def __len__(self) -> int:
        return len(self._timestamps)

    @property
    def poses(self) -> torch.Tensor:
        """(N, 4, 4) float32 camera-to-world estimates (a view of the buffer)."""
        return self._poses[: len(self)]

    def append(self, pose: torch.Tensor, timestamp: float, gt: np.ndarray | None) -> int:
        """Add the next frame's pose, timestamp (s) and (4, 4) ground truth; return its index."""
        index = len(self)
        if index == self._poses.shape[0]:
            grown = torch.full((2 * index, 4, 4), float("nan"), device=self.device)
            grown[:index] = self._poses
            self._poses = grown
        self._poses[index] = pose.detach().to(self._poses)
        self._timestamps.append(float(timestamp))
        self._gt.append(None if gt is None else np.asarray(gt, dtype=np.float64))
        return index

    def set_poses(self, indices: torch.Tensor | list[int], poses: torch.Tensor) -> None:
        """Overwrite the estimates of frames ``indices`` with (K, 4, 4) ``poses`` (mapping)."""
        index = torch.as_tensor(indices, dtype=torch.int64, device=self.device)
        self._poses[index] = poses.detach().to(self._poses)

    def truncate(self, length: int) -> None:
        """Forget the frames from ``length`` on (a frame whose processing failed)."""
        self._poses[length:] = float("nan")
        del self._timestamps[length:]
        del self._gt[length:]

    def timestamps(self) -> np.ndarray:
        """(N,) float64 timestamps, seconds."""
        return np.asarray(self._timestamps, dtype=np.float64)

    def gt_poses(self) -> np.ndarray | None:
        """(N, 4, 4) float64 ground truth (NaN rows for frames without any), or None if none had."""
        if all(g is None for g in self._gt):
            return None
        missing = np.full((4, 4), np.nan)
        return np.stack([missing if g is None else g for g in self._gt])

    def state_dict(self) -> dict:
        """CPU copies (tensors and plain numbers only; loads with ``weights_only=True``)."""
        gt = self.gt_poses()
        return {
            "poses": self.poses.detach().cpu().clone(),
            "timestamps": torch.tensor(self._timestamps, dtype=torch.float64),
            "gt": None if gt is None else torch.from_numpy(gt),
        }

    @classmethod
    def from_state_dict(cls, state: dict, device: torch.device | str = "cpu") -> Trajectory:
        """Rebuild a trajectory saved by :meth:`state_dict` on ``device``.

        Raises:
            KeyError: a missing entry.
            ValueError: entries whose lengths disagree.
        """
        poses, timestamps, gt = state["poses"], state["timestamps"], state["gt"]
        count = len(timestamps)
        if tuple(poses.shape) != (count, 4, 4) or (gt is not None and len(gt) != count):
            raise ValueError(
                f"trajectory of {count} timestamps has poses {tuple(poses.shape)} and "
                f"{'no' if gt is None else len(gt)} ground-truth poses"
            )
        trajectory = cls(device, capacity=max(2 * count, 64))
        trajectory._poses[:count] = poses.to(trajectory._poses)
        trajectory._timestamps = [float(t) for t in timestamps.tolist()]
        if gt is None:
            trajectory._gt = [None] * count
        else:
            rows = gt.double().numpy()
            trajectory._gt = [None if np.isnan(row).all() else row for row in rows]
        return trajectory
