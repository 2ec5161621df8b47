"""Where a concurrent run's mapping calls run (``mapping.concurrent_worker``).

:class:`~eslam.slam.mapping.concurrent_mapping.ConcurrentBackEnd` hands each call to a
worker and takes its result back through a future. Two workers, one interface
(:class:`Worker`):

- :class:`ThreadWorker`: a thread of the run's process (on CUDA, on a stream of its own).
  The mapper and the tracker then share one Python interpreter, whose lock each holds
  for every tensor operation it issues: on a CPU, where these small operations cost
  their dispatch more than their arithmetic, each slows the other (docs/results.md,
  "Live: mapping beside the tracker").
- :class:`ProcessWorker`: a process of its own (CPU only). It starts at the first call
  as a fresh Python (not forked from the run's threads, and without running the user's
  script again as ``multiprocessing``'s spawn would: :data:`BOOTSTRAP`), in a session of
  its own, and holds its own copy of the run's mapper and a generator. Each call sends
  the working field, the window's views and poses, the flags, the schedule and the
  generator's state through a pipe. Tensors travel through shared memory
  (``torch.multiprocessing``'s pickling): the first time a tensor is sent its storage
  moves into shared memory, after that only a handle goes, so the process optimises
  the run's working field in place and the run reads it once the reply says the call
  is done (the back end never touches the working field while a call is in flight).
  The reply holds the call's result and the generator's state after it (the draws go
  on from there, as with a thread), or the call's error. The process ignores Ctrl-C
  and SIGTERM (the run decides what a stop waits for, as with a thread) and ends when
  the run closes the pipe, or when the run's process is gone.

``auto`` (the default) takes the process on a CPU and the thread on CUDA, where the
work is queued on the device and sharing a field across processes would need CUDA IPC.
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import subprocess
import sys
import traceback
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.reduction import ForkingPickler
from typing import Protocol

import torch
import torch.multiprocessing  # its reductions: ForkingPickler sends tensors by shared memory

from eslam.errors import ConfigError
from eslam.field.scene_field import SceneField
from eslam.slam.mapping.mapper import MappingResult, MappingSchedule
from eslam.slam.views import View

WORKERS = ("auto", "thread", "process")
"""Values of ``mapping.concurrent_worker``."""

THREAD_PREFIX = "eslam-mapping"
"""Name prefix of the threads a worker starts (none is left once it is closed)."""

BOOTSTRAP = (
    "import sys\n"
    "from multiprocessing.connection import Connection\n"
    "connection = Connection(int(sys.argv[1]))\n"
    "sys.path[:] = connection.recv()\n"
    "from eslam.slam.mapping.workers import serve\n"
    "serve(connection)\n"
)
"""The mapping process's program (``python -c``; its argument: its end of the pipe). Not
``multiprocessing``'s spawn, which runs the parent's main script again in the child (a
user's script without a ``__main__`` guard would start a second run)."""

STOPS = {signal.SIGINT, signal.SIGTERM}
"""Signals the mapping process ignores (held until it does)."""

POLL_S = 0.5
"""How often a wait for the mapping process checks that it is still alive (seconds)."""


class Mapper(Protocol):
    """What a worker runs: :class:`~eslam.slam.cuda_graphs.WindowMapper` or a stand-in."""

    def map(
        self,
        field: SceneField,
        views: list[View],
        poses: torch.Tensor,
        optimise: list[bool],
        schedule: MappingSchedule,
        generator: torch.Generator,
    ) -> MappingResult: ...


@dataclass(frozen=True, eq=False)
class MappingCall:
    """The arguments of one call of :meth:`Mapper.map` (the generator as its state)."""

    field: SceneField
    views: list[View]
    poses: torch.Tensor
    optimise: list[bool]
    schedule: MappingSchedule


class Worker(Protocol):
    """Runs mapping calls one at a time beside the run loop (module doc)."""

    kind: str

    def submit(self, call: MappingCall, generator: torch.Generator) -> Future[MappingResult]:
        """Start ``call`` with ``generator`` (advanced as the call draws); its result, or
        its error, comes back through the future."""
        ...

    def close(self) -> None:
        """Let the worker end (a call in flight finishes first); again is fine, and a
        later :meth:`submit` starts it again."""
        ...


def worker_kind(setting: str, device: torch.device) -> str:
    """The worker ``mapping.concurrent_worker`` = ``setting`` names on ``device``: auto is
    the process on a CPU and the thread elsewhere.

    Raises:
        ConfigError: an unknown setting, or the process asked for on a GPU.
    """
    if setting not in WORKERS:
        raise ConfigError(
            f"mapping.concurrent_worker must be one of {', '.join(WORKERS)}, got {setting!r}"
        )
    if setting == "auto":
        return "process" if device.type == "cpu" else "thread"
    if setting == "process" and device.type != "cpu":
        raise ConfigError(
            f"mapping.concurrent_worker=process maps on the CPU only (this run is on "
            f"{device.type}): set mapping.concurrent_worker=thread or auto"
        )
    return setting


def make_worker(kind: str, mapper: Mapper, device: torch.device) -> Worker:
    """A :class:`ThreadWorker` or :class:`ProcessWorker` (``kind`` from :func:`worker_kind`)."""
    if kind == "process":
        return ProcessWorker(mapper)
    return ThreadWorker(mapper, device)


class ThreadWorker:
    """One thread that runs mapping calls one at a time; on CUDA, on a stream of its own
    that first waits for the work the run loop's stream queued before the hand-over.

    Args:
        mapper: runs the calls (shared with the run's thread, which does not map meanwhile).
        device: the run's device.
    """

    kind = "thread"

    def __init__(self, mapper: Mapper, device: torch.device) -> None:
        self.mapper = mapper
        self.executor: ThreadPoolExecutor | None = None  # started with the first call
        self.stream = torch.cuda.Stream(device) if device.type == "cuda" else None

    def submit(self, call: MappingCall, generator: torch.Generator) -> Future[MappingResult]:
        ready = None
        if self.stream is not None:
            ready = torch.cuda.Event()
            ready.record()  # the views and poses the run loop's stream built for the call
        if self.executor is None:
            self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=THREAD_PREFIX)
        return self.executor.submit(self._run, call, generator, ready)

    def _run(
        self, call: MappingCall, generator: torch.Generator, ready: torch.cuda.Event | None
    ) -> MappingResult:
        def run() -> MappingResult:
            return self.mapper.map(
                call.field, call.views, call.poses, call.optimise, call.schedule, generator
            )

        if self.stream is None:
            return run()
        with torch.cuda.stream(self.stream):
            self.stream.wait_event(ready)
            result = run()
        self.stream.synchronize()
        return result

    def close(self) -> None:
        if self.executor is not None:
            self.executor.shutdown(wait=True)
            self.executor = None


class MappingProcessError(RuntimeError):
    """The mapping process ended without answering a call (killed, or out of memory)."""


@dataclass(frozen=True, eq=False)
class Reply:
    """The mapping process's answer to one call: the result and the generator's state
    after it, or the error (itself, or its traceback as text when it cannot be sent)."""

    result: MappingResult | None
    generator: torch.Tensor | None
    error: BaseException | None = None


class ProcessWorker:
    """Mapping calls in a process of their own (module doc).

    Args:
        mapper: sent to the process when it starts (so it must pickle: a
            :class:`~eslam.slam.cuda_graphs.WindowMapper` does).
    """

    kind = "process"

    def __init__(self, mapper: Mapper) -> None:
        self.mapper = mapper
        self.process: subprocess.Popen[bytes] | None = None  # started with the first call
        self.connection: Connection | None = None
        self.executor: ThreadPoolExecutor | None = None

    def _start(self) -> None:
        ours, theirs = multiprocessing.Pipe()
        command = [sys.executable, "-c", BOOTSTRAP, str(theirs.fileno())]
        # Ctrl-C and SIGTERM are held from the start (the mask is inherited) until the
        # process ignores them; in a session of its own a terminal's Ctrl-C misses it
        previous = signal.pthread_sigmask(signal.SIG_BLOCK, STOPS)
        try:
            process = subprocess.Popen(
                command, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                start_new_session=True,
            )  # fmt: skip
        except BaseException:
            ours.close()
            raise
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)
            theirs.close()
        try:
            ours.send(list(sys.path))  # it imports what this process imports
            # the key of this process's file-descriptor sharing (tensors sent both ways)
            ours.send((bytes(multiprocessing.current_process().authkey), torch.get_num_threads()))
            ours.send(self.mapper)
        except BaseException:
            process.kill()
            process.wait()
            ours.close()
            raise
        self.process, self.connection = process, ours
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=THREAD_PREFIX)

    def submit(self, call: MappingCall, generator: torch.Generator) -> Future[MappingResult]:
        if self.process is None:
            self._start()
        assert self.executor is not None
        # pickled here, in the run's thread: tensors move to shared memory while nothing
        # else reads them
        message = bytes(ForkingPickler.dumps((call, generator.get_state())))
        return self.executor.submit(self._exchange, message, generator)

    def _exchange(self, message: bytes, generator: torch.Generator) -> MappingResult:
        connection, process = self.connection, self.process
        assert connection is not None and process is not None
        try:
            connection.send_bytes(message)
            while not connection.poll(POLL_S):
                if process.poll() is not None:
                    raise EOFError
            reply: Reply = connection.recv()
        except (EOFError, OSError) as error:
            try:
                process.wait(timeout=5.0)  # its exit code
            except subprocess.TimeoutExpired:
                pass
            raise MappingProcessError(
                f"the mapping process ended (exit code {process.returncode}) during a call"
            ) from error
        if reply.error is not None:
            raise reply.error
        assert reply.result is not None and reply.generator is not None
        generator.set_state(reply.generator)
        return reply.result

    def close(self) -> None:
        executor, process, connection = self.executor, self.process, self.connection
        self.executor = self.process = self.connection = None
        if executor is not None:
            executor.shutdown(wait=True)  # the call in flight is answered first
        if connection is not None:
            try:
                connection.send_bytes(b"")  # nothing more to map
            except OSError:
                pass
            connection.close()
        if process is not None:
            try:
                process.wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def serve(connection: Connection) -> None:
    """The mapping process (:data:`BOOTSTRAP` set its ``sys.path``): take the run's key
    and thread count, then the mapper, then answer calls until the pipe says stop or
    closes."""
    for stop in STOPS:  # the run decides when to stop
        signal.signal(stop, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)
    authkey, threads = connection.recv()
    multiprocessing.current_process().authkey = authkey
    mapper: Mapper = connection.recv()
    torch.set_num_threads(threads)
    generator = torch.Generator()
    while True:
        try:
            message = connection.recv_bytes()
        except (EOFError, OSError):
            return  # the run's process is gone
        if not message:
            return
        reply = answer(message, mapper, generator)
        try:
            connection.send(reply)
        except (OSError, ValueError):
            return


def answer(message: bytes, mapper: Mapper, generator: torch.Generator) -> Reply:
    """One call's :class:`Reply` (its error when it fails: sent as is when it pickles,
    else as its traceback's text)."""
    try:
        call, state = ForkingPickler.loads(message)
        generator.set_state(state)
        result = mapper.map(
            call.field, call.views, call.poses, call.optimise, call.schedule, generator
        )
        return Reply(result, generator.get_state())
    except Exception as error:
        try:
            pickle.dumps(error)
        except Exception:
            error = RuntimeError("".join(traceback.format_exception(error)))
        return Reply(None, None, error)
