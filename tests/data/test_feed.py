"""The frame feeds: read-ahead (prefetch) and real-time newest-frame readers."""

from __future__ import annotations

import itertools
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from eslam.config import DataConfig
from eslam.data.feed import open_feed
from eslam.data.prefetch import PrefetchedFrames
from eslam.data.realtime import (
    LatestFrameReader,
    ReplayPace,
    timestamps_are_frame_numbers,
)
from eslam.data.source import IterableSource, SequenceSource
from eslam.errors import ConfigError, InputError
from eslam.types import Frame, Intrinsics

CAMERA = Intrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)


def frame(index: int, timestamp: float | None = None) -> Frame:
    """A 4x3 frame whose pixels hold its index."""
    rgb = np.full((3, 4, 3), index % 256, dtype=np.uint8)
    depth = np.full((3, 4), 1.0 + index, dtype=np.float32)
    return Frame(
        index, rgb, depth, CAMERA, timestamp=float(index if timestamp is None else timestamp)
    )


def no_feed_threads() -> bool:
    return not any(t.name in ("eslam-prefetch", "eslam-realtime") for t in threading.enumerate())


def test_prefetch_gives_the_same_frames_in_order_and_ends_its_thread() -> None:
    frames = [frame(i) for i in range(20)]
    with PrefetchedFrames(IterableSource(CAMERA, frames), depth=3) as feed:
        got = list(feed)
    assert [f.index for f in got] == list(range(20))
    assert all(a is b for a, b in zip(got, frames, strict=True))
    assert not feed.thread.is_alive()


def test_prefetch_reads_at_most_its_depth_ahead() -> None:
    produced = []

    def endless():
        for i in range(1000):
            produced.append(i)
            yield frame(i)

    with PrefetchedFrames(endless(), depth=3) as feed:
        next(feed)
        time.sleep(0.3)  # the thread fills the queue and must then wait
        ahead = len(produced)
    assert ahead <= 1 + 3 + 1  # handed over, queued, and the one waiting for room
    assert no_feed_threads()


def test_a_read_error_is_raised_in_the_loop_at_its_frame_with_the_file() -> None:
    bad = InputError(Path("/data/depth/000003.png"), "cannot be decoded", "replace the file")

    def frames():
        yield from (frame(i) for i in range(3))
        raise bad

    got = []
    with PrefetchedFrames(frames(), depth=8) as feed:
        with pytest.raises(InputError) as raised:
            for item in feed:
                got.append(item.index)
    assert got == [0, 1, 2]
    assert raised.value is bad and "000003.png" in str(raised.value)
    assert not feed.thread.is_alive()


def test_closing_early_stops_the_thread_and_closes_the_source() -> None:
    closed = threading.Event()

    def endless():
        try:
            i = 0
            while True:
                yield frame(i)
                i += 1
        finally:
            closed.set()

    with PrefetchedFrames(endless(), depth=2) as feed:
        assert next(feed).index == 0
    assert closed.is_set() and not feed.thread.is_alive()


def test_the_feed_follows_the_config() -> None:
    source = IterableSource(CAMERA, [frame(0)])
    off = open_feed(source, DataConfig(prefetch=0), "s")
    assert off.frames is source and off.stream is None
    assert isinstance(open_feed(source, DataConfig(prefetch=2), "s").frames, PrefetchedFrames)
    realtime = open_feed(source, DataConfig(realtime=True, replay_fps=30), "s")
    assert isinstance(realtime.frames, LatestFrameReader) and realtime.stream is realtime.frames
    live = open_feed(IterableSource(CAMERA, [frame(0)], live=True), DataConfig(), "cam")
    assert live.stream is not None  # a live camera is always real time
    with pytest.raises(ValueError, match="prefetch"):
        DataConfig(prefetch=-1)


def test_a_slow_loop_gets_the_newest_frames_never_reordered_and_counts_add_up() -> None:
    stream = [frame(i, timestamp=i / 1000.0) for i in range(60)]  # a 1000 fps recording
    got = []
    with LatestFrameReader(stream, ReplayPace(fps=None)) as reader:
        for item in reader:
            got.append(item.index)
            time.sleep(0.02)  # processing is 20x slower than the stream
    counts = reader.counts()
    assert got == reader.source_indices
    assert all(a < b for a, b in itertools.pairwise(got))  # never reordered
    assert counts.received == 60 and counts.delivered == len(got)
    assert counts.replaced == 60 - len(got) > 0  # dropped, keeping the newest
    assert got[-1] == 59  # the stream's last frame is never dropped when it ends
    assert counts.received_fps > 100
    assert no_feed_threads()


class CountingSequence:
    """A recording at 1000 fps that counts the frames read from it."""

    def __init__(self, length: int) -> None:
        self.length, self.reads = length, []
        self.intrinsics, self.root = CAMERA, Path("/rec")

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> Frame:
        self.reads.append(index)
        return frame(index, timestamp=self.timestamps()[index])

    def timestamps(self) -> np.ndarray:
        return 5.0 + np.arange(self.length) / 1000.0


def test_a_replayed_recording_reads_only_the_frames_the_loop_takes() -> None:
    sequence = CountingSequence(60)
    source = SequenceSource(sequence, start=10)  # type: ignore[arg-type]
    feed = open_feed(source, DataConfig(realtime=True), "rec")
    got = []
    with feed:
        for item in feed.frames:
            got.append((item.index, item.timestamp))
            time.sleep(0.02)  # 20x slower than the stream: most frames are dropped
    assert feed.stream is not None
    counts = feed.stream.counts()
    assert counts.received == 50 and counts.replaced == 50 - len(got) > 0
    # what a camera gives: a dropped frame was never read (decoded), a taken one once
    assert sequence.reads == [index for index, _ in got]
    # the newest frame is kept: the last always; the first is frame 10 (start=10) unless
    # the reader ran ahead of the loop's first take by a millisecond or more (a loaded
    # machine), when a later one replaced it
    assert got[-1][0] == 59 and 10 <= got[0][0] < 20
    assert [stamp for _, stamp in got] == [5.0 + index / 1000.0 for index, _ in got]
    assert [index - 10 for index, _ in got] == feed.stream.source_indices


def test_a_replay_keeps_the_recorded_rate() -> None:
    stream = [frame(i, timestamp=10.0 + 0.05 * i) for i in range(5)]  # 20 fps
    began = time.monotonic()
    with LatestFrameReader(stream, ReplayPace(fps=None)) as reader:
        got = [item.index for item in reader]
    elapsed = time.monotonic() - began
    assert got == [0, 1, 2, 3, 4]  # a fast loop drops nothing
    assert elapsed >= 0.2  # the last frame comes 4 / 20 s after the first
    assert ReplayPace(fps=10.0).offset_s(3, 99.0, 0.0) == pytest.approx(0.3)


def test_frame_number_timestamps_need_a_replay_rate() -> None:
    assert timestamps_are_frame_numbers(np.array([0.0, 1.0, 2.0]))
    assert not timestamps_are_frame_numbers(np.array([1305031102.175, 1305031102.211]))
    assert not timestamps_are_frame_numbers(np.array([3.0]))
    with LatestFrameReader([frame(0), frame(1)], ReplayPace(fps=None, name="rec")) as reader:
        with pytest.raises(ConfigError, match=r"rec.*replay_fps"):
            list(reader)


def test_a_real_time_read_error_comes_after_the_waiting_frame() -> None:
    bad = InputError(Path("/rec/colour/7.png"), "truncated", "record again")

    def frames():
        yield frame(0)
        raise bad

    with LatestFrameReader(frames()) as reader:
        time.sleep(0.1)  # the frame and the error are both waiting
        assert next(reader).index == 0
        with pytest.raises(InputError) as raised:
            next(reader)
    assert raised.value is bad
    assert no_feed_threads()


def test_a_live_realsense_camera_always_runs_in_real_time():
    from eslam.config import DataConfig
    from eslam.data.feed import runs_in_real_time
    from eslam.data.realsense import RealSenseCamera

    assert RealSenseCamera.live
    assert runs_in_real_time(RealSenseCamera, DataConfig(realtime=False))
