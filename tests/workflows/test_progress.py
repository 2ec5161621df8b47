"""Stage bars of an evaluation (eslam eval, the end of eslam demo)."""

from __future__ import annotations

import io

import pytest

from eslam.workflows.progress import StageProgress


def test_a_stage_shows_its_count_and_closes_on_success_and_failure() -> None:
    out = io.StringIO()
    progress = StageProgress(True, out)
    with progress.stage("depth L1", 4, "view") as advance:
        for done in range(1, 5):
            advance(done)
    with progress.stage("accuracy and completion"):
        pass
    with pytest.raises(ValueError), progress.stage("cull mesh.ply", 10, "frame") as advance:
        advance(3)
        raise ValueError("unreadable")
    text = out.getvalue()
    assert "depth L1" in text and "4/4" in text and "accuracy and completion" in text
    assert "1/1" in text and "3/10" in text and text.endswith("\n")


def test_off_means_silent() -> None:
    out = io.StringIO()
    with StageProgress(False, out).stage("depth L1", 4) as advance:
        advance(2)
    assert out.getvalue() == ""
