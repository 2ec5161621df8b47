"""Keyframes taken from sharp frames: a keyframe due on a blurred frame waits for a sharp one.

A turning hand-held camera blurs its colour images (on TUM fr1/xyz the image sharpness
below falls as the angular velocity rises). A keyframe's colour is fitted into the map
and, in the joint optimisation, pulls on the keyframe's pose, so a blurred keyframe
spreads its blur into both (docs/results.md, "TUM RGB-D fr1/xyz": the step into the
frame after a blurred keyframe). With ``mapping.blur_defer`` = d > 0 a keyframe that
falls due (``mapping.every``) on a blurred frame waits for the next frame that is not
blurred, at most d frames; the frames after keep the fixed interval.

Sharpness is the variance of the image's Laplacian (Pech-Pacheco et al., "Diatom
autofocusing in brightfield microscopy", ICPR 2000), on the grey image:

    s = Var( d2I/dx2 + d2I/dy2 ),        I = grey level in [0, 1]

(OpenCV's 3x3 Laplacian aperture). Its scale depends on the scene's texture, so a frame
is judged against the frames just before it: blurred when

    s < r * median(s of the last HISTORY frames before it)

with r = ``mapping.blur_ratio``. Until MIN_HISTORY frames are known nothing is blurred.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

HISTORY = 15
"""Frames whose sharpness makes the reference (half a second at 30 Hz)."""
MIN_HISTORY = 3
"""Frames known before any frame is judged blurred."""


def image_sharpness(rgb: np.ndarray) -> float:
    """Variance of the Laplacian of ``rgb``'s grey image (module doc): (H, W, 3) uint8."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) colour image, got shape {rgb.shape}")
    grey = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
    return float(cv2.Laplacian(grey, cv2.CV_32F, ksize=1).var())


def is_blurred(sharpness: float, history: list[float], ratio: float) -> bool:
    """Whether ``sharpness`` is below ``ratio`` times the median of ``history`` (the
    frames before it; never with fewer than :data:`MIN_HISTORY`)."""
    if len(history) < MIN_HISTORY:
        return False
    return sharpness < ratio * float(np.median(history))


@dataclass(frozen=True)
class BlurDeferral:
    """When a due keyframe is taken (module doc); its state lives in the back end's
    component dict (``sharpness``: the recent frames', ``waited``: frames a due keyframe
    has waited so far, absent when none is due).

    Attributes:
        defer: the most frames a due keyframe waits (0 = never: the fixed interval).
        ratio: a frame is blurred below this share of the recent median sharpness.
    """

    defer: int
    ratio: float

    def __post_init__(self) -> None:
        if self.defer < 0:
            raise ValueError(f"blur_defer must be >= 0, got {self.defer}")
        if not 0 < self.ratio <= 1:
            raise ValueError(f"blur_ratio must be in (0, 1], got {self.ratio}")

    def take(self, due: bool, rgb: np.ndarray | None, own: dict) -> bool:
        """Whether a frame becomes a keyframe now.

        Args:
            due: the schedule makes this frame a keyframe (``mapping.every``).
            rgb: the frame's colour; None for a frame that cannot be one (failed, no
                depth): a due keyframe then waits on, its wait counted.
            own: the back end's state dict, updated.
        """
        if self.defer == 0:
            return due and rgb is not None
        due = due or "waited" in own
        if rgb is None:
            if due:
                own["waited"] = int(own.get("waited", 0)) + 1
            return False
        history = [float(s) for s in own.get("sharpness", [])]
        sharpness = image_sharpness(rgb)
        own["sharpness"] = [*history, sharpness][-HISTORY:]
        if not due:
            return False
        waited = int(own.get("waited", 0))
        if waited < self.defer and is_blurred(sharpness, history, self.ratio):
            own["waited"] = waited + 1
            return False
        own.pop("waited", None)
        return True
