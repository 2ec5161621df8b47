"""Checkpoints: nested round trip with weights_only loading, corrupt files, versions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.errors import InputError
from eslam.io.checkpoint import CHECKPOINT_VERSION, load_checkpoint, save_checkpoint


def _state() -> dict:
    generator = torch.Generator().manual_seed(3)
    return {
        "field": {"planes.0": torch.randn(1, 4, 5, 6), "beta": torch.tensor(10.0)},
        "keyframes": {
            "rgb": torch.randint(0, 256, (2, 3, 4, 3), dtype=torch.uint8),
            "depth": torch.randint(0, 65536, (2, 3, 4), dtype=torch.int32).to(torch.uint16),
            "frame_indices": torch.tensor([0, 4]),
            "intrinsics": {"width": 4, "height": 3, "fx": 2.0, "fy": 2.0, "cx": 1.5, "cy": 1.0},
        },
        "generator": generator.get_state(),
        "next_frame": 5,
        "tracking_time": [0.1, 0.2],
        "pair": (1, "two", None, True),
    }


def _assert_equal(a: object, b: object) -> None:
    assert type(a) is type(b)
    if isinstance(a, torch.Tensor):
        assert a.dtype == b.dtype and a.device == b.device and torch.equal(a, b)
    elif isinstance(a, dict):
        assert list(a) == list(b)
        for key in a:
            _assert_equal(a[key], b[key])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_equal(x, y)
    else:
        assert a == b


def test_checkpoint_round_trip(tmp_path: Path) -> None:
    state = _state()
    path = tmp_path / "run" / "map.pt"
    save_checkpoint(path, state)
    loaded = load_checkpoint(path, map_location="cpu")
    _assert_equal(loaded, state)
    _assert_equal(load_checkpoint(path, map_location=torch.device("cpu")), state)
    _assert_equal(load_checkpoint(path, map_location=None), state)
    restored = torch.Generator()
    restored.set_state(loaded["generator"])
    assert torch.equal(
        torch.rand(3, generator=restored), torch.rand(3, generator=torch.Generator().manual_seed(3))
    )
    raw = torch.load(path, weights_only=True)
    assert raw["eslam_checkpoint"] == CHECKPOINT_VERSION
    assert [p.name for p in path.parent.iterdir()] == ["map.pt"]


def test_checkpoint_replaces_the_old_file(tmp_path: Path) -> None:
    path = tmp_path / "map.pt"
    save_checkpoint(path, {"next_frame": 1})
    save_checkpoint(path, {"next_frame": 2})
    assert load_checkpoint(path)["next_frame"] == 2


def test_save_refuses_values_weights_only_cannot_load(tmp_path: Path) -> None:
    path = tmp_path / "map.pt"
    save_checkpoint(path, {"next_frame": 1})
    with pytest.raises(TypeError, match=r"state\['keyframes'\]\[0\] is a ndarray"):
        save_checkpoint(path, {"keyframes": [np.zeros(2)]})
    with pytest.raises(TypeError, match="must be a dict"):
        save_checkpoint(path, [1, 2])  # type: ignore[arg-type]
    assert load_checkpoint(path) == {"next_frame": 1}


@pytest.mark.parametrize(
    "content",
    [b"", b"not a torch file at all", b"PK\x03\x04 truncated zip"],
    ids=["empty", "garbage", "bad-zip"],
)
def test_corrupt_checkpoint_is_an_input_error(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "map.pt"
    path.write_bytes(content)
    with pytest.raises(InputError, match=r"map.pt: not an eslam map \("):
        load_checkpoint(path)


def test_truncated_checkpoint_is_an_input_error(tmp_path: Path) -> None:
    path = tmp_path / "map.pt"
    save_checkpoint(path, _state())
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(InputError, match="not an eslam map"):
        load_checkpoint(path)


def test_foreign_torch_file_is_an_input_error(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    torch.save({"weights": torch.zeros(2)}, path)
    with pytest.raises(InputError, match=r"model.pt: not an eslam map \(no eslam checkpoint"):
        load_checkpoint(path)


def test_version_mismatch_is_an_input_error(tmp_path: Path) -> None:
    path = tmp_path / "map.pt"
    torch.save({"eslam_checkpoint": CHECKPOINT_VERSION + 1, "state": {}}, path)
    with pytest.raises(InputError) as caught:
        load_checkpoint(path)
    message = str(caught.value)
    assert "map.pt" in message and f"version {CHECKPOINT_VERSION + 1}" in message
    assert "start a new run" in message


def test_missing_checkpoint_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"map\.pt: not found"):
        load_checkpoint(tmp_path / "map.pt")
