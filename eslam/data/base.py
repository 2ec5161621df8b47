"""The sequence protocol every reader implements, and the input checks they share.

Readers convert their dataset's conventions at this boundary: what leaves a reader is
a :class:`~eslam.types.Frame` with depth in metres (0 = invalid) and camera-to-world
poses in OpenCV axes. Anything wrong with the input raises
:class:`~eslam.errors.InputError` naming the file and the fix. Pose files are parsed and
poses checked rigid by :mod:`eslam.io.pose_files`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
from PIL import Image, UnidentifiedImageError

from eslam.data.depth_units import (
    COMMON_DEPTH_SCALES,
    DEPTH_MEDIAN_RANGE_M,
    check_depth_units,
)
from eslam.data.transform import ImageTransform
from eslam.errors import InputError
from eslam.types import Frame, Intrinsics


@runtime_checkable
class RGBDSequence(Protocol):
    """A finite, indexable sequence of RGB-D frames.

    Attributes:
        root: the folder the sequence was read from.
        intrinsics: intrinsics shared by every frame (after the reader's resize/crop).
    """

    root: Path
    intrinsics: Intrinsics

    def __len__(self) -> int:
        """Number of frames."""
        ...

    def __getitem__(self, index: int) -> Frame:
        """Frame ``index`` (0-based); reads its images from disk."""
        ...

    def gt_poses(self) -> np.ndarray | None:
        """(N, 4, 4) float64 ground-truth camera-to-world poses, or None without ground truth.

        A frame whose ground truth is missing or unusable (ScanNet's non-finite poses)
        has a NaN matrix: such frames are kept out of initialisation and evaluation.
        """
        ...

    def timestamps(self) -> np.ndarray:
        """(N,) float64 timestamps, seconds (the frame numbers where the dataset has none)."""
        ...


def iterate_frames(sequence: RGBDSequence) -> Iterator[Frame]:
    """Yield every frame of ``sequence`` in order."""
    for index in range(len(sequence)):
        yield sequence[index]


def require_dir(path: Path, what: str) -> Path:
    """Return ``path`` if it is a folder, else raise an InputError saying what it should hold."""
    if not path.exists():
        raise InputError(path, f"folder not found (expected {what})", "check the --data path")
    if not path.is_dir():
        raise InputError(path, f"is not a folder (expected {what})")
    return path


def require_file(path: Path, what: str) -> Path:
    """Return ``path`` if it is a file, else raise an InputError naming ``what`` it should hold."""
    if not path.is_file():
        raise InputError(path, f"file not found (expected {what})")
    return path


WIDE_GREY_MODES = ("I;16", "I;16L", "I;16B", "I")
"""Pillow's modes of one-channel images wider than 8 bits (16-bit grey PNGs): Pillow's own
``convert("RGB")`` clips them at 255, which turned a 16-bit grey image all white."""


def read_rgb(path: Path) -> np.ndarray:
    """Read a colour image as (H, W, 3) uint8.

    Grey images are replicated to three channels, RGBA and palette images converted,
    16-bit grey images scaled to 8 bits (value * 255 / 65535, rounded); 16-bit RGB PNGs
    Pillow already reads as 8-bit RGB. A floating-point or 32-bit image has no agreed
    colour range: it is refused rather than guessed.
    """
    try:
        with Image.open(path) as image:
            if image.mode in WIDE_GREY_MODES:
                return _grey16_to_rgb(path, np.asarray(image))
            if image.mode not in ("1", "L", "LA", "P", "PA", "RGB", "RGBA", "RGBX", "CMYK"):
                raise InputError(
                    path,
                    f"colour image has pixel mode {image.mode}, which holds no 8- or 16-bit colour",
                    "save colour as an 8-bit RGB (or grey) PNG or JPEG",
                )
            return np.asarray(image.convert("RGB"), dtype=np.uint8).copy()
    except FileNotFoundError:
        raise InputError(path, "colour image not found") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as error:
        raise InputError(
            path, f"unreadable colour image ({error})", "re-export the image"
        ) from None


def _grey16_to_rgb(path: Path, grey: np.ndarray) -> np.ndarray:
    """(H, W) 16-bit grey -> (H, W, 3) uint8, 65535 -> 255 (refused beyond 16 bits)."""
    wide = grey.astype(np.int64)
    if wide.size and (wide.min() < 0 or wide.max() > 65535):
        raise InputError(
            path,
            f"colour image holds values {wide.min()}..{wide.max()}, outside 16 bits",
            "save colour as an 8-bit RGB PNG or JPEG",
        )
    eight = ((wide * 255 + 32767) // 65535).astype(np.uint8)
    return np.repeat(eight[:, :, None], 3, axis=2)


def read_depth(path: Path, depth_scale: float) -> np.ndarray:
    """Read a 16-bit depth PNG and convert it to metres: depth = value / depth_scale.

    Returns:
        (H, W) float32 metres, 0 where the file holds 0 (invalid).
    """
    try:
        with Image.open(path) as image:
            raw = np.asarray(image)
    except FileNotFoundError:
        raise InputError(path, "depth image not found") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as error:
        raise InputError(path, f"unreadable depth image ({error})", "re-export the image") from None
    if raw.ndim != 2 or raw.dtype.kind not in "ui":
        raise InputError(
            path,
            f"depth must be a single-channel integer image, got shape {raw.shape} {raw.dtype}",
            "save depth as a 16-bit PNG",
        )
    return (raw.astype(np.float32) / np.float32(depth_scale)).astype(np.float32)


def check_image_size(path: Path, shape: tuple[int, ...], intrinsics: Intrinsics) -> None:
    """Raise if an image of ``shape`` does not match the intrinsics' size."""
    height, width = shape[:2]
    if (width, height) != intrinsics.size:
        raise InputError(
            path,
            f"image is {width}x{height} but the intrinsics are for "
            f"{intrinsics.width}x{intrinsics.height}",
            "fix the camera parameters or the image size",
        )


ImagePreparation = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
"""(rgb, depth metres) -> (rgb, depth metres) at the raw camera, e.g. TUM's undistortion."""


@dataclass(frozen=True, eq=False)
class FrameReading:
    """How a reader turns one colour + depth file pair into a :class:`Frame`.

    Every reader's frames go through :meth:`read`, so the checks (image sizes, depth
    units), the invalid-depth rule and the resize/crop are the same for all layouts.

    Attributes:
        raw_intrinsics: the camera of the files as stored.
        depth_scale: depth PNG units per metre.
        transform: resize + crop applied last (intrinsics follow: :attr:`intrinsics`).
        invalid_depth: a raw depth value meaning "no depth" besides 0 (7-Scenes: 65535).
        colour_any_size: resize colour to the depth size instead of requiring it
            (ScanNet's colour is 1296x968, its depth 640x480).
        prepare: applied to (rgb, depth) at the raw camera before the transform.
    """

    raw_intrinsics: Intrinsics
    depth_scale: float
    transform: ImageTransform = field(default_factory=ImageTransform)
    invalid_depth: int | None = None
    colour_any_size: bool = False
    prepare: ImagePreparation | None = None

    @property
    def intrinsics(self) -> Intrinsics:
        """The camera of the frames :meth:`read` returns."""
        return self.transform.intrinsics(self.raw_intrinsics)

    def read(
        self,
        index: int,
        files: tuple[Path, Path],
        pose: np.ndarray | None,
        timestamp: float,
    ) -> Frame:
        """Read, check and transform one frame.

        Args:
            index: the frame's position in its sequence.
            files: its (colour, depth) images.
            pose: (4, 4) ground-truth camera-to-world, or None / a NaN matrix for none.
            timestamp: seconds, or the frame number.

        Raises:
            InputError: unreadable image, wrong size, or depth that cannot be metres.
        """
        colour_path, depth_path = files
        rgb = read_rgb(colour_path)
        units = read_depth(depth_path, 1.0)
        return self.build(index, (rgb, units), pose, timestamp, files)

    def build(
        self,
        index: int,
        images: tuple[np.ndarray, np.ndarray],
        pose: np.ndarray | None,
        timestamp: float,
        where: tuple[str | Path, str | Path],
    ) -> Frame:
        """Check and transform one frame's decoded images (files or recorded messages).

        Args:
            index: the frame's position in its sequence.
            images: (H, W, 3) uint8 colour and (H, W) float32 depth in file units
                (metres = units / depth_scale, 0 = invalid).
            pose: (4, 4) ground-truth camera-to-world, or None / a NaN matrix for none.
            timestamp: seconds, or the frame number.
            where: what to name in errors about the colour and the depth image.

        Raises:
            InputError: wrong size, or depth that cannot be metres.
        """
        rgb, units = images
        colour_path, depth_path = Path(where[0]), Path(where[1])
        raw = self.raw_intrinsics
        if self.colour_any_size:
            rgb = ImageTransform(raw.size).colour(rgb)
        else:
            check_image_size(colour_path, rgb.shape, raw)
        check_image_size(depth_path, units.shape, raw)
        if self.invalid_depth is not None:
            units[units == self.invalid_depth] = 0.0
        depth = units / np.float32(self.depth_scale)
        check_depth_units(depth, depth_path, self.depth_scale)
        if self.prepare is not None:
            rgb, depth = self.prepare(rgb, depth)
        usable = pose is not None and bool(np.isfinite(pose).all())
        return Frame(
            index=index,
            rgb=self.transform.colour(rgb),
            depth=self.transform.depth(depth),
            intrinsics=self.intrinsics,
            pose_gt=np.array(pose, dtype=np.float64) if usable else None,
            timestamp=float(timestamp),
        )


class FileSequence:
    """Base of the readers whose frames are (colour, depth) image files on disk.

    A subclass's ``__init__`` finds the files and sets :attr:`reading` and the four
    per-frame lists below (all in frame order, one entry per frame); this class then
    implements :class:`RGBDSequence` on them, so every reader indexes, reads and
    reports poses and time stamps the same way.

    Attributes:
        reading: how one file pair becomes a checked, transformed :class:`Frame`.
        _colour_paths, _depth_paths: the frames' image files.
        _poses: (N, 4, 4) float64 camera-to-world ground truth (a NaN matrix for a
            frame without one), or None when the sequence has none.
        _times: (N,) float64 time stamps in seconds, or frame numbers where the
            dataset has no time stamps.
    """

    reading: FrameReading
    _colour_paths: list[Path]
    _depth_paths: list[Path]
    _poses: np.ndarray | None
    _times: np.ndarray

    def __len__(self) -> int:
        return len(self._colour_paths)

    def __getitem__(self, index: int) -> Frame:
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} out of range for {len(self)} frames")
        files = (self._colour_paths[index], self._depth_paths[index])
        pose = None if self._poses is None else self._poses[index]
        return self.reading.read(index, files, pose, self._times[index])

    def depth_path(self, index: int) -> Path:
        """The depth image of frame ``index`` (named in depth-unit errors)."""
        return self._depth_paths[index]

    def gt_poses(self) -> np.ndarray | None:
        """(N, 4, 4) float64 camera-to-world poses (NaN where a frame has none), or None."""
        return None if self._poses is None else self._poses.copy()

    def timestamps(self) -> np.ndarray:
        """(N,) float64 seconds, or the frame numbers where the dataset has no time stamps."""
        return self._times.copy()

    def frame_files(self, index: int) -> tuple[Path, Path]:
        """The (colour, depth) files of frame ``index``, e.g. to fingerprint the input."""
        return self._colour_paths[index], self._depth_paths[index]


__all__ = [
    "COMMON_DEPTH_SCALES",
    "DEPTH_MEDIAN_RANGE_M",
    "FileSequence",
    "FrameReading",
    "RGBDSequence",
    "check_depth_units",
    "check_image_size",
    "iterate_frames",
    "read_depth",
    "read_rgb",
    "require_dir",
    "require_file",
]
