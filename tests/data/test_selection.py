"""Frame selection (start / stride / max_frames) and the depth-units check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.config import DataConfig
from eslam.data import FrameSelection, open_sequence
from eslam.data.base import check_depth_units
from eslam.data.replica import write_replica_sequence
from eslam.errors import ConfigError, InputError
from eslam.synthetic import SynthConfig, generate_sequence


@pytest.fixture(scope="module")
def sequence_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("seq")
    write_replica_sequence(root, generate_sequence(SynthConfig(frames=7, width=32, height=24)))
    return root


def test_start_stride_max_frames(sequence_dir: Path) -> None:
    whole = open_sequence(DataConfig(path=str(sequence_dir)))
    part = open_sequence(DataConfig(path=str(sequence_dir), start=1, stride=2, max_frames=2))
    assert isinstance(part, FrameSelection)
    assert len(part) == 2
    np.testing.assert_array_equal(part.gt_poses(), whole.gt_poses()[[1, 3]])
    np.testing.assert_array_equal(part.timestamps(), [1.0, 3.0])
    frame = part[1]
    assert frame.index == 1  # renumbered
    assert frame.timestamp == 3.0  # the dataset's own time
    np.testing.assert_array_equal(frame.depth, whole[3].depth)
    assert len(open_sequence(DataConfig(path=str(sequence_dir), stride=3))) == 3  # 0, 3, 6
    with pytest.raises(IndexError):
        part[2]


def test_selection_errors(sequence_dir: Path) -> None:
    with pytest.raises(ConfigError, match=r"data.start=7 is past the end .*7 frames"):
        open_sequence(DataConfig(path=str(sequence_dir), start=7))
    with pytest.raises(ValueError, match="stride must be >= 1"):
        DataConfig(stride=0)
    with pytest.raises(ConfigError, match=r"data.path is not set"):
        open_sequence(DataConfig())


def test_depth_in_millimetres_read_as_metres_names_the_scale() -> None:
    depth_mm = np.full((4, 4), 2500.0, np.float32)  # 2.5 m stored in mm, read with scale 1
    with pytest.raises(
        InputError, match=r"d.png: median depth is 2500 m .*depth scale 1000 would give 2.50 m"
    ):
        check_depth_units(depth_mm, Path("d.png"), 1.0)
    replica_raw = np.full((4, 4), 2.5 * 6553.5, np.float32)  # Replica units read as metres
    with pytest.raises(InputError, match=r"depth scale 6553.5 would give 2.50 m"):
        check_depth_units(replica_raw, Path("d.png"), 1.0)
    check_depth_units(np.zeros((4, 4), np.float32), Path("d.png"), 1000.0)  # no depth: passes
    check_depth_units(np.full((4, 4), 2.5, np.float32), Path("d.png"), 1000.0)


def test_wrong_depth_scale_in_config_is_caught_on_read(sequence_dir: Path) -> None:
    sequence = open_sequence(DataConfig(path=str(sequence_dir), depth_scale=1.0))
    with pytest.raises(InputError, match=r"depth000000.png: median depth .*\(depth scale 6553.5"):
        sequence[0]
