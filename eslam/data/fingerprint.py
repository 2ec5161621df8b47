"""A fingerprint of a run's input, so a resumed run continues on the same frames.

A run folder records what its sequence looked like when the run started (frame count
after the frame selection, first and last colour/depth file names relative to the
sequence folder with their sizes, and the camera). ``eslam resume`` compares it with
the sequence it opens: a sequence that grew, shrank or holds other files would
continue a trajectory on frames it was not built from (or crash on a missing one), so
resume refuses it. Names are relative, so data that moved (``--data``) still matches.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from eslam.data.base import RGBDSequence


@dataclass(frozen=True)
class FileStamp:
    """One input file: its path relative to the sequence folder and its size in bytes."""

    name: str
    size: int


@dataclass(frozen=True)
class InputFingerprint:
    """What identifies a sequence cheaply (no image is read).

    Attributes:
        frames: number of frames (after data.start / stride / max_frames).
        camera: (width, height, fx, fy, cx, cy) of the frames the run sees.
        files: (colour, depth) of the first and of the last frame, in that order; empty
            for a reader whose frames are not files.
    """

    frames: int
    camera: tuple[float, ...]
    files: tuple[FileStamp, ...] = ()

    def to_dict(self) -> dict:
        """JSON-ready form (the run folder's input.json)."""
        return {
            "frames": self.frames,
            "camera": list(self.camera),
            "files": [dataclasses.asdict(stamp) for stamp in self.files],
        }

    @classmethod
    def from_dict(cls, data: dict) -> InputFingerprint:
        """Read :meth:`to_dict`'s form back.

        Raises:
            ValueError: a key is missing or has the wrong type.
        """
        try:
            return cls(
                frames=int(data["frames"]),
                camera=tuple(float(v) for v in data["camera"]),
                files=tuple(FileStamp(str(f["name"]), int(f["size"])) for f in data["files"]),
            )
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f"not an input fingerprint ({error!r})") from None


def _stamp(path: Path, root: Path) -> FileStamp:
    try:
        name = path.relative_to(root).as_posix()
    except ValueError:
        name = path.name
    if name == ".":  # a recording: the file holds every frame
        name = path.name
    try:
        size = path.stat().st_size
    except OSError:
        size = -1
    return FileStamp(name, size)


def fingerprint(sequence: RGBDSequence) -> InputFingerprint:
    """The fingerprint of ``sequence`` (file names, sizes and camera; no image is read)."""
    k = sequence.intrinsics
    camera = (float(k.width), float(k.height), k.fx, k.fy, k.cx, k.cy)
    files: tuple[FileStamp, ...] = ()
    frame_files = getattr(sequence, "frame_files", None)
    if len(sequence) > 0 and frame_files is not None:
        try:
            pairs = [frame_files(0), frame_files(len(sequence) - 1)]
        except AttributeError:  # a selection over a reader without files
            pairs = []
        root = Path(sequence.root)
        files = tuple(_stamp(Path(p), root) for pair in pairs for p in pair)
    return InputFingerprint(frames=len(sequence), camera=camera, files=files)


def differences(recorded: InputFingerprint, current: InputFingerprint) -> list[str]:
    """How ``current`` differs from ``recorded``, as short phrases (empty: the same input)."""
    found = []
    if current.frames != recorded.frames:
        change = "grew" if current.frames > recorded.frames else "shrank"
        found.append(f"it {change} from {recorded.frames} to {current.frames} frames")
    if current.camera != recorded.camera:
        found.append(
            "the camera changed from "
            f"{_camera_text(recorded.camera)} to {_camera_text(current.camera)}"
        )
    if recorded.files and current.files and current.files != recorded.files:
        for before, now in zip(recorded.files, current.files, strict=False):
            if before != now:
                found.append(f"{before.name} ({before.size} bytes) is now {now.name} "
                             f"({now.size} bytes)")  # fmt: skip
                break
    return found


def _camera_text(camera: tuple[float, ...]) -> str:
    width, height, fx, fy, cx, cy = camera
    return f"{width:g}x{height:g} fx={fx:g} fy={fy:g} cx={cx:g} cy={cy:g}"
