"""SIGTERM and Ctrl-C stop a command the same way, and neither is lost.

Python raises a signal handler's exception wherever the main thread is when it runs the
handler; when that is a weakref callback or a ``__del__`` (the import system's module
locks have one; the garbage collector runs others at any allocation), the exception is
printed as "Exception ignored" and the command goes on as if no signal came. While a
command runs, :func:`stops_as_interrupt` makes SIGTERM raise ``KeyboardInterrupt`` (runs
save their frames, as on Ctrl-C) and hands a swallowed ``KeyboardInterrupt`` back:
``sys.unraisablehook`` receives it and a timer thread trips the SIGTERM handler again a
moment later, which Python runs in the main thread at its next check, outside the
callback (tripped from the main thread itself, the handler would run inside the hook,
where its exception is swallowed too). A block that ends with an interrupt still on its
way raises it at its end.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import NoReturn

__all__ = ["stops_as_interrupt"]

_REDELIVERY_DELAY_S = 0.02
"""How long after a swallowed interrupt the SIGTERM handler is tripped again: long
enough for the main thread to leave the callback, short against any frame."""


class _Redelivery:
    """The unraisable-exception hook of :func:`stops_as_interrupt`: a swallowed
    ``KeyboardInterrupt`` is raised again in the main thread; anything else goes on to
    the hook that was there before."""

    def __init__(self, previous) -> None:
        self.previous = previous
        self.pending = False

    def __call__(self, args) -> None:
        if isinstance(args.exc_value, KeyboardInterrupt):
            self.pending = True
            timer = threading.Timer(_REDELIVERY_DELAY_S, _thread.interrupt_main, (signal.SIGTERM,))
            timer.daemon = True
            timer.start()
            return
        self.previous(args)


def _raise_interrupt(signum: int, frame: object) -> NoReturn:
    raise KeyboardInterrupt


@contextmanager
def stops_as_interrupt() -> Iterator[None]:
    """Within the block SIGTERM raises ``KeyboardInterrupt`` in the main thread and a
    ``KeyboardInterrupt`` swallowed by a callback is raised again (module doc); the
    handler and hook are restored after. Outside the main thread (signals cannot be set
    there) nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous_handler = signal.signal(signal.SIGTERM, _raise_interrupt)
    previous_hook = sys.unraisablehook
    redelivery = _Redelivery(previous_hook)
    sys.unraisablehook = redelivery
    try:
        yield
        if redelivery.pending:
            raise KeyboardInterrupt  # the block ended before the interrupt came back
    except KeyboardInterrupt:
        redelivery.pending = False
        raise
    finally:
        sys.unraisablehook = previous_hook
        signal.signal(signal.SIGTERM, previous_handler)
