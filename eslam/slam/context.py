"""What every run component is built with: the run's settings and where it reports.

The run loop's components (the tracking front end, the mapping back end, view filters)
are built by registry factories from one :class:`RunContext`, so a component written
outside eslam gets exactly what the built-in ones get.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import torch

from eslam.config import ESLAMConfig
from eslam.render.rays import camera_directions
from eslam.slam.run.observers import RunObserver
from eslam.types import Intrinsics


@dataclass(frozen=True, eq=False)
class RunContext:
    """The run a component belongs to.

    Attributes:
        config: the run's configuration.
        device: the compute device.
        intrinsics: the camera of every frame.
        directions: (H * W, 3) camera-frame ray directions of that camera, on ``device``.
        observers: told about mapping calls (and everything else the loop reports).
        logger: the run's log, for messages no observer can give (bound estimates).
        source: the input's name, for messages.
        concurrent_mapping: the mapping back end runs beside the tracker
            (``mapping.concurrent`` as the session resolved it: on in real time when not
            set, off for a resumed run).
        real_time: frames arrive at the camera's pace and are dropped while the run is
            busy (a live source, ``data.realtime``).
    """

    config: ESLAMConfig
    device: torch.device
    intrinsics: Intrinsics
    directions: torch.Tensor
    observers: RunObserver
    logger: logging.Logger
    source: str
    concurrent_mapping: bool = False
    real_time: bool = False

    @classmethod
    def build(
        cls,
        config: ESLAMConfig,
        device: torch.device,
        intrinsics: Intrinsics,
        observers: RunObserver,
        logger: logging.Logger,
        source: str,
        concurrent_mapping: bool = False,
        real_time: bool = False,
    ) -> RunContext:
        """A context whose ray directions are computed from ``intrinsics`` once."""
        directions = camera_directions(intrinsics, device)
        return cls(
            config,
            device,
            intrinsics,
            directions,
            observers,
            logger,
            source,
            concurrent_mapping,
            real_time,
        )
