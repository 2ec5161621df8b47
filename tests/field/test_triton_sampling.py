"""plane_sampling: triton equals the reference: values, plane and point gradients.

Without CUDA the kernels run on CPU tensors in Triton's interpreter (TRITON_INTERPRET=1,
set by tests/conftest.py before triton is imported: setting it in this module is too
late, triton having decorated its own library kernels at import; the interpreter works
with this venv's numpy and torch). With CUDA the compiled kernels run on CUDA tensors
and the CPU cases skip. Sizes are small: the interpreter runs each program in numpy.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

pytest.importorskip("triton", reason="plane_sampling: triton needs the triton package")

from eslam.config import ESLAMConfig, FieldConfig
from eslam.errors import ConfigError
from eslam.field import triton_sampling
from eslam.field.plane_sampling import sample_planes_reference
from eslam.field.planes import plane_shapes, to_window
from eslam.field.scene_field import SceneField
from eslam.field.triton_sampling import check_device, sample_levels_triton
from eslam.slam.session import run_slam

CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
DEVICES = ["cpu", pytest.param("cuda", marks=[CUDA, pytest.mark.cuda])]

GRIDS = [(5, 7, 9), (3, 4, 2)]
"""Two levels (nx, ny, nz); the second reads through a window."""

WINDOW = ((-1.2, 0.9), (-1.0, 1.0), (-0.8, 1.3))
"""A grown level's box in the scene's normalised coordinates."""


@pytest.fixture(scope="module")
def kernels():
    return triton_sampling.kernels()


def _on(device: str, kernels) -> torch.device:
    if device == "cpu" and not kernels.INTERPRETED:
        pytest.skip("CPU tensors need TRITON_INTERPRET=1 (the kernels are compiled here)")
    return torch.device(device)


def _levels(dtype: torch.dtype, device: torch.device):
    """Padded planes (a row and two columns beyond the largest plane, never read), their
    shapes and windows, and 200 points: inside, outside the bound, on its faces and
    corners and on vertices."""
    generator = torch.Generator().manual_seed(0)
    shapes = [plane_shapes(grid) for grid in GRIDS]
    planes = [
        torch.randn(
            3,
            channels,
            max(h for h, _ in level) + 1,
            max(w for _, w in level) + 2,
            generator=generator,
            dtype=torch.float64,
        )
        for level, channels in zip(shapes, (8, 5), strict=True)  # 5: a masked channel tile
    ]
    points = torch.rand(200, 3, generator=generator, dtype=torch.float64) * 2.8 - 1.4
    points[:8] = torch.tensor([[-1.0, 1.0, 0.0], [1.0, -1.0, 1.0], [-1.0, -1.0, -1.0]]).repeat(
        3, 1
    )[:8]
    points[8:16] = torch.tensor([-0.5, 0.0, 0.5]) + torch.zeros(8, 1, dtype=torch.float64)
    window = torch.tensor(WINDOW, dtype=torch.float32, device=device)
    planes = [p.to(device, dtype).requires_grad_(True) for p in planes]
    return planes, shapes, [None, window], points.to(device, dtype)


def _reference(points, planes, shapes, windows):
    return [
        sample_planes_reference(p, s, points if w is None else to_window(points, w))
        for p, s, w in zip(planes, shapes, windows, strict=True)
    ]


def _value_and_gradients(sample, points, planes):
    """Per-level values and the gradients of a fixed random functional of them."""
    points = points.clone().requires_grad_(True)
    outputs = sample(points)
    generator = torch.Generator().manual_seed(7)
    weights = [torch.randn(o.shape, generator=generator, dtype=o.dtype).to(o) for o in outputs]
    total = sum((o * w).sum() for o, w in zip(outputs, weights, strict=True))
    return [o.detach() for o in outputs], torch.autograd.grad(total, [points, *planes])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(("dtype", "atol"), [(torch.float64, 1e-12), (torch.float32, 2e-5)])
def test_levels_equal_reference(kernels, device, dtype, atol):
    device = _on(device, kernels)
    planes, shapes, windows, points = _levels(dtype, device)
    values, grads = _value_and_gradients(
        lambda p: sample_levels_triton(p, planes, shapes, windows), points, planes
    )
    ref_values, ref_grads = _value_and_gradients(
        lambda p: _reference(p, planes, shapes, windows), points, planes
    )
    for a, b in zip(values, ref_values, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=atol)
    torch.testing.assert_close(grads[0], ref_grads[0], rtol=0, atol=atol * 100)
    for a, b, level_shapes in zip(grads[1:], ref_grads[1:], shapes, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=atol * 10)
        for i, (h, w) in enumerate(level_shapes):  # padding is never read
            assert bool((a[i, :, h:] == 0).all()) and bool((a[i, :, :, w:] == 0).all())
            assert bool((a[i, :, :h, :w] != 0).any())


@pytest.mark.parametrize("device", DEVICES)
def test_point_gradient_alone_and_no_double_backward(kernels, device):
    """The SDF tracker's use (frozen planes, first derivatives w.r.t. points only); NaN
    points read the lower border, as in the reference."""
    device = _on(device, kernels)
    planes, shapes, windows, points = _levels(torch.float64, device)
    planes = [p.detach() for p in planes]
    points[20] = float("nan")
    query = points.clone().requires_grad_(True)
    (out, _) = sample_levels_triton(query, planes, shapes, windows)
    (gradient,) = torch.autograd.grad(out.sum(), query, create_graph=True)
    reference = points.clone().requires_grad_(True)
    (expected,) = torch.autograd.grad(
        sample_planes_reference(planes[0], shapes[0], reference).sum(), reference
    )
    torch.testing.assert_close(
        out.detach(), sample_planes_reference(planes[0], shapes[0], points), rtol=0, atol=1e-12
    )
    torch.testing.assert_close(gradient, expected, rtol=0, atol=1e-10)
    with pytest.raises(RuntimeError):  # no second derivatives: never a silent zero
        gradient.sum().backward()


@pytest.mark.parametrize("device", DEVICES)
def test_field_with_triton_sampling_equals_reference_after_growth(kernels, device):
    """The field's dispatch: every level of both plane sets (channels-last) in one call,
    grown levels reading through their window buffers."""
    device = _on(device, kernels)
    config = FieldConfig(
        channels=4, geometry_resolution=(0.6, 0.3), appearance_resolution=(0.6, 0.4)
    )
    bound = torch.tensor([[-1.9, 2.9], [-2.2, 1.5], [-1.0, 1.3]])
    reference = SceneField(
        dataclasses.replace(config, plane_sampling="reference"),
        bound,
        torch.Generator().manual_seed(0),
    )
    triton = SceneField.from_state(
        dataclasses.replace(config, plane_sampling="triton"), reference.state_dict()
    )
    larger = torch.tensor([[-2.5, 3.5], [-2.2, 1.5], [-1.2, 1.6]])
    fields = []
    for field in (reference, triton):
        assert field.grow(larger, torch.Generator().manual_seed(9))
        fields.append(field.to(device, torch.float64))
    assert not triton.geometry.levels["fine"]._identity
    points = torch.rand(100, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    points = (larger[:, 0] - 0.3 + points * (larger[:, 1] - larger[:, 0] + 0.6)).to(device)
    results = []
    for field in fields:
        query = points.clone().requires_grad_(True)
        out = field.query(query)
        total = (out.sdf * torch.linspace(-1, 1, len(out.sdf)).to(out.sdf)).sum() + out.rgb.sum()
        grads = torch.autograd.grad(total, [query, *field.plane_parameters()])
        results.append((out.sdf.detach(), out.rgb.detach(), *grads))
    for a, b in zip(*results, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-10)


@pytest.mark.cuda
def test_the_op_traces_under_torch_compile(kernels):
    """torch.compile (Dynamo + AOTAutograd, backend aot_eager: the trace, no C++ build)
    takes the op in one graph through its fake and autograd registrations."""
    device = _on("cuda" if torch.cuda.is_available() else "cpu", kernels)
    planes, shapes, windows, points = _levels(torch.float64, device)
    points = points[:40]

    def loss(p, level_planes):
        return (sample_levels_triton(p, [level_planes], shapes[1:], windows[1:])[0] ** 2).sum()

    torch._dynamo.reset()
    compiled = torch.compile(loss, backend="aot_eager", fullgraph=True)
    query = points.clone().requires_grad_(True)
    traced = compiled(query, planes[1])
    expected = sample_planes_reference(planes[1], shapes[1], to_window(points, windows[1])) ** 2
    torch.testing.assert_close(traced, expected.sum(), rtol=0, atol=1e-12)
    grads = torch.autograd.grad(traced, [query, planes[1]])
    reference = points.clone().requires_grad_(True)
    ref_value = (
        sample_planes_reference(planes[1], shapes[1], to_window(reference, windows[1])) ** 2
    ).sum()
    for a, b in zip(grads, torch.autograd.grad(ref_value, [reference, planes[1]]), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-10)


def test_triton_sampling_is_refused_where_it_cannot_run(kernels, monkeypatch, tmp_path: Path):
    check_device("fused", torch.device("cpu"))  # other samplings: never checked
    with pytest.raises(ConfigError, match=r"field.plane_sampling: triton runs on CUDA.*fused"):
        check_device("triton", torch.device("mps"))
    monkeypatch.setattr(kernels, "INTERPRETED", False)
    with pytest.raises(ConfigError, match="not on the cpu device"):
        check_device("triton", torch.device("cpu"))
    # a run is refused before its folder is written
    config = dataclasses.replace(
        ESLAMConfig(), field=dataclasses.replace(FieldConfig(), plane_sampling="triton")
    )
    with pytest.raises(ConfigError, match="plane_sampling: triton"):
        run_slam(config, tmp_path / "run")
    assert not (tmp_path / "run").exists()
    monkeypatch.setattr(triton_sampling, "triton", None)
    with pytest.raises(ConfigError, match="pip install triton"):
        check_device("triton", torch.device("cuda"))
    with pytest.raises(RuntimeError, match=r"pip install triton.*fused"):
        sample_levels_triton(
            torch.zeros(1, 3), [torch.zeros(3, 1, 2, 2)], [plane_shapes((2, 2, 2))]
        )
