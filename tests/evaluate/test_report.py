"""report.md layout."""

from __future__ import annotations

from pathlib import Path

from eslam.evaluate.report import metrics_table, metrics_text, write_report


def test_table_orders_and_labels_known_metrics() -> None:
    table = metrics_table({"f1_pct": 88.25, "ate_rmse_cm": 0.6312, "frames": 60, "other": 1})
    lines = table.splitlines()
    assert lines[2] == "| ATE RMSE (cm) | 0.631 |"
    assert lines[3] == "| F1 (< 1 cm) (%) | 88.250 |"
    assert lines[4] == "| Frames | 60 |"
    assert "other" not in table
    assert "ATE RMSE" in metrics_text({"ate_rmse_cm": 0.63})


def test_table_shows_the_tracker_s_own_judgement() -> None:
    judged = metrics_table({"tracking_failures": 0, "tracking_degenerate_frames": 157})
    assert "| Frames whose tracking failed | 0 |" in judged
    assert "| Frames with a degenerate view | 157 |" in judged


def test_report_holds_table_settings_and_images(tmp_path: Path) -> None:
    path = tmp_path / "report.md"
    write_report(
        path, "run", {"ate_rmse_cm": 1.0}, ["ESLAM culling"], [("Trajectory", "trajectory.png")]
    )
    text = path.read_text()
    assert text.startswith("# run\n")
    assert "| ATE RMSE (cm) | 1.000 |" in text
    assert "- ESLAM culling" in text
    assert "![Trajectory](trajectory.png)" in text
