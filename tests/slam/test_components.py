"""The run's components: one registry type, each config name backed by its registry,
and a tracker, a view filter and a back end from outside eslam run with no edit to
the run loop."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import pytest
import torch

from eslam.config import FieldConfig, MappingConfig, TrackingConfig
from eslam.errors import ConfigError
from eslam.field.plane_sampling import PLANE_SAMPLINGS
from eslam.io.checkpoint import load_checkpoint
from eslam.registry import Registry
from eslam.slam.mapping.backend import BACK_ENDS, KeyframeBackEnd
from eslam.slam.mapping.windows import WINDOWS
from eslam.slam.run.observers import RunObserverBase
from eslam.slam.session import Components, run_slam
from eslam.slam.tracking.frontend import TrackingFrontEnd
from eslam.slam.tracking.trackers import TRACKERS
from eslam.slam.tracking.view_filters import VIEW_FILTERS
from eslam.slam.views import sampleable_mask
from tests.conftest import TINY_FRAMES, tiny_config


def _literal(config: type, key: str) -> set[str]:
    return set(typing.get_args(typing.get_type_hints(config)[key]))


@pytest.mark.parametrize(
    ("registry", "config", "key"),
    [
        (TRACKERS, TrackingConfig, "method"),
        (WINDOWS, MappingConfig, "selection"),
        (BACK_ENDS, MappingConfig, "back_end"),
        (PLANE_SAMPLINGS, FieldConfig, "plane_sampling"),
    ],
)
def test_each_config_name_is_a_registry_entry(registry: Registry, config: type, key: str) -> None:
    assert _literal(config, key) == set(registry.names())


def test_a_registry_names_its_choices_and_refuses_a_taken_name() -> None:
    registry: Registry[int] = Registry("counter", "x.counter")
    registry.register("one", lambda: 1)
    assert registry.make("one") == 1 and "one" in registry and len(registry) == 1
    with pytest.raises(ConfigError, match=r"unknown x.counter 'two' \(choose one of: one\)"):
        registry.make("two")
    with pytest.raises(ValueError, match="registered already"):
        registry.register("one", lambda: 2)
    registry.unregister("one")
    assert registry.names() == ()


def test_the_triton_sampling_refuses_a_device_it_cannot_run_on() -> None:
    for name in ("reference", "fast", "fused"):
        PLANE_SAMPLINGS.check(name, torch.device("cpu"))  # run anywhere
    with pytest.raises(ConfigError, match="plane_sampling: triton"):
        PLANE_SAMPLINGS.check("triton", torch.device("mps"))


def test_a_device_check_refuses_before_anything_is_built() -> None:
    def cuda_only(device) -> None:
        if torch.device(device).type != "cuda":
            raise ConfigError("needs CUDA")

    registry: Registry[int] = Registry("kernel", "x.kernel")
    registry.register("gpu", lambda: 1, check=cuda_only)
    with pytest.raises(ConfigError, match="needs CUDA"):
        registry.check("gpu", "cpu")


class Recording:
    """A tracker from outside eslam: the rendering tracker, remembering each view."""

    views: typing.ClassVar[list] = []

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("render", config)

    def track(self, field, view, initial_pose, generator):
        Recording.views.append(view)
        return self.real.track(field, view, initial_pose, generator)


class LeftHalf:
    """A view filter from outside eslam: only the image's left half is tracked on."""

    name = "left_half"
    emptied = "no pixel in the left half"

    def __init__(self, context) -> None:
        self.width = context.intrinsics.width

    def keep(self, view, guess, state):
        columns = torch.arange(view.depth.numel(), device=view.depth.device) % self.width
        return columns < self.width // 2


class Counting:
    """A back end from outside eslam: the paper's, counting the frames it was given in
    its own checkpointed state."""

    def __init__(self, context) -> None:
        self.inner = KeyframeBackEnd(context)

    def begin_frame(self) -> None:
        self.inner.begin_frame()

    def add(self, frame, index, tracked, state, total) -> bool:
        own = state.component("counting")
        own["frames"] = own.get("frames", 0) + 1
        return self.inner.add(frame, index, tracked, state, total)

    def finish(self, state, last) -> None:
        self.inner.finish(state, last)

    def rollback(self, state, mark) -> None:
        self.inner.rollback(state, mark)


@pytest.mark.slow
def test_components_from_outside_run_without_editing_the_loop(
    tiny_sequence: Path,
    tiny_static_ate_cm: float,
    tmp_path: Path,
    register,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    register(TRACKERS, "recording", Recording)
    register(VIEW_FILTERS, "left_half", LeftHalf)
    register(BACK_ENDS, "counting", Counting)
    monkeypatch.setattr(Recording, "views", [])
    config = tiny_config(tiny_sequence, "output.mesh=false")
    config = dataclasses.replace(
        config,
        tracking=dataclasses.replace(config.tracking, method="recording"),
        mapping=dataclasses.replace(config.mapping, back_end="counting"),
    )

    def front_end(context):
        return TrackingFrontEnd(context, filters=[VIEW_FILTERS.make("left_half", context)])

    components = Components(front_end=front_end)
    out = tmp_path / "run"
    run_slam(config, out, stop_after=5, components=components)
    assert load_checkpoint(out / "map.pt")["components"]["counting"] == {"frames": 5}
    result = run_slam(config, out, resume=True, components=components)
    # the component's state came back from the checkpoint and went on counting
    assert load_checkpoint(out / "map.pt")["components"]["counting"] == {"frames": TINY_FRAMES}
    assert len(Recording.views) == TINY_FRAMES - 1  # frame 0 keeps its first pose
    width = 80  # the tiny sequence's images are 80x60
    for view in Recording.views:
        columns = torch.nonzero(sampleable_mask(view))[:, 0] % width
        assert len(columns) > 0 and int(columns.max()) < width // 2
    # tracked on half the image, the run still follows the camera
    assert result.metrics["ate_rmse_cm"] < 0.3 * tiny_static_ate_cm


class NothingFrom:
    """A view filter that leaves no pixel from frame 5 on."""

    name = "nothing_from_5"
    emptied = "the test filter keeps nothing from frame 5 on"

    def keep(self, view, guess, state):
        keep = state.next_frame < 5
        return torch.full_like(view.depth, keep, dtype=torch.bool)


class Frames(RunObserverBase):
    """Remembers every FrameDone."""

    def __init__(self) -> None:
        self.done: list = []

    def on_frame(self, frame) -> None:
        self.done.append(frame)


@pytest.mark.slow
def test_a_frame_a_view_filter_empties_keeps_the_guess_and_says_why(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    config = tiny_config(tiny_sequence, "output.mesh=false")
    seen = Frames()

    def front_end(context):
        return TrackingFrontEnd(context, filters=[NothingFrom()])

    run_slam(config, tmp_path / "run", components=Components(front_end), observers=[seen])
    assert [frame.tracked for frame in seen.done] == [False] + [True] * 4 + [False] * 7
    assert all(frame.emptied_by == NothingFrom.emptied for frame in seen.done[5:])
    assert all(frame.emptied_by is None for frame in seen.done[:5])
    log = (tmp_path / "run" / "log.txt").read_text()
    assert f"frame 5: {NothingFrom.emptied}: not tracked, the motion model's pose is kept" in log
    assert log.count(NothingFrom.emptied) == TINY_FRAMES - 5
