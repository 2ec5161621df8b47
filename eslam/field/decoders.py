"""Tiny MLP decoders from plane features to TSDF and colour (docs/method.md section 1).

Paper: one hidden layer of 32 channels (64 -> 32 -> out); release: two hidden layers
of 16 (64 -> 16 -> 16 -> out). ReLU hidden activations; no positional encoding and no
view direction. Geometry head: 1 output, tanh -> TSDF s in [-1, 1] in units of the
truncation T. Appearance head: 3 outputs, sigmoid -> RGB in [0, 1].
"""

from __future__ import annotations

import math
from itertools import pairwise
from typing import Literal

import torch
from torch import nn

OutputActivation = Literal["tanh", "sigmoid", "none"]


class MLPDecoder(nn.Module):
    """in_dim -> [hidden (ReLU)] x layers -> out_dim -> output activation.

    Linear layers use PyTorch's default initialisation.
    """

    def __init__(
        self,
        in_dim: int,
        hidden: int,
        layers: int,
        out_dim: int,
        activation: OutputActivation = "none",
        generator: torch.Generator | None = None,
    ):
        """Build the layers.

        Args:
            in_dim: input feature width (64 for the paper's concatenated levels).
            hidden: width of every hidden layer (paper 32, release 16).
            layers: number of hidden layers, >= 1 (paper 1, release 2).
            out_dim: outputs (1 for the TSDF, 3 for RGB).
            activation: applied to the output: tanh (TSDF), sigmoid (RGB) or none.
            generator: CPU source of the initial weights (None: torch's global one).
        """
        super().__init__()
        if min(in_dim, hidden, layers, out_dim) < 1:
            raise ValueError(
                f"in_dim, hidden, layers and out_dim must be >= 1, "
                f"got {in_dim}, {hidden}, {layers}, {out_dim}"
            )
        if activation not in ("tanh", "sigmoid", "none"):
            raise ValueError(f"activation must be tanh, sigmoid or none, got {activation!r}")
        widths = [in_dim] + [hidden] * layers
        self.hidden = nn.ModuleList(_linear(a, b, generator) for a, b in pairwise(widths))
        self.output = _linear(hidden, out_dim, generator)
        self.activation = activation

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """(N, in_dim) features -> (N, out_dim) activated outputs."""
        h = features
        for layer in self.hidden:
            h = torch.relu(layer(h))
        out = self.output(h)
        if self.activation == "tanh":
            return torch.tanh(out)
        if self.activation == "sigmoid":
            return torch.sigmoid(out)
        return out

    def extra_repr(self) -> str:
        return f"activation={self.activation}"


def _linear(in_dim: int, out_dim: int, generator: torch.Generator | None) -> nn.Linear:
    """nn.Linear with torch's default initialisation drawn from ``generator``.

    weight ~ kaiming_uniform(a = sqrt(5)) = U(-1/sqrt(in), 1/sqrt(in)) and bias ~
    U(-1/sqrt(in), 1/sqrt(in)), in that order, exactly as ``nn.Linear.reset_parameters``
    (so a generator seeded like the global one gives the same numbers).
    """
    layer = nn.Linear(in_dim, out_dim, device="meta").to_empty(device="cpu")
    with torch.no_grad():
        nn.init.kaiming_uniform_(layer.weight, a=math.sqrt(5), generator=generator)
        bound = 1.0 / math.sqrt(in_dim)
        nn.init.uniform_(layer.bias, -bound, bound, generator=generator)
    return layer


def geometry_decoder(
    in_dim: int, hidden: int, layers: int, generator: torch.Generator | None = None
) -> MLPDecoder:
    """The TSDF head: features -> s = tanh(MLP) in [-1, 1], units of T (paper)."""
    return MLPDecoder(in_dim, hidden, layers, 1, "tanh", generator)


def appearance_decoder(
    in_dim: int, hidden: int, layers: int, generator: torch.Generator | None = None
) -> MLPDecoder:
    """The colour head: features -> RGB = sigmoid(MLP) in [0, 1] (paper)."""
    return MLPDecoder(in_dim, hidden, layers, 3, "sigmoid", generator)
