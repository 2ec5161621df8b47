"""Loop closure's registration against the ground truth: depth-only ICP on frame pairs.

For each ``--pairs`` entry ``i:j`` the depth of frame i is registered to frame j's by
the projective point-to-plane ICP that verifies loops (``eslam/slam/loops/icp.py``),
started at the ground truth's relative pose (every ``--stride``-th pixel of the
source, default the loop closer's), and the table gives how far ICP moved
from it (cm, degrees), its inlier share and residual. On exact data ICP stays at the
truth; where it settles a degree away, loop edges carry that error (docs/loops.md).

    python benchmarks/registration_check.py --config tum/tum_cpu --data DATA/fr1_xyz
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.errors import ConfigError, InputError
from eslam.slam.loops.closer import pose_difference
from eslam.slam.loops.icp import IcpSettings, register
from eslam.slam.loops.pose_graph import relative_pose

PAIRS = ("4:0", "8:0", "20:0", "40:0", "180:0", "200:0", "400:300", "600:100")


def check_pairs(
    sequence, pairs: list[tuple[int, int]], settings: IcpSettings | None = None
) -> list[tuple[int, int, float, float, float, float]]:
    """(i, j, cm, degrees, inlier share, residual mm) per pair (module doc)."""
    rows = []
    for i, j in pairs:
        a, b = sequence[i], sequence[j]
        truth = relative_pose(b.pose_gt, a.pose_gt)
        greys = (a.rgb.mean(axis=-1) / 255.0, b.rgb.mean(axis=-1) / 255.0)
        found = register(
            a.depth, b.depth, sequence.intrinsics, truth, settings or IcpSettings(), greys
        )
        metres, degrees = pose_difference(truth, found.pose)
        rows.append((i, j, 100 * metres, degrees, found.inlier_fraction, 1000 * found.residual))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--config", required=True, help="a config file or packaged name")
    parser.add_argument("--data", required=True, help="the sequence folder")
    parser.add_argument("--pairs", nargs="+", default=list(PAIRS), help="i:j frame pairs")
    parser.add_argument(
        "--stride", type=int, help="source pixels taken (default: the loop closer's)"
    )
    args = parser.parse_args(argv)
    try:
        pairs = [tuple(int(x) for x in p.split(":")) for p in args.pairs]
        config = load_config(args.config, [f"data.path={args.data}"])
        sequence = open_sequence(config.data)
        if any(max(p) >= len(sequence) or len(p) != 2 for p in pairs):
            raise ValueError(f"pairs must be i:j with frames below {len(sequence)}")
        rows = check_pairs(sequence, pairs, IcpSettings(stride=args.stride))
    except (ConfigError, InputError, ValueError) as error:
        print(f"registration_check.py: {error}", file=sys.stderr)
        return 2
    print("| frames | ICP from the truth (cm) | (deg) | inliers | residual (mm) |")
    print("|---|---:|---:|---:|---:|")
    for i, j, cm, degrees, inliers, residual in rows:
        print(f"| {i} -> {j} | {cm:.2f} | {degrees:.2f} | {inliers:.0%} | {residual:.1f} |")
    table = np.array([r[2:4] for r in rows])
    print(f"| mean | {table[:, 0].mean():.2f} | {table[:, 1].mean():.2f} | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
