"""Motion blur in a finished run: how blurred its frames are, and what that costs.

A turning camera blurs its colour images. This measures each frame's sharpness as the
run read it, the ground truth's turn rate into it (degrees per second), and the run's
relative pose error into it (``eslam.evaluate.trajectory.pair_errors``, delta 1), then
prints (markdown):

- the rank correlation (Spearman) of sharpness with the turn rate and with the error;
- the frames split into thirds by sharpness: the turn rate and the error in each;
- the keyframes (the run's map.pt) split into blurred and sharp (:func:`is_blurred`):
  the error of the step into the keyframe and of the step after it (the first frame
  tracked on the map the keyframe changed).

Sharpness is the variance of the image's Laplacian (Pech-Pacheco et al., "Diatom
autofocusing in brightfield microscopy", ICPR 2000), on the grey image I in [0, 1]:

    s = Var( d2I/dx2 + d2I/dy2 )

(OpenCV's 3x3 aperture). Its scale depends on the scene's texture, so a frame is judged
against the frames just before it: blurred when s < r * median(s of the HISTORY frames
before it), r = ``--ratio``. The same rule deferring keyframes from blurred frames
(``mapping.blur_defer``, commit 83f894a) did not help: docs/results.md, "What we tried".

No SLAM runs here.

    python benchmarks/motion_blur.py RUN_DIR [--data SEQUENCE] [--ratio 0.7]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import spearmanr

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.errors import ConfigError, InputError
from eslam.evaluate.trajectory import pair_errors
from eslam.io.checkpoint import load_checkpoint
from eslam.io.trajectory import read_run_trajectories

HISTORY = 15
"""Frames whose sharpness makes a frame's reference (half a second at 30 Hz)."""
MIN_HISTORY = 3
"""Frames known before any frame is judged blurred."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", type=Path, help="a finished run folder with ground truth")
    parser.add_argument("--data", type=Path, help="the sequence (default: the run's)")
    parser.add_argument("--ratio", type=float, default=0.7, help="blurred below this share")
    return parser.parse_args(argv)


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


def turn_rates(truth: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(N-1,) degrees per second the ground truth turns from frame i to i + 1."""
    motion = np.linalg.inv(truth[:-1]) @ truth[1:]
    cosine = np.clip((np.trace(motion[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    return np.degrees(np.arccos(cosine)) / np.maximum(np.diff(times), 1e-9)


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else float("nan")


def blurred_frames(sharpness: np.ndarray, ratio: float) -> np.ndarray:
    """Per frame, whether it is blurred against the :data:`HISTORY` frames before it."""
    return np.array(
        [
            is_blurred(float(s), sharpness[max(0, i - HISTORY) : i].tolist(), ratio)
            for i, s in enumerate(sharpness)
        ]
    )


def report(
    sharpness: np.ndarray,
    truth: np.ndarray,
    estimate: np.ndarray,
    times: np.ndarray,
    keyframes: list[int],
    ratio: float,
) -> list[str]:
    """The markdown lines (module doc) for one run's frames."""
    errors = pair_errors(estimate, truth)
    into = errors.first + 1  # the frame each step leads into
    turn = turn_rates(truth, times)[errors.first]
    step_mm = 1000 * errors.translation
    sharp_into = sharpness[into]
    lines = [
        f"- {len(sharpness)} frames; Spearman rank correlation of sharpness with the "
        f"ground truth's turn rate {spearmanr(sharp_into, turn)[0]:+.2f}, with the "
        f"translation RPE into the frame {spearmanr(sharp_into, step_mm)[0]:+.2f}",
        "",
        "| frames by sharpness | frames | turn rate (deg/s, median) | RPE into them |",
        "|---|---:|---:|---:|",
    ]
    order = np.argsort(sharp_into)
    for name, part in zip(
        ("blurriest third", "middle third", "sharpest third"),
        np.array_split(order, 3),
        strict=True,
    ):
        lines.append(
            f"| {name} | {len(part)} | {np.median(turn[part]):.1f} | "
            f"{rms(step_mm[part]):.2f} mm / {rms(errors.rotation[part]):.3f} deg |"
        )
    blurred = blurred_frames(sharpness, ratio)
    step_of = {int(frame): k for k, frame in enumerate(into)}
    lines += [
        "",
        f"| keyframes (blurred: below {ratio:g} of the median of the {HISTORY} frames "
        "before) | keyframes | RPE into the keyframe | RPE of the step after it |",
        "|---|---:|---:|---:|",
    ]
    for name, chosen in (("blurred", True), ("sharp", False)):
        frames = [k for k in keyframes if bool(blurred[k]) == chosen and k in step_of]
        at = [step_of[k] for k in frames]
        after = [step_of[k + 1] for k in frames if k + 1 in step_of]
        lines.append(
            f"| {name} | {len(frames)} | {rms(step_mm[at]):.2f} mm | {rms(step_mm[after]):.2f} mm |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    run = args.run
    try:
        times, estimate, truth = read_run_trajectories(run, "config.yaml", "map.pt")
        overrides = [] if args.data is None else [f"data.path={args.data}"]
        config = load_config(run / "config.yaml", overrides)
        sequence = open_sequence(config.data)
    except (InputError, ConfigError) as error:
        print(f"motion_blur.py: {error}", file=sys.stderr)
        return 2
    count = len(estimate)
    if count > len(sequence) or not np.allclose(times, sequence.timestamps()[:count]):
        print(
            f"motion_blur.py: {run}: its frames are not the sequence's first {count}; "
            "give the run's sequence with --data",
            file=sys.stderr,
        )
        return 2
    sharpness = np.array([image_sharpness(sequence[i].rgb) for i in range(count)])
    keyframes = [int(i) for i in load_checkpoint(run / "map.pt")["keyframes"]["frame_indices"]]
    print(f"## motion_blur: {run}")
    print("")
    print("\n".join(report(sharpness, truth, estimate, times, keyframes, args.ratio)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
