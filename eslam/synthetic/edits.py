"""Synthetic sequences edited to test recovery: frames reordered (the camera returns to
a place it saw), frames without depth (the camera moves on unseen), and frames whose
depth comes from another room (a place that looks alike but is not).

:func:`write_edited_sequence` renders the frames of a :class:`SynthConfig` in the order
given and writes them in the Replica layout with ``synth.json`` (the scene bound and
the edit), like :func:`~eslam.synthetic.files.write_synthetic_sequence`; the ground
truth of each written frame is the pose its colour was rendered from.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from eslam.atomic import atomic_directory, write_text
from eslam.data.replica import REPLICA_DEPTH_SCALE, write_replica_sequence
from eslam.synthetic.config import FPS, SynthConfig
from eslam.synthetic.scenes import build_scene, scene_bound
from eslam.synthetic.sequence import SyntheticSequence
from eslam.types import Frame


@dataclass(frozen=True)
class SequenceEdit:
    """How to edit a synthetic sequence.

    Attributes:
        order: the source frame written at each new index (repeats allowed).
        blind: new indices written with no depth (all zeros).
        foreign: new indices whose depth is the same source frame's in the room of
            seed ``foreign_seed`` (the colour and the ground truth stay this room's).
        foreign_seed: the other room's seed.
    """

    order: tuple[int, ...]
    blind: frozenset[int] = frozenset()
    foreign: frozenset[int] = frozenset()
    foreign_seed: int = 1

    def __post_init__(self) -> None:
        for name in ("blind", "foreign"):
            outside = [i for i in getattr(self, name) if not 0 <= i < len(self.order)]
            if outside:
                raise ValueError(f"{name} indices {outside} are outside the {len(self.order)}")


def edited_frames(config: SynthConfig, edit: SequenceEdit) -> Iterator[Frame]:
    """The frames of ``config`` edited as ``edit`` says (rendered lazily)."""
    source = SyntheticSequence(config)
    other = SyntheticSequence(replace(config, seed=edit.foreign_seed)) if edit.foreign else None
    for new, old in enumerate(edit.order):
        frame = source[old]
        depth = frame.depth
        if new in edit.blind:
            depth = np.zeros_like(depth)
        elif new in edit.foreign:
            assert other is not None
            depth = other[old].depth
        yield replace(frame, index=new, depth=depth, timestamp=float(new))


def write_edited_sequence(out_dir: str | Path, config: SynthConfig, edit: SequenceEdit) -> Path:
    """Write ``config``'s frames edited by ``edit`` to the new folder ``out_dir``
    (module doc); returns it."""
    out_dir = Path(out_dir)
    with atomic_directory(out_dir) as staging:
        write_replica_sequence(staging, edited_frames(config, edit), REPLICA_DEPTH_SCALE)
        info = {
            "config": asdict(config),
            "edit": {
                "order": list(edit.order),
                "blind": sorted(edit.blind),
                "foreign": sorted(edit.foreign),
                "foreign_seed": edit.foreign_seed,
            },
            "fps": FPS,
            "world": "metres, z up, floor at z = 0; poses camera-to-world, OpenCV axes",
            "bound": scene_bound(build_scene(config.scene, config.seed)),
        }
        write_text(staging / "synth.json", json.dumps(info, indent=2) + "\n")
    return out_dir


def return_after_blind(
    mapped: int, blind: int, back_to: Sequence[int]
) -> tuple[tuple[int, ...], frozenset[int]]:
    """The order and blind indices of a forced loss: frames 0 to ``mapped`` - 1, then
    ``blind`` frames that follow them without depth (the camera moves on), then the
    source frames ``back_to`` (a return to places the first frames saw)."""
    order = (*range(mapped + blind), *back_to)
    return order, frozenset(range(mapped, mapped + blind))


def reversal(forward: int) -> tuple[int, ...]:
    """The order of a reversing camera: frames 0 to ``forward`` - 1, then back two at a
    time to frame 1 or 0 (at the first frame back the truth is two steps behind where a
    constant-velocity guess puts it one ahead)."""
    return (*range(forward), *range(forward - 3, -1, -2))
