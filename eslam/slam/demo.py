"""`eslam demo`: write a synthetic scene, run ESLAM on it with the CPU preset, evaluate."""

from __future__ import annotations

from pathlib import Path

from eslam.config import load_config
from eslam.data.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.slam.loop import RunResult, run_slam

DEMO_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "demo.yaml"
"""The demo's configuration: the synthetic scene with the CPU preset (shipped in the package)."""
DEMO_SCENE = SynthConfig(frames=60, width=160, height=120, seed=0)
"""The demo's synthetic sequence: 60 frames of the procedural room."""


def run_demo(out_dir: str | Path, overrides: tuple[str, ...] = ()) -> RunResult:
    """Write the demo scene to ``out_dir/data`` (once) and run to ``out_dir/run``."""
    out_dir = Path(out_dir)
    data = out_dir / "data"
    if not (data / "synth.json").is_file():
        write_synthetic_sequence(data, DEMO_SCENE, overwrite=True)
    bound = read_synthetic_bound(data)
    config = load_config(
        DEMO_CONFIG,
        [f"data.path={data}", f"scene.bound={bound}", *overrides],
    )
    return run_slam(config, out_dir / "run", overwrite=True)
