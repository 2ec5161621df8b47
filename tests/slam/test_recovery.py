"""Never lose the camera (docs/tracking.md, "Recovery"): with exact ground truth, a
forced loss (frames with no usable depth while the camera moves on, then a return to
a mapped place) is relocalised and the poses from there on are within 1 cm of the
truth; a place that looks alike but is not (a mapped keyframe's colour over another
room's depth) is refused; and the pieces: place recognition, the figures and the log."""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eslam.config import load_config
from eslam.data.replica import ReplicaSequence
from eslam.errors import ConfigError
from eslam.evaluate.report import metrics_table
from eslam.slam.places.features import (
    mutual_matches,
    mutual_matches_reference,
    orb_features,
    residuals,
    rigid_fit,
    rigid_fits,
    rigid_pose,
    thumbnail,
)
from eslam.slam.run.writer import recovery_metrics
from eslam.slam.session import RunResult, run_slam
from eslam.slam.state import TRACKING_COLUMNS, quality_row, recovery_of
from eslam.slam.tracking.base import TrackingQuality
from eslam.synthetic import (
    SynthConfig,
    SyntheticSequence,
    write_synthetic_sequence,
)
from eslam.synthetic.edits import SequenceEdit, return_after_blind, write_edited_sequence
from eslam.types import Intrinsics
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import demo_config

SIZE = (120, 90)
ROOM = SynthConfig(frames=15, width=SIZE[0], height=SIZE[1], seed=0, step_rotation_deg=2.0)
"""The synthetic room, 2 degrees of yaw a frame (exact ground truth)."""
MAPPED, BLIND = 10, 5  # frames 0-9 tracked and mapped; 10-14 the camera moves on, no depth
RETURN = (3, 4, 5, 6)  # back to where frames 3-6 were
ORDER, BLIND_AT = return_after_blind(MAPPED, BLIND, RETURN)
BACK = MAPPED + BLIND  # the first frame back at a mapped place


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The room as written, unedited."""
    return write_synthetic_sequence(tmp_path_factory.mktemp("recovery") / "room", ROOM)


@pytest.fixture(scope="module")
def lossy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The forced loss: mapped frames, a blind stretch, a return."""
    out = tmp_path_factory.mktemp("lossy") / "room"
    return write_edited_sequence(out, ROOM, SequenceEdit(ORDER, BLIND_AT))


def run(data: Path, out: Path, *extra: str) -> RunResult:
    return run_slam(demo_config(data, *extra), out)


def errors_cm(run_dir: Path) -> np.ndarray:
    """Per frame, the estimate's distance from the ground truth (no alignment: frame 0
    starts at its ground truth, which fixes the world frame)."""
    estimate = np.loadtxt(run_dir / "trajectory.txt")
    truth = np.loadtxt(run_dir / "trajectory_gt.txt")
    return 100.0 * np.linalg.norm(estimate[:, 1:4] - truth[:, 1:4], axis=1)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("settings", "how"),
    [((), None), (("tracking.recovery.keyframe_starts=0",), "relocalised")],
    ids=["default", "relocalisation"],
)
def test_a_lost_camera_comes_back_within_a_centimetre(
    lossy: Path, tmp_path: Path, settings: tuple[str, ...], how: str | None
) -> None:
    """Back at a mapped place after the blind stretch: a failed frame or two, then the
    recovery (by default whichever try passes first; with no keyframe starts, by
    relocalisation) puts the camera back, within 1 cm of the truth from then on."""
    result = run(lossy, tmp_path / "run", *settings)
    metrics = result.metrics
    back = BACK
    timings = json.loads((tmp_path / "run" / "timings.json").read_text())
    recovered = [i for i, code in enumerate(timings["tracking_recovery"]) if code and code > 0]
    assert recovered, metrics
    first = recovered[0]
    assert back <= first <= back + 2
    errors = errors_cm(tmp_path / "run")
    assert errors[:back].max() < 10.0  # the blind stretch is extrapolated: a guess
    assert errors[first:].max() < 1.0, errors[first:]  # recovered, and it stays
    assert metrics["tracking_ended_tracked"] is True
    if how == "relocalised":
        relocalised = metrics["tracking_relocalisations"]
        assert relocalised and relocalised[0]["frame"] == first
        assert relocalised[0]["keyframe"] < MAPPED
        log = (tmp_path / "run" / "log.txt").read_text()
        assert f"frame {first}: the first try failed; tracked relocalised at keyframe" in log
        # stopped right after the relocalisation, resumed: the same run (the place index
        # is rebuilt from the keyframes' images, the motion model reads the rows)
        stopped = tmp_path / "stopped"
        config = load_config(tmp_path / "run" / "config.yaml")
        run_slam(config, stopped, stop_after=first + 1)
        resumed = run_slam(load_config(stopped / "config.yaml"), stopped, resume=True)
        np.testing.assert_allclose(resumed.poses, result.poses, rtol=0, atol=1e-7)
        assert resumed.metrics["tracking_relocalisations"] == relocalised


@pytest.mark.slow
def test_without_recovery_the_same_loss_is_for_good(lossy: Path, tmp_path: Path) -> None:
    """The yardstick of the test above: the motion model alone does not come back."""
    metrics = run(lossy, tmp_path / "run", "tracking.recovery.enabled=false").metrics
    assert "tracking_relocalisations" in metrics and not metrics["tracking_relocalisations"]
    assert errors_cm(tmp_path / "run")[BACK:].min() > 5.0


@pytest.mark.slow
def test_a_place_that_looks_alike_is_refused(tmp_path: Path) -> None:
    """After the blind stretch, frames show mapped keyframes' colour over another room's
    depth (seed 1): the colour matches, the map does not, so nothing is relocalised."""
    foreign = frozenset(range(BACK, len(ORDER)))
    edit = SequenceEdit(ORDER, BLIND_AT, foreign=foreign, foreign_seed=1)
    data = write_edited_sequence(tmp_path / "alike", ROOM, edit)
    metrics = run(data, tmp_path / "run").metrics
    assert metrics["tracking_relocalisations"] == []
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "looks like keyframe frame" in log and "refused" in log
    assert metrics["tracking_failures"] >= len(foreign) - 1


def test_place_recognition_ranks_and_locates_a_frame(source: Path) -> None:
    cam = json.loads((source / "cam_params.json").read_text())["camera"]
    intrinsics = Intrinsics(cam["w"], cam["h"], cam["fx"], cam["fy"], cam["cx"], cam["cy"])
    truth = np.loadtxt(source / "traj.txt").reshape(-1, 4, 4)

    def frame(i: int) -> tuple[np.ndarray, np.ndarray]:
        rgb = iio.imread(source / f"results/frame{i:06d}.jpg")
        depth = iio.imread(source / f"results/depth{i:06d}.png").astype(np.float32)
        return rgb, depth / cam["scale"]

    key_rgb, key_depth = frame(4)
    query_rgb, query_depth = frame(5)
    key = orb_features(key_rgb, key_depth, intrinsics)
    query = orb_features(query_rgb, query_depth, intrinsics)
    assert len(key) > 20 and np.isfinite(key.points).all(axis=1).sum() > 20
    # the global descriptor: itself 1, the next frame alike, a far one less so
    assert float(thumbnail(key_rgb) @ thumbnail(key_rgb)) == pytest.approx(1.0, abs=1e-5)
    near, far = (float(thumbnail(frame(i)[0]) @ thumbnail(key_rgb)) for i in (5, 14))
    assert near > far
    assert not thumbnail(np.full_like(key_rgb, 90)).any()  # a flat image is alike to none
    pairs = mutual_matches(query.descriptors, key.descriptors)
    camera, points = query.points[pairs[:, 0]], key.points[pairs[:, 1]]
    usable = np.isfinite(points).all(axis=1) & np.isfinite(camera).all(axis=1)
    world = points[usable] @ truth[4][:3, :3].T + truth[4][:3, 3]
    found = rigid_pose(camera[usable].astype(np.float64), world, min_inliers=10)
    assert found is not None and found.inliers >= 10
    assert np.linalg.norm(found.pose[:3, 3] - truth[5][:3, 3]) < 0.05  # a start, not the answer
    assert rigid_pose(camera[usable][:5], world[:5], min_inliers=10) is None
    shuffled = np.random.default_rng(0).permutation(len(world))  # no agreeing matches
    assert rigid_pose(camera[usable], world[shuffled], min_inliers=len(world) // 2) is None
    assert len(mutual_matches(query.descriptors[:1], key.descriptors)) == 0
    reference = mutual_matches_reference(query.descriptors, key.descriptors)
    assert len(pairs) > 20 and np.array_equal(pairs, reference)


def test_mutual_matches_equal_their_reference_on_near_ties() -> None:
    """Descriptors a few bits apart, many at equal distances: the matcher's pairs are
    the reference's (ratio test, mutual nearest, lowest index on a tie)."""
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, (300, 32), dtype=np.uint8)
    flips = rng.integers(0, 256, (300, 32), dtype=np.uint8) & rng.choice(
        np.array([0, 1, 2, 4], dtype=np.uint8), (300, 32), p=[0.85, 0.05, 0.05, 0.05]
    )
    a, b = base, base[rng.permutation(300)] ^ flips
    b = np.concatenate([b, b[:50]])  # exact duplicates in b: ties for a's nearest
    for ratio in (0.6, 0.8, 1.0):
        fast, reference = mutual_matches(a, b, ratio), mutual_matches_reference(a, b, ratio)
        assert len(reference) > 50 and np.array_equal(fast, reference)
    assert len(mutual_matches_reference(a[:1], b)) == 0


def test_ransac_fits_its_samples_at_once_as_a_loop_over_them_would() -> None:
    """``rigid_fits`` (batched Kabsch) equals ``rigid_fit`` (scipy) per sample, and
    ``rigid_pose`` picks the pose the sequential RANSAC below picks: 60 matches of
    which 20 are moved 0.2-1 m off (wrong matches), depth noise of 5 mm."""
    rng = np.random.default_rng(3)
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_rotvec([0.1, -0.3, 0.2]).as_matrix()
    truth[:3, 3] = [0.4, -0.1, 0.25]
    camera = rng.uniform([-1, -1, 0.5], [1, 1, 3], size=(60, 3))
    world = camera @ truth[:3, :3].T + truth[:3, 3] + rng.normal(0, 0.005, size=(60, 3))
    world[:20] += rng.uniform(0.2, 1.0, size=(20, 3)) * rng.choice([-1, 1], size=(20, 3))
    samples = np.stack([rng.choice(60, 3, replace=False) for _ in range(50)])
    np.testing.assert_allclose(
        rigid_fits(camera[samples], world[samples]),
        np.stack([rigid_fit(camera[s], world[s]) for s in samples]),
        atol=1e-10,
    )

    def sequential(seed: int) -> np.ndarray:  # the loop rigid_pose vectorises
        generator = np.random.default_rng(seed)
        best = np.zeros(60, dtype=bool)
        for _ in range(200):
            sample = generator.choice(60, size=3, replace=False)
            if np.linalg.matrix_rank(world[sample] - world[sample].mean(axis=0), tol=1e-3) < 2:
                continue
            inliers = residuals(rigid_fit(camera[sample], world[sample]), camera, world) < 0.03
            if inliers.sum() > best.sum():
                best = inliers
        return rigid_fit(camera[best], world[best])

    for seed in range(5):
        found = rigid_pose(camera, world, min_inliers=30, seed=seed)
        assert found is not None and found.inliers == 40
        np.testing.assert_allclose(found.pose, sequential(seed), atol=1e-10)
        assert np.abs(found.pose[:3, 3] - truth[:3, 3]).max() < 0.01


def test_recovery_is_recorded_in_the_quality_rows_and_metrics() -> None:
    plain = TrackingQuality(5, 0.9, 0.002, False)
    found = TrackingQuality(5, 0.95, 0.002, False, recovery="relocalised", recovered_from=8)
    nearby = TrackingQuality(5, 0.8, 0.002, False, recovery="start", recovered_from=None)
    rows = [quality_row(None), quality_row(plain), quality_row(found), quality_row(nearby)]
    assert all(len(row) == len(TRACKING_COLUMNS) for row in rows)
    assert [recovery_of(row) for row in rows] == [
        None,
        None,
        ("relocalised", 8),
        ("start", None),
    ]
    assert recovery_metrics(rows) == {
        "tracking_recovered_frames": {"start": 1, "relocalised": 1},
        "tracking_relocalisations": [{"frame": 2, "keyframe": 8}],
    }
    table = metrics_table(recovery_metrics(rows))
    assert "| Frames recovered after a failed try | start 1, relocalised 1 |" in table
    assert "| Relocalisations (frame from keyframe frame) | 1; 2 from 8 |" in table


def test_an_edited_sequence_has_its_order_blind_and_foreign_frames(tmp_path: Path) -> None:
    room = SynthConfig(frames=3, width=32, height=24, seed=0, step_rotation_deg=5.0)
    edit = SequenceEdit((0, 1, 2, 0), blind=frozenset({1}), foreign=frozenset({3}))
    data = write_edited_sequence(tmp_path / "edited", room, edit)
    written = ReplicaSequence(data)
    plain = SyntheticSequence(room)
    assert len(written) == 4
    np.testing.assert_allclose(written.gt_poses()[3], plain.gt_poses()[0], atol=1e-6)
    assert not written[1].depth.any() and written[2].depth.any()
    assert np.abs(written[3].depth - written[0].depth).max() > 0.05  # another room's depth
    np.testing.assert_array_equal(written[3].rgb, written[0].rgb)
    assert json.loads((data / "synth.json").read_text())["edit"]["blind"] == [1]
    with pytest.raises(ValueError, match="blind indices"):
        SequenceEdit((0, 1), blind=frozenset({2}))


def test_keyframe_coverage_without_observed_space_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"keyframe_coverage needs tracking\.observed_only"):
        load_config(DEMO_CONFIG, ["mapping.keyframe_coverage=0.8"])
    config = load_config(
        DEMO_CONFIG, ["mapping.keyframe_coverage=0.8", "tracking.observed_only=true"]
    )
    assert config.mapping.keyframe_coverage == 0.8
