"""The live viewer: a short run recorded with --viewer-save, read back with rerun's reader."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.io.trajectory import read_tum_trajectory
from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.viz.depth_images import depth_millimetres
from eslam.workflows.demo import DEMO_CONFIG

rr = pytest.importorskip("rerun", reason="the [viewer] extra (rerun-sdk) is not installed")

FRAMES = 3
WIDTH, HEIGHT = 64, 48
# A few frames, coarse planes, few iterations; poses never refined by mapping, so the
# pose logged at each frame is the run's final one.
SETTINGS = [
    "tracking.method=render",
    "tracking.render.rays=100",
    "tracking.border=4",
    "tracking.render.iterations=2",
    "mapping.rays=300",
    "mapping.every=2",
    "mapping.window=3",
    "mapping.iterations=2",
    "mapping.first_iterations=30",
    "mapping.first_lr_factor=5.0",
    "mapping.first_warm_start=none",
    "mapping.optimise_poses=false",
    "render.samples_stratified=8",
    "render.samples_surface=4",
    "render.samples_no_depth=16",
    "output.progress=false",
    "output.mesh=false",
    "field.geometry_resolution=[0.24, 0.12]",
    "field.appearance_resolution=[0.24, 0.12]",
    "viewer.render_every=2",
    "viewer.render_downscale=2",
    "viewer.mesh_every=1",
    "viewer.mesh_resolution=0.1",
]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("viewer")
    data = root / "data"
    write_synthetic_sequence(data, SynthConfig(frames=FRAMES, width=WIDTH, height=HEIGHT, seed=1))
    rrd = root / "out" / "run.rrd"
    argv = ["run", str(DEMO_CONFIG), "--data", str(data), "--out", str(root / "run")]
    argv += ["--viewer-save", str(rrd), f"scene.bound={read_synthetic_bound(data)}", *SETTINGS]
    assert main(argv) == 0
    return root / "run", rrd


def read_back(rrd: Path):
    with rr.server.Server(host="127.0.0.1", datasets={"runs": [str(rrd)]}) as server:
        dataset = server.client().get_dataset("runs")
        return dataset.reader(index="frame").to_pandas()


def column(table, entity: str, component: str) -> list:
    """One value per frame row of ``entity:component`` (None where nothing was logged)."""
    values = table[f"{entity}:{component}"].tolist()
    return [None if v is None else v[0] for v in values]


def test_recording_holds_the_run_poses_images_mesh_and_scalars(
    recorded: tuple[Path, Path],
) -> None:
    run_dir, rrd = recorded
    assert rrd.is_file() and not list(rrd.parent.glob(".*")), "published whole, no leftovers"
    table = read_back(rrd).sort_values("frame")
    assert table["frame"].tolist() == list(range(FRAMES))
    _, poses = read_tum_trajectory(run_dir / "trajectory.txt")
    translations = np.stack(column(table, "/world/camera", "Transform3D:translation"))
    np.testing.assert_allclose(translations, poses[:, :3, 3], atol=1e-5)
    # rerun keeps a Mat3x3 column by column
    rotations = [
        np.reshape(m, (3, 3)).T for m in column(table, "/world/camera", "Transform3D:mat3x3")
    ]
    np.testing.assert_allclose(np.stack(rotations), poses[:, :3, :3], atol=1e-5)
    strip = column(table, "/world/trajectory/estimated", "LineStrips3D:strips")[-1]
    np.testing.assert_allclose(np.stack(strip), poses[:, :3, 3], atol=1e-5)
    gt = column(table, "/world/trajectory/ground_truth", "LineStrips3D:strips")[-1]
    assert len(gt) == FRAMES

    resolution = column(table, "/world/camera/image", "Pinhole:resolution")[0]
    assert list(resolution) == [WIDTH, HEIGHT]
    for blob in column(table, "/world/camera/image/rgb", "EncodedImage:blob"):
        assert Image.open(io.BytesIO(bytes(blob))).size == (WIDTH, HEIGHT)
    depth_sizes = column(table, "/world/camera/image/depth", "DepthImage:format")
    assert all((f["width"], f["height"]) == (WIDTH, HEIGHT) for f in depth_sizes)
    sequence = open_sequence(DataConfig(path=str(run_dir.parent / "data")))
    for index, buffer in enumerate(column(table, "/world/camera/image/depth", "DepthImage:buffer")):
        logged = np.frombuffer(bytes(buffer), dtype=np.uint16).reshape(HEIGHT, WIDTH)
        np.testing.assert_array_equal(logged, depth_millimetres(sequence[index].depth))

    # rendered every 2nd frame at half size; the mesh at every keyframe (frames 0 and 2)
    rendered = column(table, "/rendered/depth", "DepthImage:format")
    assert [f is not None for f in rendered] == [True, False, True]
    assert all((f["width"], f["height"]) == (WIDTH // 2, HEIGHT // 2) for f in rendered if f)
    buffer = column(table, "/rendered/depth", "DepthImage:buffer")[2]
    depth = np.frombuffer(bytes(buffer), dtype=np.uint16)  # millimetres
    assert (depth > 0).mean() > 0.9, "the map's surface is hit"
    meshes = table["/world/mesh:Mesh3D:vertex_positions"].tolist()
    assert [m is not None for m in meshes] == [True, False, True]
    assert len(meshes[-1]) > 100 and np.isfinite(np.stack(meshes[-1])).all()
    losses = column(table, "/scalars/mapping/loss", "Scalars:scalars")
    assert all(np.isfinite(loss) for loss in losses if loss is not None)
    assert column(table, "/scalars/time/tracking_ms", "Scalars:scalars")[1] > 0


def test_a_spawned_viewer_without_a_display_is_refused_before_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("sys.platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "run"
    argv = [
        "run",
        str(DEMO_CONFIG),
        "--data",
        str(tmp_path),
        "--out",
        str(out),
        "--viewer",
        "rerun",
    ]
    assert main(argv) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "no display" in err and "--viewer rerun-web" in err and len(err.splitlines()) == 1
    assert not out.exists()
