"""The scene field: feature planes + tiny MLP decoders (docs/method.md section 1).

TSDF s(p) = tanh(MLP_g(F_g(p_n))) in units of the truncation T, colour
c(p) = sigmoid(MLP_a(F_a(p_n))), with p_n the point normalised by the fitted bound and
F_g, F_a the geometry and appearance plane features (:mod:`eslam.field.planes`).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import nn

from eslam.config import FieldConfig
from eslam.field.decoders import appearance_decoder, geometry_decoder
from eslam.field.plane_sampling import PLANE_SAMPLINGS
from eslam.field.planes import (
    PlaneLevel,
    PlaneSet,
    enclosing_bound,
    fit_bound,
    fused_features,
    normalize_points,
)
from eslam.stages import stage
from eslam.types import FieldOutput


class SceneField(nn.Module):
    """Hybrid scene representation: two plane sets and two decoders, plus beta.

    Attributes:
        config: the :class:`FieldConfig` it was built from.
        bound: (3, 2) buffer, the FITTED scene box (upper corner grown to multiples of
            ``config.bound_multiple``), metres; float32 unless the module is converted.
            It is in the state_dict, so a loaded field rebuilds the same grids.
        truncation: T, metres.
        beta: scalar parameter, sharpness of the SDF-to-density map (init
            ``config.beta_init``; requires_grad = ``config.learn_beta``).
        geometry: geometry planes (:class:`PlaneSet`).
        appearance: appearance planes, or None when ``config.shared_planes`` (then the
            colour decoder reads the geometry features; ablation a).
        geometry_decoder: features -> TSDF in [-1, 1] (tanh).
        appearance_decoder: features -> RGB in [0, 1] (sigmoid).
    """

    def __init__(
        self, config: FieldConfig, bound: torch.Tensor, generator: torch.Generator | None = None
    ):
        """Build planes over ``bound`` fitted to ``config.bound_multiple``.

        Args:
            config: plane and decoder settings.
            bound: (3, 2) [[xmin, xmax], [ymin, ymax], [zmin, zmax]], metres; any float
                dtype or device (the field is built on the CPU; move it with ``.to``).
            generator: CPU generator of the initial planes and decoder weights (a run
                passes one seeded with its seed); None draws from torch's global one.
        """
        super().__init__()
        self.config = config
        fitted = fit_bound(torch.as_tensor(bound).detach().cpu().double(), config.bound_multiple)
        self.register_buffer("bound", fitted.float())
        self.truncation = float(config.truncation)
        common = dict(
            channels=config.channels,
            init_std=config.init_std,
            levels=config.levels,
            fusion=config.level_fusion,
            sampling=config.plane_sampling,
            generator=generator,
        )
        # whether every level of both plane sets is sampled in one op (chosen once)
        self.rows_at_once = PLANE_SAMPLINGS.make(config.plane_sampling).rows
        self.geometry = PlaneSet(fitted, config.geometry_resolution, **common)
        self.appearance = (
            None
            if config.shared_planes
            else PlaneSet(fitted, config.appearance_resolution, **common)
        )
        colour_planes = self.geometry if self.appearance is None else self.appearance
        hidden, layers = config.decoder_hidden, config.decoder_layers
        self.geometry_decoder = geometry_decoder(self.geometry.out_dim, hidden, layers, generator)
        self.appearance_decoder = appearance_decoder(
            colour_planes.out_dim, hidden, layers, generator
        )
        self.beta = nn.Parameter(
            torch.tensor(float(config.beta_init)), requires_grad=config.learn_beta
        )

    @classmethod
    def from_state(cls, config: FieldConfig, state: Mapping[str, torch.Tensor]) -> SceneField:
        """A field rebuilt from ``state_dict()`` output (on the CPU, float32).

        Raises:
            KeyError: ``state`` has no ``bound``.
            RuntimeError: the parameters do not match ``config`` (shapes, names).
        """
        if "bound" not in state:
            raise KeyError("field state has no 'bound' entry (not a SceneField state_dict?)")
        field = cls(config, state["bound"], torch.Generator())  # overwritten below
        state = dict(state)
        for name, level in field.named_modules():
            if not isinstance(level, PlaneLevel):
                continue
            vertices, window = f"{name}.vertices", f"{name}.window"
            if vertices not in state:  # saved before levels could grow: grids from the bound
                state[vertices], state[window] = level.vertices, level.window
            elif not torch.equal(state[vertices].cpu(), level.vertices.cpu()):
                level.reshape_like(state[vertices], state.get(window, level.window))
        field.load_state_dict(state)
        return field

    def grow(self, required: torch.Tensor, generator: torch.Generator | None = None) -> bool:
        """Enlarge the bound to hold ``required``, keeping every learnt feature in place.

        The new bound is :func:`~eslam.field.planes.enclosing_bound` of the current one
        (whole ``bound_multiple`` steps per side). Each plane level keeps its vertex
        spacing and gains whole vertices on the sides that grew, so ``query`` inside the
        old bound is unchanged (up to float rounding); new features are drawn like
        fresh ones from ``generator``. Plane parameters are replaced: build optimisers
        after growing (tracking and mapping make theirs per call).

        Args:
            required: (3, 2) box to cover, metres.
            generator: random source on the field's device; None = torch's global one.

        Returns:
            Whether the bound changed.
        """
        old = self.bound.detach().clone()
        new = enclosing_bound(old, required, self.config.bound_multiple).to(old)
        if torch.equal(new, old):
            return False
        for planes in (self.geometry, self.appearance):
            if planes is not None:
                planes.grow(old, new, generator)
        with torch.no_grad():
            self.bound.copy_(new)
        return True

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        """The field at world points.

        Args:
            points: (N, 3) world coordinates, metres. Points outside the bound read
                the planes' border features.
            with_rgb: also decode colour.

        Returns:
            FieldOutput with sdf (N,) TSDF in [-1, 1] (units of T; metric SDF = sdf * T)
            and rgb (N, 3) in [0, 1], or None when ``with_rgb`` is False.
        """
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {tuple(points.shape)}")
        points_n = normalize_points(points.to(self.beta.dtype), self.bound)
        with stage("plane sampling"):
            geometry, colour = self.plane_features(points_n, with_rgb)
        with stage("decoders"):
            sdf = self.geometry_decoder(geometry)[:, 0]
            rgb = self.appearance_decoder(colour) if colour is not None else None
        return FieldOutput(sdf=sdf, rgb=rgb)

    def plane_features(
        self, points_n: torch.Tensor, with_colour: bool = True
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Geometry features (N, G) and colour features (N, A) (None unless ``with_colour``)
        at (N, 3) normalised points; the colour ones are the geometry's with shared planes.

        With ``plane_sampling: fused`` (or ``triton``) every level of both plane sets is
        sampled in one op.
        """
        colour_set = self.appearance if with_colour else None
        if self.rows_at_once:
            sets = [self.geometry] if colour_set is None else [self.geometry, colour_set]
            features = fused_features(sets, points_n)
            geometry = features[0]
            colour = features[1] if colour_set is not None else None
        else:
            geometry = self.geometry.features(points_n)
            colour = colour_set.features(points_n) if colour_set is not None else None
        if with_colour and self.appearance is None:
            colour = geometry
        return geometry, colour

    def plane_parameters(self) -> list[nn.Parameter]:
        """The plane tensors, geometry then appearance, coarse then fine."""
        sets = [self.geometry] if self.appearance is None else [self.geometry, self.appearance]
        return [level.planes for planes in sets for level in planes.levels.values()]

    def decoder_parameters(self) -> list[nn.Parameter]:
        """Both decoders' weights and biases, plus beta when it is learnt."""
        params = [*self.geometry_decoder.parameters(), *self.appearance_decoder.parameters()]
        return [*params, self.beta] if self.beta.requires_grad else params

    def parameter_count(self) -> int:
        """Learnable scalars: plane entries (padding excluded), decoders, beta if learnt.

        For the paper's settings the planes dominate: C (nx ny + nx nz + ny nz) per level.
        """
        planes = self.geometry.numel_used()
        if self.appearance is not None:
            planes += self.appearance.numel_used()
        decoders = sum(p.numel() for p in self.decoder_parameters())
        return planes + decoders
