"""MLP decoders: layer layout, parameter counts, output ranges."""

from __future__ import annotations

import pytest
import torch

from eslam.field.decoders import MLPDecoder, appearance_decoder, geometry_decoder


def _count(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def test_paper_and_release_layouts():
    paper = geometry_decoder(64, 32, 1)
    assert [layer.out_features for layer in paper.hidden] == [32]
    assert _count(paper) == (64 * 32 + 32) + (32 * 1 + 1)
    release = appearance_decoder(64, 16, 2)
    assert [layer.out_features for layer in release.hidden] == [16, 16]
    assert _count(release) == (64 * 16 + 16) + (16 * 16 + 16) + (16 * 3 + 3)


def test_output_ranges_and_shapes():
    torch.manual_seed(0)
    features = torch.randn(500, 8) * 100.0
    sdf = geometry_decoder(8, 4, 2)(features)
    rgb = appearance_decoder(8, 4, 2)(features)
    assert sdf.shape == (500, 1) and rgb.shape == (500, 3)
    assert sdf.min() >= -1 and sdf.max() <= 1
    assert rgb.min() >= 0 and rgb.max() <= 1


def test_hidden_relu_and_linear_head():
    decoder = MLPDecoder(2, 3, 1, 1, "none")
    with torch.no_grad():
        decoder.hidden[0].weight.copy_(torch.tensor([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]]))
        decoder.hidden[0].bias.zero_()
        decoder.output.weight.copy_(torch.tensor([[1.0, 2.0, 3.0]]))
        decoder.output.bias.fill_(0.5)
    out = decoder(torch.tensor([[2.0, -1.0], [-3.0, 4.0]]))
    # relu(2, -2, -1) = (2, 0, 0) -> 2.5; relu(-3, 3, 4) = (0, 3, 4) -> 18.5.
    torch.testing.assert_close(out, torch.tensor([[2.5], [18.5]]))


@pytest.mark.parametrize(
    "args", [(0, 4, 1, 1, "none"), (4, 4, 0, 1, "none"), (4, 4, 1, 1, "softplus")]
)
def test_rejects_bad_arguments(args):
    with pytest.raises(ValueError):
        MLPDecoder(*args)
