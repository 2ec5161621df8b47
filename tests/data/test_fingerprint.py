"""The input fingerprint: what a run folder records so resume refuses changed data."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.fingerprint import InputFingerprint, differences, fingerprint
from eslam.data.replica import write_replica_sequence
from eslam.synthetic import SynthConfig, generate_sequence


def _write(root: Path, frames: int) -> Path:
    write_replica_sequence(root, generate_sequence(SynthConfig(frames=frames, width=32, height=24)))
    return root


@pytest.fixture(scope="module")
def sequence_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write(tmp_path_factory.mktemp("seq") / "data", 5)


def _print(path: Path, **selection) -> InputFingerprint:
    return fingerprint(open_sequence(DataConfig(path=str(path), **selection)))


def test_the_fingerprint_names_frames_files_and_camera(sequence_dir: Path) -> None:
    found = _print(sequence_dir)
    assert found.frames == 5 and found.camera[:2] == (32.0, 24.0)
    names = [stamp.name for stamp in found.files]
    assert names == [
        "results/frame000000.jpg",
        "results/depth000000.png",
        "results/frame000004.jpg",
        "results/depth000004.png",
    ]
    assert all(stamp.size > 0 for stamp in found.files)
    assert InputFingerprint.from_dict(found.to_dict()) == found
    # a frame selection fingerprints the frames the run sees
    part = _print(sequence_dir, start=1, max_frames=2)
    assert part.frames == 2 and part.files[0].name == "results/frame000001.jpg"


def test_moved_data_has_the_same_fingerprint(sequence_dir: Path, tmp_path: Path) -> None:
    moved = tmp_path / "elsewhere"
    shutil.copytree(sequence_dir, moved)
    assert differences(_print(sequence_dir), _print(moved)) == []


def test_grown_shrunk_and_changed_sequences_differ(sequence_dir: Path, tmp_path: Path) -> None:
    recorded = _print(sequence_dir)
    grown = _print(_write(tmp_path / "grown", 7))
    assert "it grew from 5 to 7 frames" in differences(recorded, grown)
    shrunk = _print(_write(tmp_path / "shrunk", 3))
    assert "it shrank from 5 to 3 frames" in differences(recorded, shrunk)
    changed = tmp_path / "changed"
    shutil.copytree(sequence_dir, changed)
    last = changed / "results" / "depth000004.png"
    last.write_bytes(last.read_bytes() + b"\0")  # another file under the same name
    found = differences(recorded, _print(changed))
    assert len(found) == 1 and found[0].startswith("results/depth000004.png (")


def test_a_different_camera_differs(sequence_dir: Path) -> None:
    recorded = _print(sequence_dir)
    resized = _print(sequence_dir, resize=(16, 12))
    found = differences(recorded, resized)
    assert any(d.startswith("the camera changed from 32x24") for d in found)


def test_a_damaged_record_is_an_error() -> None:
    with pytest.raises(ValueError, match="not an input fingerprint"):
        InputFingerprint.from_dict({"frames": 3})
