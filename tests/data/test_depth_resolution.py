"""data.depth_downsample: depth at 1/k resolution per side, colour and camera unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.config import DataConfig, load_config
from eslam.data import open_sequence
from eslam.data.depth_resolution import DepthDownsampled, downsample_depth
from eslam.data.fingerprint import fingerprint
from eslam.data.replica import write_replica_sequence
from eslam.errors import ConfigError
from eslam.synthetic import SynthConfig, generate_sequence


def test_each_block_takes_its_top_left_depth() -> None:
    depth = np.arange(1, 7 * 10 + 1, dtype=np.float32).reshape(7, 10)
    depth[0, 3] = 0.0  # invalid stays invalid where it is the kept pixel
    low = downsample_depth(depth, 3)
    assert low.shape == depth.shape and low.dtype == np.float32
    for v in range(7):
        for u in range(10):
            assert low[v, u] == depth[3 * (v // 3), 3 * (u // 3)]
    assert (low[0:3, 3:6] == 0.0).all()
    assert len(np.unique(low)) == 3 * 4  # 1/3 of the detail per side: 3 x 4 values
    assert downsample_depth(depth, 1) is depth
    with pytest.raises(ValueError, match="depth_downsample"):
        downsample_depth(depth, 0)


@pytest.fixture(scope="module")
def sequence_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("seq")
    write_replica_sequence(root, generate_sequence(SynthConfig(frames=3, width=32, height=24)))
    return root


def test_open_sequence_lowers_only_the_depth(sequence_dir: Path) -> None:
    full = open_sequence(DataConfig(path=str(sequence_dir)))
    low = open_sequence(DataConfig(path=str(sequence_dir), depth_downsample=8, start=1))
    assert isinstance(low.sequence, DepthDownsampled)  # under the frame selection
    frame, reference = low[0], full[1]
    np.testing.assert_array_equal(frame.depth, downsample_depth(reference.depth, 8))
    assert not np.array_equal(frame.depth, reference.depth)
    np.testing.assert_array_equal(frame.rgb, reference.rgb)
    assert frame.intrinsics == reference.intrinsics and low.intrinsics == full.intrinsics
    np.testing.assert_array_equal(low.gt_poses(), full.gt_poses()[1:])
    np.testing.assert_array_equal(low.timestamps(), full.timestamps()[1:])
    whole = open_sequence(DataConfig(path=str(sequence_dir), depth_downsample=8))
    assert fingerprint(whole) == fingerprint(full)  # the same input files


def test_config_refuses_a_factor_below_one() -> None:
    with pytest.raises(ConfigError, match=r"data\.depth_downsample"):
        load_config(None, ["data.depth_downsample=0"])
    assert load_config(None, ["data.depth_downsample=8"]).data.depth_downsample == 8
