"""A stop signal that lands in a callback is not lost (eslam.cli.interrupts)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

_SCRIPT = textwrap.dedent(
    """
    import gc, os, signal, sys, time, weakref
    from eslam.cli.interrupts import stops_as_interrupt

    class Held:
        pass

    def swallowed(_):
        # the SIGTERM handler runs here, as it did in an import lock's callback
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)  # the handler runs inside this callback
        raise AssertionError("the SIGTERM handler did not run in the callback")

    outcome = "went on"
    try:
        with stops_as_interrupt():
            held = Held()
            ref = weakref.ref(held, swallowed)
            del held  # the callback raises KeyboardInterrupt: Python swallows it there
            for _ in range(200):
                time.sleep(0.005)  # the command goes on; the interrupt must come back
    except KeyboardInterrupt:
        outcome = "interrupted"
    print(outcome)
    # outside the block the hook and the SIGTERM handler are the previous ones again
    handler = signal.getsignal(signal.SIGTERM)
    print(sys.unraisablehook is sys.__unraisablehook__, handler == signal.SIG_DFL)
    """
)


def _python(code: str) -> subprocess.CompletedProcess:
    """``code`` run by this Python in the repository root."""
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parents[1],
    )


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_sigterm_swallowed_by_a_callback_still_stops_the_command() -> None:
    done = _python(_SCRIPT)
    assert done.returncode == 0, done.stderr
    outcome, restored = done.stdout.split("\n")[:2]
    assert outcome == "interrupted"
    assert restored == "True True"
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_other_unraisable_errors_are_still_reported() -> None:
    code = textwrap.dedent(
        """
        import weakref
        from eslam.cli.interrupts import stops_as_interrupt

        class Held:
            pass

        def broken(_):
            raise ValueError("a callback's own error")

        with stops_as_interrupt():
            held = Held()
            ref = weakref.ref(held, broken)
            del held
        print("went on")
        """
    )
    done = _python(code)
    assert done.stdout.strip() == "went on"
    assert "ValueError: a callback's own error" in done.stderr
