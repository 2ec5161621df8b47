"""report.md of a run: the metrics table, the evaluation settings, the plots.

Pure text: the caller computes the metrics and draws the plots; this module only lays
them out, so the same table is printed by ``eslam eval`` and ``eslam demo``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from eslam.atomic import write_text

METRICS: tuple[tuple[str, str, str], ...] = (
    ("ate_rmse_cm", "ATE RMSE", "cm"),
    ("ate_mean_cm", "ATE mean", "cm"),
    ("ate_median_cm", "ATE median", "cm"),
    ("ate_max_cm", "ATE max", "cm"),
    ("accuracy_cm", "Accuracy", "cm"),
    ("completion_cm", "Completion", "cm"),
    ("completion_ratio_pct", "Completion ratio (< 5 cm)", "%"),
    ("depth_l1_cm", "Depth L1", "cm"),
    ("precision_pct", "Precision (< 1 cm)", "%"),
    ("recall_pct", "Recall (< 1 cm)", "%"),
    ("f1_pct", "F1 (< 1 cm)", "%"),
    ("fpt_s", "Frame processing time", "s"),
    ("fps_wall", "FPS (wall clock)", ""),
    ("fps_wall_after_first", "FPS after the first frame", ""),
    ("fps_poses_after_first", "Poses per second after the first frame", ""),
    ("fps_tracking", "FPS, tracking only (Co-SLAM)", ""),
    ("first_frame_s", "First frame", "s"),
    ("frames_received", "Frames received (real time)", ""),
    ("frames_dropped", "Frames dropped (real time)", ""),
    ("tracking_failures", "Frames whose tracking failed", ""),
    ("tracking_failed_longest_run", "Longest run of failed frames", ""),
    ("tracking_ended_tracked", "Run ended tracked", ""),
    ("tracking_recovered_frames", "Frames recovered after a failed try", ""),
    ("tracking_relocalisations", "Relocalisations (frame from keyframe frame)", ""),
    ("tracking_degenerate_frames", "Frames with a degenerate view", ""),
    ("peak_memory_mb", "Peak memory", "MB"),
    ("frames", "Frames", ""),
    ("device", "Device", ""),
)
"""Known metrics.json keys: (key, label, unit), in the order tables show them."""


def _shown(value: object) -> str:
    if isinstance(value, dict):
        return ", ".join(f"{key} {_shown(item)}" for key, item in value.items())
    if isinstance(value, list):  # relocalisations: {"frame": i, "keyframe": k}
        return f"{len(value)}" + "".join(
            f"; {item['frame']} from {item['keyframe']}" for item in value if isinstance(item, dict)
        )
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    if isinstance(value, int):
        return str(value)
    return f"{value:.3f}" if abs(value) < 100 else f"{value:.1f}"


def metrics_table(metrics: Mapping[str, object]) -> str:
    """A two-column markdown table of the known metrics present in ``metrics``."""
    lines = ["| metric | value |", "|---|---:|"]
    for key, label, unit in METRICS:
        if key in metrics:
            suffix = f" ({unit})" if unit else ""
            lines.append(f"| {label}{suffix} | {_shown(metrics[key])} |")
    return "\n".join(lines) + "\n"


def metrics_text(metrics: Mapping[str, object]) -> str:
    """The same metrics as aligned plain-text lines, for the terminal."""
    lines = []
    for key, label, unit in METRICS:
        if key in metrics:
            lines.append(f"  {label:<28} {_shown(metrics[key]):>10} {unit}".rstrip())
    return "\n".join(lines)


def titled_table(title: str, metrics: Mapping[str, object]) -> str:
    """A title line and one aligned ``name  value`` line per entry (any keys, in order).

    Example::

        ATE (se3 alignment)
          ate_rmse_cm     1.3470
          pairs           785
    """
    width = max((len(name) for name in metrics), default=0)
    lines = [title]
    for name, value in metrics.items():
        if isinstance(value, bool):
            shown = "yes" if value else "no"
        elif isinstance(value, float):
            shown = f"{value:.4f}"
        else:
            shown = str(value)
        lines.append(f"  {name:<{width}}  {shown}")
    return "\n".join(lines)


def write_report(
    path: str | Path,
    title: str,
    metrics: Mapping[str, object],
    settings: Sequence[str],
    images: Sequence[tuple[str, str]],
) -> None:
    """Write report.md (atomically).

    Args:
        path: the file to write.
        title: first heading (e.g. the run folder's name).
        metrics: the run's metrics.json contents.
        settings: bullet lines saying how the metrics were measured (protocol,
            sample counts, meshes compared).
        images: (caption, file name relative to the report) of each plot.
    """
    parts = [f"# {title}", "", metrics_table(metrics)]
    if settings:
        parts += ["## How these were measured", "", *[f"- {line}" for line in settings], ""]
    for caption, name in images:
        parts += [f"## {caption}", "", f"![{caption}]({name})", ""]
    write_text(path, "\n".join(parts).rstrip("\n") + "\n")
