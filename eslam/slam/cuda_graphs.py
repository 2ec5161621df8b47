"""CUDA graphs for the tracking and mapping iterations (``compute.cuda_graphs``).

With ``auto`` on a CUDA device whose torch can capture them (:func:`graph_support`),
each iteration of a frame's tracking and of a mapping call is one replay of a CUDA
graph of the graph-ready step (:mod:`eslam.slam.static_steps`): the rays drawn, the
loss rendered, the backward pass, a capturable Adam step (and the tracker's best pose)
in one launch. Between replays only the learning rates are filled (mapping's cosine).

Capture (:class:`CapturedIteration`): the step runs a few times on a side stream first
(warm-up: Adam's state and library workspaces are created) with a scratch generator, so
the run's random numbers are untouched, and the parameters it changes are restored
afterwards; then one iteration is captured with the run's generator registered with
the graph, so each replay draws what the eager step would draw next and advances the
generator as far.

A graph reads fixed addresses, so it is captured again when what it was captured on
changes: the field's tensors (plane growth replaces the planes; a rolled-back frame
replaces the field), the view size or the generator. Mapping keeps a graph per window
size W and rays per step (the step draws ``rays // W`` rays per view; the buffers, pose
slots and optimiser are shared): W grows with the keyframes until ``mapping.window``,
after which a mapping call replays the graph it has (the overlap window policy may
vary W: the :data:`GRAPHS_KEPT` most recent are kept).

Otherwise (``off``, a CPU or MPS device, a torch without what is needed) the eager
steps run: :func:`~eslam.slam.tracking.render.track_frame` and
:func:`~eslam.slam.mapping.mapper.map_window`, unchanged. ``auto`` falling back is logged once.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import logging
from collections import OrderedDict
from collections.abc import Callable, Sequence

import torch

from eslam.field.scene_field import SceneField
from eslam.render.renderer import SceneFieldLike
from eslam.slam.mapping.mapper import (
    MappingResult,
    MappingSchedule,
    MappingSettings,
    map_window,
    warm_start_window,
)
from eslam.slam.static_steps import (
    StaticMapping,
    StaticTracking,
    field_tensors,
    run_mapping,
    run_tracking,
    same_tensors,
    view_shape,
)
from eslam.slam.tracking.base import TrackingResult
from eslam.slam.tracking.render import RenderTracker, TrackingSettings, frozen
from eslam.slam.views import View

log = logging.getLogger("eslam")

WARMUP_ITERATIONS = 2
"""Eager iterations on a side stream before a capture (PyTorch's CUDA-graph recipe)."""

GRAPHS_KEPT = 4
"""Mapping graphs kept (one per window size and ray count, the most recently used):
each holds its own activation memory."""

_told: set[str] = set()


@functools.cache
def graph_support(device: torch.device) -> str | None:
    """None when the iterations can be CUDA graphs on ``device``, else why not.

    Needs a CUDA device, ``CUDAGraph.register_generator_state`` (the run's own
    generator drawing inside a graph) and capturable Adam.
    """
    if device.type != "cuda":
        return f"the device is {device.type}, not CUDA"
    if not hasattr(torch.cuda.CUDAGraph, "register_generator_state"):
        return f"torch {torch.__version__} cannot register a generator with a CUDA graph"
    if "capturable" not in inspect.signature(torch.optim.Adam).parameters:
        return f"torch {torch.__version__} has no capturable Adam"
    return None


def use_cuda_graphs(mode: str, device: torch.device, logger: logging.Logger = log) -> bool:
    """Whether ``compute.cuda_graphs`` = ``mode`` runs the iterations as CUDA graphs on
    ``device``; what ``auto`` chose is logged once (per reason it ran eagerly)."""
    if mode == "off":
        return False
    reason = graph_support(device)
    said = reason or "graphs"
    if said not in _told:
        _told.add(said)
        if reason is None:
            logger.info("compute.cuda_graphs=auto: each iteration is a CUDA-graph replay")
        else:
            logger.info("compute.cuda_graphs=auto: the iterations run eagerly (%s)", reason)
    return reason is None


class CapturedIteration:
    """One iteration captured as a CUDA graph (module doc); :meth:`replay` runs it.

    Args:
        step: the iteration, drawing from the generator it is given.
        generator: the run's CUDA generator (registered with the graph).
        keep: tensors the iteration changes that must hold their values after the
            warm-up and capture (the field's parameters while mapping).
    """

    def __init__(
        self,
        step: Callable[[torch.Generator], None],
        generator: torch.Generator,
        keep: Sequence[torch.Tensor] = (),
    ) -> None:
        device = generator.device
        with torch.no_grad():
            saved = [tensor.detach().clone() for tensor in keep]
        try:
            scratch = torch.Generator(device=device)
            scratch.manual_seed(0)
            side = torch.cuda.Stream(device)
            side.wait_stream(torch.cuda.current_stream(device))
            with torch.cuda.stream(side):
                for _ in range(WARMUP_ITERATIONS):
                    step(scratch)
            torch.cuda.current_stream(device).wait_stream(side)
            self.graph = torch.cuda.CUDAGraph()
            self.graph.register_generator_state(generator)
            with torch.cuda.graph(self.graph, capture_error_mode="thread_local"):
                step(generator)
        finally:
            with torch.no_grad():
                for tensor, value in zip(keep, saved, strict=True):
                    tensor.copy_(value)

    def replay(self) -> None:
        """Run the captured iteration again."""
        self.graph.replay()


def capture(
    step: Callable[[torch.Generator], None],
    generator: torch.Generator,
    keep: Sequence[torch.Tensor] = (),
    logger: logging.Logger = log,
) -> CapturedIteration | None:
    """:class:`CapturedIteration`, or None when capturing fails (an operation a graph
    cannot hold): logged as a warning, and the caller runs eagerly from then on."""
    try:
        return CapturedIteration(step, generator, keep)
    except RuntimeError as error:
        logger.warning(
            "compute.cuda_graphs: capturing an iteration failed (%s): the iterations run "
            "eagerly from now on",
            error,
        )
        return None


class TrackingGraphs:
    """A rendering tracker's graph-ready iterations and their captured graph."""

    def __init__(self) -> None:
        self.static: StaticTracking | None = None
        self.graph: CapturedIteration | None = None
        self.captured_on: tuple[list[torch.Tensor], torch.Generator] | None = None
        self.captures = 0
        self.failed = False

    def track(
        self,
        settings: TrackingSettings,
        field: SceneFieldLike,
        view: View,
        initial_pose: torch.Tensor,
        generator: torch.Generator,
    ) -> TrackingResult | None:
        """The pose of ``view`` as :func:`~eslam.slam.tracking.render.track_frame`, each
        iteration a replay (captured first when needed); None when a capture failed."""
        static = self.static
        if static is None or static.shape != view_shape(view):
            self.static = self.graph = None  # free the old buffers and graph first
            static = self.static = StaticTracking(settings, view)
        tensors = field_tensors(field)  # type: ignore[arg-type]
        if (
            self.graph is None
            or self.captured_on is None
            or self.captured_on[1] is not generator
            or not same_tensors(self.captured_on[0], tensors)
        ):
            self.graph = self.captured_on = None
            static.start(view, initial_pose)  # real data for the warm-up
            with frozen(field):  # type: ignore[arg-type]
                self.graph = capture(lambda g: static.step(field, g), generator)
            if self.graph is None:
                self.failed = True
                return None
            self.captured_on = (tensors, generator)
            self.captures += 1
        return run_tracking(static, field, view, initial_pose, self.graph.replay)


@dataclasses.dataclass(frozen=True)
class GraphedRenderTracker(RenderTracker):
    """The rendering tracker with ``compute.cuda_graphs``: graphs where
    :func:`use_cuda_graphs` says so (and capturing works), else exactly
    :class:`RenderTracker`."""

    mode: str = "auto"
    graphs: TrackingGraphs = dataclasses.field(default_factory=TrackingGraphs, compare=False)

    def track(
        self,
        field: SceneFieldLike,
        view: View,
        initial_pose: torch.Tensor,
        generator: torch.Generator,
    ) -> TrackingResult:
        """Pose of ``view`` from ``initial_pose``."""
        graphs = (
            self.settings.tracking.iterations > 0
            and not self.graphs.failed
            and use_cuda_graphs(self.mode, view.depth.device)
        )
        result = (
            self.graphs.track(self.settings, field, view, initial_pose, generator)
            if graphs
            else None
        )
        if result is None:
            return super().track(field, view, initial_pose, generator)
        return result


class WindowMapper:
    """Mapping calls: :func:`~eslam.slam.mapping.mapper.map_window`, or its iterations as
    CUDA-graph replays where :func:`use_cuda_graphs` says so and capturing works
    (module doc).

    One :class:`~eslam.slam.static_steps.StaticMapping` of ``mapping.window`` slots, and
    a graph per (window size, rays per step), the :data:`GRAPHS_KEPT` most recently used
    kept.

    Args:
        settings: the mapping settings.
        mode: ``compute.cuda_graphs``.
    """

    def __init__(self, settings: MappingSettings, mode: str) -> None:
        self.settings = settings
        self.mode = mode
        self.static: StaticMapping | None = None
        self.graphs: OrderedDict[tuple[int, int], CapturedIteration] = OrderedDict()
        self.generator: torch.Generator | None = None
        self.captures = 0
        self.failed = False

    def map(
        self,
        field: SceneField,
        views: list[View],
        poses: torch.Tensor,
        optimise: list[bool],
        schedule: MappingSchedule,
        generator: torch.Generator,
        on_step: Callable[[int], None] | None = None,
    ) -> MappingResult:
        """One mapping call, as :func:`~eslam.slam.mapping.mapper.map_window` (same arguments)."""
        graphs = (
            schedule.iterations > 0
            and not self.failed
            and use_cuda_graphs(self.mode, views[0].depth.device)
        )
        if graphs:  # as map_window: the warm start (eager) before the rendering steps
            warm_start_window(field, views, poses, self.settings, schedule, generator)
        replay = (
            self._replay(field, views, poses, optimise, schedule, generator) if graphs else None
        )
        if replay is None and graphs and schedule.warm_start is not None:
            schedule = dataclasses.replace(schedule, warm_start=None)  # it ran above
        if replay is None:
            return map_window(
                field, views, poses, optimise, self.settings, schedule, generator, on_step
            )
        assert self.static is not None
        return run_mapping(self.static, views, poses, optimise, schedule, replay, on_step)

    def _replay(
        self,
        field: SceneField,
        views: list[View],
        poses: torch.Tensor,
        optimise: list[bool],
        schedule: MappingSchedule,
        generator: torch.Generator,
    ) -> Callable[[], None] | None:
        """The replay of one iteration for this call (captured when no kept graph has
        this window size and ray count on these buffers and generator); None when a
        capture failed."""
        static = self.static
        if static is None or not static.fits(field, views):
            self.static = None  # free the old buffers and graphs first
            self.graphs.clear()
            slots = max(len(views), self.settings.mapping.window)
            static = self.static = StaticMapping(self.settings, field, views[0], slots)
        if generator is not self.generator:
            self.graphs.clear()
            self.generator = generator
        size, rays = len(views), schedule.rays
        graph = self.graphs.get((size, rays))
        if graph is not None:
            self.graphs.move_to_end((size, rays))
            return graph.replay
        while len(self.graphs) >= GRAPHS_KEPT:
            self.graphs.popitem(last=False)
        static.start(views, poses, optimise, schedule.lr_factor)  # real data for the warm-up
        graph = capture(
            lambda g: static.step(field, g, rays, size), generator, keep=list(field.parameters())
        )
        if graph is None:
            self.failed = True
            return None
        self.graphs[(size, rays)] = graph
        self.captures += 1
        return graph.replay
