"""A recording replayed in real time: mapping in turn against mapping beside the tracker.

Runs ``eslam run CONFIG --data DATA --realtime`` once per mode, each in a fresh process
and one after the other (a real-time run must have the machine to itself), with
``mapping.concurrent`` false (in turn) and true (beside the tracker), and prints one
markdown row per mode from each run's metrics.json: frames tracked and dropped, the
tracked rate after the first frame (while frames come, and with the final mapping
calls), the first frame's wall time, the ATE over the tracked frames, the tracker's lag
behind the camera (mean and largest), mapping calls and keyframes replaced
(docs/live.md, "Mapping beside the tracker").

    python benchmarks/realtime_replay.py --config tum/tum_cpu \\
        --data .../rgbd_dataset_freiburg1_xyz --out /tmp/replay threads=1
    python benchmarks/realtime_replay.py --config sevenscenes/redkitchen_cpu \\
        --data .../7scenes-redkitchen --out /tmp/replay7 threads=1 data.replay_fps=30

Trailing KEY=VALUE arguments are config overrides for every run (a layout without
timestamps needs ``data.replay_fps``). Prints the table only (docs/results.md takes its
rows by hand).
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from pathlib import Path

MODES = {"in-turn": "false", "beside": "true"}
"""Mode name -> mapping.concurrent."""

COLUMNS = (
    ("frames tracked", "frames", "{:d}"),
    ("dropped", "frames_dropped", "{:d}"),
    ("tracked fps after the first", "fps_poses_after_first", "{:.2f}"),
    ("same, final mapping included", "fps_wall_after_first", "{:.2f}"),
    ("first frame s", "first_frame_s", "{:.1f}"),
    ("ATE cm", "ate_rmse_cm", "{:.2f}"),
    ("failed", "tracking_failures", "{:d}"),
    ("lag s mean / max", ("tracking_lag_s_mean", "tracking_lag_s_max"), "{:.1f} / {:.1f}"),
    ("mapping calls", "mapping_calls", "{:d}"),
    ("keyframes replaced", "mapping_keyframes_replaced", "{:d}"),
)


def run_mode(config: str, data: Path, out: Path, concurrent: str, overrides: list[str]) -> dict:
    """One real-time run in a fresh process; its metrics.json."""
    command = [
        sys.executable, "-m", "eslam", "run", config, "--data", str(data), "--out", str(out),
        "--overwrite", "--realtime", *overrides, f"mapping.concurrent={concurrent}",
        "output.progress=false",
    ]  # fmt: skip
    print("$", shlex.join(command), file=sys.stderr)
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return json.loads((out / "metrics.json").read_text(encoding="utf-8"))


def cell(metrics: dict, key: str | tuple[str, ...], form: str) -> str:
    """A table cell: ``form`` over the metric(s) ``key``, "-" where one is missing."""
    keys = (key,) if isinstance(key, str) else key
    values = [metrics.get(k) for k in keys]
    if any(v is None for v in values):
        return "-"
    return form.format(*values)


def table(rows: dict[str, dict]) -> str:
    """The markdown table, one row per mode."""
    head = "| mapping | " + " | ".join(name for name, _, _ in COLUMNS) + " |"
    rule = "|---|" + "---:|" * len(COLUMNS)
    body = [
        f"| {mode} | " + " | ".join(cell(m, key, form) for _, key, form in COLUMNS) + " |"
        for mode, m in rows.items()
    ]
    return "\n".join([head, rule, *body])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, help="config name or file")
    parser.add_argument("--data", type=Path, required=True, help="the recording")
    parser.add_argument("--out", type=Path, required=True, help="folder for the run folders")
    parser.add_argument(
        "--mode", action="append", choices=list(MODES), help="one run (again for more; all)"
    )
    parser.add_argument("overrides", nargs="*", help="KEY=VALUE config overrides")
    args = parser.parse_args(argv)
    rows = {}
    for mode in args.mode or list(MODES):
        out = args.out / mode
        rows[mode] = run_mode(args.config, args.data, out, MODES[mode], args.overrides)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
