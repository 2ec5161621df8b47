"""What a stopped run raises: every stop a user can cause names `eslam resume RUN`."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from eslam.errors import InputError, RunInterrupted, RunStopped
from eslam.slam.run.observers import Observers, RunObserverBase
from eslam.slam.run.stops import interrupted_early, save_on_failure, stopped_error

RUN = Path("runs/room0")


@pytest.mark.parametrize("frames", [0, 7])
@pytest.mark.parametrize(
    "error",
    [
        InputError("results/depth000007.png", "unreadable depth image"),
        OSError(28, "No space left on device"),
        MemoryError(),
    ],
)
def test_a_stop_a_user_can_cause_names_resume(error: BaseException, frames: int) -> None:
    stopped = stopped_error(error, frames, RUN)
    assert isinstance(stopped, RunStopped)
    message = str(stopped)
    assert "\n" not in message and message.endswith(f"continue with `eslam resume {RUN}`)")
    if frames == 0:
        assert "stopped before its first frame was complete" in message
    else:
        assert f"stopped after 7 frames, saved in {RUN}" in message


@pytest.mark.parametrize("frames", [0, 3])
def test_an_interruption_names_resume(frames: int) -> None:
    stopped = stopped_error(KeyboardInterrupt(), frames, RUN)
    assert isinstance(stopped, RunInterrupted)
    assert f"(continue with `eslam resume {RUN}`)" in str(stopped)
    already = RunInterrupted(2, RUN)
    assert stopped_error(already, 5, RUN) is already


def test_a_bug_keeps_its_traceback_with_a_note() -> None:
    bug = ZeroDivisionError("division by zero")
    assert stopped_error(bug, 4, RUN) is bug
    assert bug.__notes__ == [
        f"eslam: 4 completed frames are saved in {RUN} (continue with `eslam resume {RUN}`)"
    ]


class FullDisk(RunObserverBase):
    def on_failure(self, error: BaseException, frames: int) -> None:
        raise OSError(28, "No space left on device")


def test_a_failing_save_never_hides_the_error(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("eslam.test_stops")
    with caplog.at_level(logging.ERROR, logger="eslam.test_stops"):
        save_on_failure(Observers([FullDisk()]), KeyboardInterrupt(), 5, logger)
    assert "could not save the completed frames: OSError" in caplog.text


def test_an_interruption_while_the_folder_opens(tmp_path: Path) -> None:
    interrupt = KeyboardInterrupt()
    # no config.yaml yet: no run folder exists, nothing to resume
    assert interrupted_early(interrupt, tmp_path, resume=False) is interrupt
    (tmp_path / "config.yaml").write_text("run")
    fresh = interrupted_early(interrupt, tmp_path, resume=False)
    assert "before the first frame was complete" in str(fresh)
    resumed = interrupted_early(interrupt, tmp_path, resume=True)
    assert str(resumed) == (
        f"interrupted before resuming, its saved frames in {tmp_path} unchanged "
        f"(continue with `eslam resume {tmp_path}`)"
    )
