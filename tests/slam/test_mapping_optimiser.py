"""The mapping and warm-start Adam run multi-tensor (``foreach``): the same values, bit
for bit, as torch's readable single-tensor Adam (the reference) over a whole mapping
call, TSDF warm start and refined poses included."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.slam.mapping import mapper, warm_start
from eslam.slam.mapping.mapper import MappingSettings, map_window, mapping_schedule
from eslam.slam.mapping.warm_start import WarmStart
from tests.slam.test_warm_start import _setup


def single_tensor(make):
    """``make`` (an optimiser factory) with Adam's per-parameter loop (foreach off)."""

    def made(*args, **kwargs):
        optimiser = make(*args, **kwargs)
        for group in optimiser.param_groups:
            group["foreach"] = False
        return optimiser

    return made


def mapped(monkeypatch: pytest.MonkeyPatch, reference: bool):
    """A two-view mapping call (3 warm-start steps, 5 rendering steps, the second pose
    refined): the field's parameters and the refined poses."""
    if reference:
        monkeypatch.setattr(mapper, "mapping_optimiser", single_tensor(mapper.mapping_optimiser))
        monkeypatch.setattr(
            warm_start, "warm_start_optimiser", single_tensor(warm_start.warm_start_optimiser)
        )
    config, field, view = _setup()
    moved = torch.eye(4)
    moved[0, 3] = 0.02
    schedule = dataclasses.replace(
        mapping_schedule(config.mapping, first=True),
        iterations=5,
        warm_start=WarmStart(steps=3, points=256),
    )
    result = map_window(
        field,
        [view, view],
        torch.stack((torch.eye(4), moved)),
        [False, True],
        MappingSettings(config.mapping, config.render, config.loss),
        schedule,
        torch.Generator().manual_seed(0),
    )
    monkeypatch.undo()
    return [p.detach().clone() for p in field.parameters()], result.poses


def test_the_multi_tensor_adam_maps_as_the_single_tensor_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    fast_params, fast_poses = mapped(monkeypatch, reference=False)
    slow_params, slow_poses = mapped(monkeypatch, reference=True)
    assert len(fast_params) == len(slow_params) > 0
    for fast, slow in zip(fast_params, slow_params, strict=True):
        assert torch.equal(fast, slow)
    assert torch.equal(fast_poses, slow_poses)
    assert not torch.equal(fast_poses[1], torch.eye(4))  # the refined pose moved


def test_both_optimisers_are_multi_tensor() -> None:
    _, field, _ = _setup()
    window = mapper.WindowPoses.create(torch.eye(4)[None], [False])
    config = _setup()[0]
    optimisers = (
        mapper.mapping_optimiser(field, window, config.mapping, 1.0),
        warm_start.warm_start_optimiser(field, 0.1, 0.01),
    )
    for optimiser in optimisers:
        assert all(group["foreach"] for group in optimiser.param_groups)
