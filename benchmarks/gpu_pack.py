"""Copy the frames benchmarks/gpu_check.py reads into one folder that fits a device call.

The device tool sends the working tree with the folders named in ``carry``, 64 MiB in
all; ``../shared/data`` beside the checkout does not travel. This copies, unchanged:
Replica room0 (its 20 frames), 7-Scenes redkitchen frames 0 to ``--sevenscenes``-1 and
as many TUM fr1/xyz frames from frame 0 as the rest of ``--limit-mib`` holds (at most
``--tum``; rgb.txt and depth.txt cut to them, the whole groundtruth.txt), then prints
the frames and bytes of each. Put the folder where git ignores it, e.g.

    echo /.gpu-data/ >> .git/info/exclude
    python benchmarks/gpu_pack.py --data-root ../shared/data --out .gpu-data

and name ``.gpu-data`` in the run's ``carry``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

MIB = 1024 * 1024


def _size(paths: list[Path]) -> int:
    return sum(p.stat().st_size for p in paths)


def sevenscenes_files(root: Path, frames: int) -> list[Path]:
    """The sequence's shared files and frames 0..frames-1 (colour, depth, pose)."""
    shared = [p for p in root.iterdir() if p.is_file() and not p.name.startswith("frame-")]
    picked = []
    for index in range(frames):
        picked += sorted(root.glob(f"frame-{index:06d}.*"))
    return shared + picked


def tum_lists(root: Path) -> tuple[list[str], list[str], list[str]]:
    """(comment lines, rgb.txt entries, depth.txt entries) of a TUM sequence."""

    def entries(name: str) -> tuple[list[str], list[str]]:
        lines = (root / name).read_text().splitlines()
        return [x for x in lines if x.startswith("#")], [x for x in lines if x and x[0] != "#"]

    comments, colour = entries("rgb.txt")
    _, depth = entries("depth.txt")
    return comments, colour, depth


def tum_cut(root: Path, frames: int) -> tuple[list[str], list[str], list[Path]]:
    """The first ``frames`` colour entries, the depth entries up to 0.1 s after the last
    of them, and the image files they name."""
    _, colour, depth = tum_lists(root)
    colour = colour[:frames]
    last = float(colour[-1].split()[0]) + 0.1
    depth = [x for x in depth if float(x.split()[0]) <= last]
    files = [root / x.split()[1] for x in colour + depth]
    return colour, depth, files


def pack(args: argparse.Namespace) -> int:
    room0 = args.data_root / "replica-room0"
    kitchen = args.data_root / "7scenes-redkitchen"
    tum = args.tum or args.data_root / "tum-fr1-xyz"
    for folder in (room0, kitchen, tum):
        if not folder.is_dir():
            print(
                f"gpu_pack.py: {folder} is not a folder (check --data-root / --tum)",
                file=sys.stderr,
            )
            return 2
    room0_files = [p for p in room0.rglob("*") if p.is_file()]
    kitchen_files = sevenscenes_files(kitchen, args.sevenscenes)
    left = args.limit_mib * MIB - _size(room0_files) - _size(kitchen_files)
    left -= (tum / "groundtruth.txt").stat().st_size
    frames = 0
    for count in range(1, min(args.tum_frames, len(tum_lists(tum)[1])) + 1):
        if _size(tum_cut(tum, count)[2]) > left:
            break
        frames = count
    if frames == 0:
        print(
            f"gpu_pack.py: no TUM frame fits in --limit-mib {args.limit_mib} (lower --sevenscenes)",
            file=sys.stderr,
        )
        return 2
    if args.out.exists():
        shutil.rmtree(args.out)
    for source, files in ((room0, room0_files), (kitchen, kitchen_files)):
        target = args.out / source.name
        for path in files:
            (target / path.relative_to(source)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, target / path.relative_to(source))
    colour, depth, files = tum_cut(tum, frames)
    comments = tum_lists(tum)[0]
    target = args.out / "tum-fr1-xyz"
    for path in files:
        (target / path.relative_to(tum)).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, target / path.relative_to(tum))
    (target / "rgb.txt").write_text("\n".join(comments + colour) + "\n")
    (target / "depth.txt").write_text("\n".join(comments + depth) + "\n")
    shutil.copy2(tum / "groundtruth.txt", target / "groundtruth.txt")
    for name, count in (
        ("replica-room0", 20),
        ("7scenes-redkitchen", args.sevenscenes),
        ("tum-fr1-xyz", frames),
    ):
        size = _size([p for p in (args.out / name).rglob("*") if p.is_file()])
        print(f"{name}: {count} frames, {size / MIB:.1f} MiB")
    total = _size([p for p in args.out.rglob("*") if p.is_file()])
    print(f"{args.out}: {total / MIB:.1f} MiB in all")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data-root", type=Path, default=Path("../shared/data"))
    parser.add_argument("--tum", type=Path, help="a TUM sequence folder (default: the data root's)")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--sevenscenes", type=int, default=200, help="7-Scenes frames")
    parser.add_argument("--tum-frames", type=int, default=200, help="TUM frames at most")
    parser.add_argument("--limit-mib", type=float, default=58.0, help="size of the folder")
    return pack(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
