"""TUM's associate.py pairing (``data.pairing: associate``): the same pairs as the
benchmark tool's own algorithm, transcribed here as the reference, on crafted stamps and
on the shared fr1/xyz frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.config import DataConfig, load_config
from eslam.data.tum import TUMSequence, associate, read_file_list
from eslam.data.tum_pairs import unique_pairs
from eslam.errors import ConfigError


def associate_py(first: list[float], second: list[float], max_difference: float = 0.02):
    """The pairing loop of TUM RGB-D's associate.py (offset 0), as published: candidates
    (difference, a, b) sorted, each stamp taken at most once, the matches sorted."""
    first_keys, second_keys = list(first), list(second)
    potential = sorted(
        (abs(a - b), a, b) for a in first_keys for b in second_keys if abs(a - b) < max_difference
    )
    matches = []
    for _, a, b in potential:
        if a in first_keys and b in second_keys:
            first_keys.remove(a)
            second_keys.remove(b)
            matches.append((a, b))
    return sorted(matches)


def stamps(colour: np.ndarray, depth: np.ndarray) -> list[tuple[float, float]]:
    rows, columns = unique_pairs(colour, depth)
    return [(float(colour[r]), float(depth[c])) for r, c in zip(rows, columns, strict=True)]


def test_a_depth_stamp_goes_to_its_closest_colour_once() -> None:
    # colour 0.00 and 0.01 both want depth 0.012; 0.01 is closer and takes it, 0.00 then
    # takes 0.003 ... which is closer to it than 0.012 anyway: both orders checked
    colour = np.array([0.0, 0.01, 0.05, 0.2])
    depth = np.array([0.012, 0.003, 0.069, 0.5])
    assert stamps(colour, depth) == associate_py(list(colour), list(depth))
    assert stamps(colour, depth) == [(0.0, 0.003), (0.01, 0.012), (0.05, 0.069)]
    # one depth between two colour stamps: only the closer colour image gets it
    assert stamps(np.array([0.0, 0.03]), np.array([0.016])) == [(0.03, 0.016)]
    # 0.02 apart is not a pair (strictly less, as associate.py)
    assert stamps(np.array([0.0]), np.array([0.02])) == []


def test_random_stamps_pair_as_associate_py() -> None:
    generator = np.random.default_rng(0)
    colour = np.cumsum(generator.uniform(0.01, 0.05, 300))
    depth = np.sort(colour + generator.normal(0.0, 0.012, 300))
    assert stamps(colour, depth) == associate_py(list(colour), list(depth))


def test_the_shared_frames_pair_as_associate_py(real_data: Path) -> None:
    root = real_data / "tum-fr1-xyz"
    colour = read_file_list(root / "rgb.txt", "colour images").timestamps
    depth = read_file_list(root / "depth.txt", "depth images").timestamps
    expected = associate_py(list(colour), list(depth))
    assert stamps(colour, depth) == expected
    sequence = TUMSequence(root, DataConfig(format="tum", pairing="associate"))
    assert len(sequence) == len(expected)


def test_poses_go_with_the_associated_frames() -> None:
    colour = np.array([0.0, 0.03, 0.06, 0.2])
    depth = np.array([0.001, 0.031, 0.061, 0.201])
    poses = np.array([0.0, 0.03])  # none within 0.08 s of 0.2
    pairs = associate(colour, depth, poses, pairing="associate")
    np.testing.assert_array_equal(pairs.colour, [0, 1, 2])
    np.testing.assert_array_equal(pairs.depth, [0, 1, 2])
    assert pairs.pose is not None
    np.testing.assert_array_equal(pairs.pose, [0, 1, 1])
    # the release's rule drops the frame 0.03 s (< 1/32 s) after the last kept one
    np.testing.assert_array_equal(associate(colour, depth, None).colour, [0, 2, 3])


def test_an_unknown_pairing_is_refused() -> None:
    with pytest.raises(ConfigError, match="pairing"):
        load_config("tum/tum_cpu", ["data.pairing=nearest"])
