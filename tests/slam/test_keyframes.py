"""Keyframe store (compression, growth, state) and the window selection policies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import MappingConfig
from eslam.io.checkpoint import load_checkpoint, save_checkpoint
from eslam.slam.mapping.keyframes import DEPTH_UNITS_PER_METRE, KeyframeStore
from eslam.slam.mapping.windows import (
    OverlapWindow,
    RandomWindow,
    RecentWindow,
    make_window_strategy,
)
from eslam.slam.trajectory import Trajectory
from eslam.types import Frame, Intrinsics

CAMERA = Intrinsics(width=32, height=24, fx=20.0, fy=20.0, cx=15.5, cy=11.5)
NO_CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
DEVICES = ["cpu", pytest.param("cuda", marks=[NO_CUDA, pytest.mark.cuda])]


def _frame(index: int, seed: int = 0, depth: np.ndarray | None = None) -> Frame:
    rng = np.random.default_rng(seed + index)
    rgb = rng.integers(0, 256, (CAMERA.height, CAMERA.width, 3), dtype=np.uint8)
    if depth is None:
        depth = rng.uniform(0.1, 13.0, (CAMERA.height, CAMERA.width)).astype(np.float32)
    return Frame(index=index, rgb=rgb, depth=depth, intrinsics=CAMERA)


def _plane(metres: float) -> np.ndarray:
    return np.full((CAMERA.height, CAMERA.width), metres, dtype=np.float32)


def _store(device: str = "cpu", capacity: int = 16) -> KeyframeStore:
    return KeyframeStore(CAMERA, Trajectory(device), device, capacity)


def _add(store: KeyframeStore, frame: Frame, pose) -> int:
    """Give frame ``frame.index`` the ``pose`` in the store's trajectory, then store it."""
    trajectory = store.trajectory
    while len(trajectory) < frame.index:
        trajectory.append(torch.eye(4), 0.0, None)
    trajectory.append(torch.as_tensor(pose, dtype=torch.float32), 0.0, None)
    return store.add(frame, frame.index)


def _pose(rotation: np.ndarray | None = None, translation=(0.0, 0.0, 0.0)) -> torch.Tensor:
    pose = torch.eye(4)
    if rotation is not None:
        pose[:3, :3] = torch.as_tensor(rotation, dtype=torch.float32)
    pose[:3, 3] = torch.tensor(translation)
    return pose


@pytest.mark.parametrize("device", DEVICES)
def test_store_round_trip_of_colour_and_depth(device: str) -> None:
    store = _store(device)
    frame = _frame(7)
    depth = frame.depth.copy()
    depth[0, :4] = [0.0, np.nan, -1.0, np.inf]
    frame = Frame(index=7, rgb=frame.rgb, depth=depth, intrinsics=CAMERA)
    k = _add(store, frame, _pose(translation=(1.0, 2.0, 3.0)))
    assert k == 0 and len(store) == 1 and store.frame_indices == (7,)
    rgb, metres = store.rgb(0), store.depth(0)
    assert rgb.dtype == torch.float32 and rgb.device.type == device and rgb.shape == (24, 32, 3)
    assert metres.dtype == torch.float32 and metres.device.type == device
    assert torch.equal((rgb * 255).round().to(torch.uint8).cpu(), torch.from_numpy(frame.rgb))
    assert float(rgb.min()) >= 0.0 and float(rgb.max()) <= 1.0
    valid = np.isfinite(depth) & (depth > 0)
    restored = metres.cpu().numpy()
    assert np.all(restored[~valid] == 0)
    assert np.abs(restored[valid] - depth[valid]).max() <= 0.5 / DEPTH_UNITS_PER_METRE + 1e-6
    assert 0.5 / DEPTH_UNITS_PER_METRE == pytest.approx(1e-4)
    assert store.rgb(0, "cpu").device.type == "cpu" and store.depth(0, "cpu").device.type == "cpu"


def test_store_far_depth_is_invalid_and_counted() -> None:
    store = _store()
    depth = _plane(5.0)
    depth[0, :3] = [13.1, 13.2, 100.0]
    _add(store, _frame(0, depth=depth), torch.eye(4))
    metres = store.depth(0)
    assert float(metres[0, 0]) == pytest.approx(13.1, abs=1e-4)
    assert metres[0, 1] == 0 and metres[0, 2] == 0
    assert store.far_depth_pixels == 2


def test_store_grows_past_its_capacity() -> None:
    store = _store("cpu", 2)
    frames = [_frame(4 * i, seed=1) for i in range(9)]
    for i, frame in enumerate(frames):
        assert _add(store, frame, _pose(translation=(float(i), 0.0, 0.0))) == i
    assert len(store) == 9 and store.capacity >= 9 and store.capacity <= 16
    assert store.frame_indices == tuple(range(0, 36, 4))
    assert store.poses.shape == (9, 4, 4)
    assert torch.equal(store.poses[:, 0, 3], torch.arange(9.0))
    for i, frame in enumerate(frames):
        assert torch.equal(
            (store.rgb(i) * 255).round().to(torch.uint8), torch.from_numpy(frame.rgb)
        )
        assert torch.allclose(store.depth(i), torch.from_numpy(frame.depth), atol=1.01e-4, rtol=0)


def test_store_poses_come_from_the_trajectory_and_checks() -> None:
    store = _store()
    _add(store, _frame(0), np.eye(4))
    _add(store, _frame(1), torch.eye(4, dtype=torch.float64))
    store.trajectory.set_poses([1], _pose(translation=(0.0, 0.5, 0.0))[None])
    assert store.poses.dtype == torch.float32 and float(store.poses[1, 1, 3]) == 0.5
    with pytest.raises(IndexError):
        store.depth(-1)
    with pytest.raises(ValueError, match="no finite pose"):
        store.add(_frame(2), 2)  # the trajectory has no frame 2
    store.trajectory.append(torch.full((4, 4), float("nan")), 0.0, None)
    with pytest.raises(ValueError, match="no finite pose"):
        store.add(_frame(2), 2)
    small = Intrinsics(width=8, height=6, fx=5.0, fy=5.0, cx=3.5, cy=2.5)
    with pytest.raises(ValueError, match="keyframes are 32x24"):
        store.add(Frame(3, np.zeros((6, 8, 3), np.uint8), np.ones((6, 8), np.float32), small), 0)
    assert len(store) == 2
    store.truncate(1)
    assert len(store) == 1 and store.frame_indices == (0,)


def test_store_state_round_trip_through_a_checkpoint(tmp_path: Path) -> None:
    store = _store("cpu", 8)
    depth = _plane(2.0)
    depth[0, 0] = 20.0
    for i in range(3):
        _add(
            store,
            _frame(i * 4, seed=2, depth=depth if i == 1 else None),
            _pose(translation=(i, 0, 0)),
        )
    state = store.state_dict()
    assert state["rgb"].shape == (3, 24, 32, 3)
    assert state["rgb"].untyped_storage().nbytes() == 3 * 24 * 32 * 3  # compact, not capacity
    save_checkpoint(tmp_path / "map.pt", {"keyframes": state})
    saved = load_checkpoint(tmp_path / "map.pt")["keyframes"]
    loaded = KeyframeStore.from_state_dict(saved, store.trajectory, "cpu")
    assert len(loaded) == 3 and loaded.intrinsics == CAMERA and loaded.device == torch.device("cpu")
    assert loaded.frame_indices == (0, 4, 8) and loaded.far_depth_pixels == 1
    assert torch.equal(loaded.poses, store.poses)
    for k in range(3):
        assert torch.equal(loaded.rgb(k), store.rgb(k)) and torch.equal(
            loaded.depth(k), store.depth(k)
        )
    _add(loaded, _frame(12), torch.eye(4))
    assert len(loaded) == 4 and len(store) == 3


def test_store_state_with_wrong_shapes_is_refused() -> None:
    store = _store()
    _add(store, _frame(0), torch.eye(4))
    state = store.state_dict()
    state["rgb"] = torch.zeros(2, 24, 32, 3, dtype=torch.uint8)
    with pytest.raises(ValueError, match="rgb has shape"):
        KeyframeStore.from_state_dict(state, store.trajectory)
    state = store.state_dict()
    with pytest.raises(ValueError, match="outside the trajectory"):
        KeyframeStore.from_state_dict(state, Trajectory())
    del state["rgb"]
    with pytest.raises(KeyError):
        KeyframeStore.from_state_dict(state, store.trajectory)


def test_empty_store_state_round_trip() -> None:
    loaded = KeyframeStore.from_state_dict(_store().state_dict(), Trajectory())
    assert len(loaded) == 0 and loaded.poses.shape == (0, 4, 4)


def _store_of(count: int) -> KeyframeStore:
    store = _store(capacity=count)
    for i in range(count):
        _add(store, _frame(i, depth=_plane(2.0)), torch.eye(4))
    return store


def test_random_window_keeps_current_and_two_latest() -> None:
    generator = torch.Generator().manual_seed(0)
    window = RandomWindow(size=5)
    for count in range(1, 12):
        store = _store_of(count)
        selected = window.select(store, count - 1, generator)
        assert selected == sorted(set(selected)) and len(selected) == min(count, 5)
        assert set(range(max(0, count - 3), count)) <= set(selected)
    store = _store_of(10)
    selected = window.select(store, 3, generator)
    assert {3, 8, 9} <= set(selected) and len(selected) == 5
    with pytest.raises(IndexError):
        window.select(store, 10, generator)
    with pytest.raises(ValueError, match=">= 3"):
        RandomWindow(size=2)


def test_random_window_is_seeded_and_covers_every_keyframe() -> None:
    store = _store_of(30)
    window = RandomWindow(size=5)
    draws = [window.select(store, 29, torch.Generator().manual_seed(s)) for s in range(200)]
    again = [window.select(store, 29, torch.Generator().manual_seed(s)) for s in range(200)]
    assert draws == again
    assert len({tuple(d) for d in draws}) > 100
    assert set().union(*draws) == set(range(30))
    generator = torch.Generator().manual_seed(1)
    counts = np.bincount(
        [k for _ in range(3000) for k in window.select(store, 29, generator) if k < 27],
        minlength=27,
    )
    assert counts.min() > 0.7 * counts.mean() and counts.max() < 1.3 * counts.mean()


def _overlap_store() -> KeyframeStore:
    """Keyframes 0 (same view as the current), 1 (looking the opposite way), 2 (50 m
    aside), 3 (half overlapping), 4 and 5 (latest, opposite) and 6 (current)."""
    opposite = np.diag([-1.0, 1.0, -1.0])  # 180 degrees about y: looks along -z
    poses = [
        _pose(),
        _pose(opposite),
        _pose(translation=(50.0, 0.0, 0.0)),
        _pose(translation=(1.6, 0.0, 0.0)),
        _pose(opposite),
        _pose(opposite, (0.0, 0.0, 5.0)),
        _pose(),
    ]
    store = _store()
    for i, pose in enumerate(poses):
        _add(store, _frame(i, depth=_plane(2.0)), pose)
    return store


def test_overlap_fractions() -> None:
    store = _overlap_store()
    window = OverlapWindow(size=4, samples=500)
    fractions = window.overlap_fractions(store, 6, [0, 1, 2, 3], torch.Generator().manual_seed(0))
    assert fractions is not None
    assert fractions[0] == 1.0 and fractions[1] == 0.0 and fractions[2] == 0.0
    # Shifted by 1.6 m at 2 m depth: 16 of 32 columns stay in view.
    assert 0.3 < float(fractions[3]) < 0.7


def test_overlap_window_excludes_keyframes_that_do_not_overlap() -> None:
    store = _overlap_store()
    small = OverlapWindow(size=4)
    for seed in range(20):
        selected = small.select(store, 6, torch.Generator().manual_seed(seed))
        assert len(selected) == 4 and {4, 5, 6} <= set(selected) and selected[0] in (0, 3)
    large = OverlapWindow(size=10)
    assert large.select(store, 6, torch.Generator().manual_seed(0)) == [0, 3, 4, 5, 6]
    strict = OverlapWindow(size=10, min_overlap=0.9)
    assert strict.select(store, 6, torch.Generator().manual_seed(0)) == [0, 4, 5, 6]
    assert RandomWindow(size=10).select(store, 6) == list(range(7))


def test_overlap_window_without_depth_draws_from_all() -> None:
    store = _overlap_store()
    _add(store, _frame(7, depth=_plane(0.0)), torch.eye(4))
    window = OverlapWindow(size=10)
    assert window.overlap_fractions(store, 7, [0, 1]) is None
    assert window.select(store, 7, torch.Generator().manual_seed(0)) == list(range(8))
    with pytest.raises(ValueError):
        OverlapWindow(size=5, min_overlap=1.0)


def test_make_window_strategy() -> None:
    assert make_window_strategy(MappingConfig()) == RandomWindow(20)
    made = make_window_strategy(MappingConfig(window=7, selection="overlap"))
    assert isinstance(made, OverlapWindow) and made.size == 7


def test_recent_window_takes_the_latest_keyframes() -> None:
    window = RecentWindow(size=4)
    store = _store_of(10)
    assert window.select(store, 9) == [6, 7, 8, 9]
    assert window.select(store, 3) == [3, 7, 8, 9]  # current and the latest others
    assert window.select(_store_of(2), 1) == [0, 1]
    assert make_window_strategy(MappingConfig(window=4, selection="recent")) == window
    with pytest.raises(ValueError, match=">= 3"):
        RecentWindow(size=2)
