"""benchmarks/gpu_check.py and gpu_pack.py: the one prepared GPU run and the data it carries.

The GPU parts cannot run here; what can is held: the packed folder is a readable TUM
sequence cut at the frames that fit, bad arguments get one line and exit code 2, every
CUDA test file is found, and a run's log tells whether its iterations were replayed."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from eslam.data.tum import TUMSequence
from eslam.testing.scripts import load_script

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def test_pack_cuts_tum_to_what_fits_and_reads_back(real_data: Path, tmp_path: Path, capsys):
    pack = load_script(BENCHMARKS / "gpu_pack.py")
    out = tmp_path / "pack"
    args = ["--data-root", str(real_data), "--out", str(out), "--sevenscenes", "3"]
    assert pack.main([*args, "--tum-frames", "5", "--limit-mib", "40"]) == 0
    assert len(list((out / "7scenes-redkitchen").glob("frame-*.color.jpg"))) == 3
    assert len(TUMSequence(out / "tum-fr1-xyz")) == 5
    assert "tum-fr1-xyz: 5 frames" in capsys.readouterr().out
    # a limit the fixed parts already fill: one line, exit code 2, nothing written
    assert pack.main([*args, "--out", str(tmp_path / "none"), "--limit-mib", "10"]) == 2
    assert "no TUM frame fits" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


def test_bad_arguments_get_one_line(tmp_path: Path, capsys) -> None:
    check = load_script(BENCHMARKS / "gpu_check.py")
    with pytest.raises(SystemExit) as stop:
        check.main(["--data-root", str(tmp_path / "missing"), "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert "gpu_pack.py" in capsys.readouterr().err
    if not torch.cuda.is_available():
        with pytest.raises(SystemExit) as stop:
            check.main(["--data-root", str(tmp_path), "--out", str(tmp_path), "--device", "cuda"])
        assert stop.value.code == 2
        assert "--device cpu --smoke" in capsys.readouterr().err


def test_finds_every_cuda_test_file() -> None:
    check = load_script(BENCHMARKS / "gpu_check.py")
    files = check.cuda_test_files()
    for name in ("test_graphed.py", "test_triton_sampling.py", "test_steps.py"):
        assert any(f.endswith(name) for f in files), name


def test_the_log_tells_how_the_iterations_ran(tmp_path: Path) -> None:
    runs = load_script(BENCHMARKS / "gpu_runs.py")
    log = tmp_path / "log.txt"
    assert runs.graphs_note(log, "eager") == "off"
    lines = {
        "compute.cuda_graphs=auto: each iteration is a CUDA-graph replay": "replayed",
        "compute.cuda_graphs=auto: the iterations run eagerly (the device is cpu, not CUDA)": (
            "eager: the device is cpu, not CUDA"
        ),
        "compute.cuda_graphs: capturing an iteration failed (x): the iterations run eagerly": (
            "capture failed, eager"
        ),
    }
    for line, note in lines.items():
        log.write_text(f"12:00:00 INFO {line}\n")
        assert runs.graphs_note(log, "graphs+triton") == note
