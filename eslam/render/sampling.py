"""Where to sample along rays: depth-guided, uniform, box, importance (docs/method.md section 2).

Rays are parametrised by z, the depth along the camera's optical axis: a sample at z
lies at ``origin + z * direction`` with directions of unit camera z (see RayBatch).
All functions are pure; every random number comes from the ``generator`` argument
(``None`` falls back to torch's global generator), which must live on the device of
the tensors.
"""

from __future__ import annotations

import torch

PDF_EPSILON = 1e-5
"""Added to every bin weight before normalising the importance pdf, so that a ray with
all-zero weights samples its bins uniformly (NeRF's hierarchical sampling uses 1e-5)."""


def _unit_rand(
    shape: tuple[int, ...], like: torch.Tensor, generator: torch.Generator | None
) -> torch.Tensor:
    return torch.rand(shape, generator=generator, device=like.device, dtype=like.dtype)


def stratified_offsets(
    count: int,
    n: int,
    perturb: bool,
    generator: torch.Generator | None,
    like: torch.Tensor,
    noise: torch.Tensor | None = None,
) -> torch.Tensor:
    """Fractions t in [0, 1] of ``n`` samples per ray, evenly spaced or jittered in their bins.

    Without ``perturb``: t_k = k / (n - 1), k = 0..n-1 (both ends included; t = 0.5 when
    n = 1). With ``perturb``, each t_k is redrawn uniformly in its bin
    [lower_k, upper_k], where the bin edges are the midpoints between neighbours
    (lower_0 = 0, upper_{n-1} = 1), as in NeRF's stratified sampling.

    Args:
        count: number of rays N.
        like: a tensor whose device and dtype the result takes.
        noise: (N, n) uniforms in [0, 1) to jitter with instead of drawing them from
            ``generator`` (drawn ahead, so the caller's computation is free of RNG state).

    Returns:
        (N, n) fractions, sorted along the last axis.

    Example:
        n = 3 gives t = [0, 0.5, 1] and bins [0, 0.25], [0.25, 0.75], [0.75, 1].
    """
    if n < 1:
        raise ValueError(f"need at least one sample per ray, got n={n}")
    if n == 1:
        t = torch.full((count, 1), 0.5, device=like.device, dtype=like.dtype)
        lower, upper = torch.zeros_like(t), torch.ones_like(t)
    else:
        t = torch.linspace(0.0, 1.0, n, device=like.device, dtype=like.dtype).expand(count, n)
        mids = 0.5 * (t[:, 1:] + t[:, :-1])
        lower = torch.cat((t[:, :1], mids), dim=1)
        upper = torch.cat((mids, t[:, -1:]), dim=1)
    if not perturb:
        return t.contiguous()
    if noise is None:
        noise = _unit_rand((count, n), like, generator)
    return lower + (upper - lower) * noise


def uniform_samples(
    near: torch.Tensor,
    far: torch.Tensor,
    n: int,
    perturb: bool,
    generator: torch.Generator | None = None,
    noise: torch.Tensor | None = None,
) -> torch.Tensor:
    """``n`` samples per ray on [near, far]: z_k = near + t_k (far - near).

    t_k from :func:`stratified_offsets` (evenly spaced, or jittered within bins by
    ``noise`` (N, n) when given, else by draws from ``generator``).

    Args:
        near: (N,) start of each interval.
        far: (N,) end of each interval.

    Returns:
        (N, n) sorted samples inside [near, far].

    Example:
        near = 0, far = 1, n = 5, perturb = False -> [0, 0.25, 0.5, 0.75, 1].
    """
    t = stratified_offsets(near.shape[0], n, perturb, generator, near, noise)
    return near[:, None] + t * (far - near)[:, None]


def depth_guided_samples(
    depth: torch.Tensor,
    n_stratified: int,
    n_surface: int,
    truncation: float,
    *,
    surface_band: float = 1.5,
    far_factor: float = 1.2,
    perturb: bool = False,
    generator: torch.Generator | None = None,
    noise: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """ESLAM's samples along rays with a measured depth D (docs/method.md section 2).

    ``n_stratified`` samples on [0, far_factor D] and ``n_surface`` samples on
    [D - band T, D + band T] (release: far_factor 1.2, band 1.5), each set drawn by
    :func:`uniform_samples` (jittered within its own bins when ``perturb``), then merged
    and sorted. ``n_surface = 0`` leaves the stratified set alone (ablation e).

    The release jitters after merging, within bins of the merged set; jittering each
    set in its own bins keeps every sample inside its interval (the difference is
    within one bin width).

    Args:
        depth: (N,) measured depth along the optical axis, metres, > 0.
        truncation: T, metres.
        noise: the jitter of the stratified (N, n_stratified) and surface (N, n_surface)
            samples, drawn ahead (:func:`draw_depth_guided_noise`); None draws from
            ``generator`` here, in the same order.

    Returns:
        (N, n_stratified + n_surface) sorted sample depths, metres.

    Example:
        D = 2, T = 0.06, 32 + 8 samples, no perturb: 2.4 k / 31 (k = 0..31) and
        1.91 + 0.18 j / 7 (j = 0..7), sorted together.
    """
    if n_surface < 0:
        raise ValueError(f"n_surface must be >= 0, got {n_surface}")
    stratified_noise, surface_noise = (None, None) if noise is None else noise
    zeros = torch.zeros_like(depth)
    z = uniform_samples(
        zeros, far_factor * depth, n_stratified, perturb, generator, stratified_noise
    )
    if n_surface > 0:
        half = surface_band * truncation
        surface = uniform_samples(
            depth - half, depth + half, n_surface, perturb, generator, surface_noise
        )
        z = torch.sort(torch.cat((z, surface), dim=1), dim=1).values
    return z


def draw_depth_guided_noise(
    count: int,
    n_stratified: int,
    n_surface: int,
    generator: torch.Generator | None,
    like: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The uniforms :func:`depth_guided_samples` jitters ``count`` rays with, drawn in the
    order it draws them itself: (count, n_stratified), then (count, n_surface)."""
    stratified = _unit_rand((count, n_stratified), like, generator)
    surface = _unit_rand((count, n_surface), like, generator)
    return stratified, surface


def ray_box_intersection(
    origins: torch.Tensor, directions: torch.Tensor, bound: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Parameters where rays enter and leave an axis-aligned box (slab method).

    Per axis a: t1 = (b_min_a - o_a) / d_a, t2 = (b_max_a - o_a) / d_a;
    entry = max_a min(t1, t2), exit = min_a max(t1, t2). An axis with d_a = 0 does not
    bound t if o_a lies inside the slab, and makes the ray miss otherwise.

    Args:
        origins: (N, 3) ray origins.
        directions: (N, 3) ray directions (any length; t is in their units).
        bound: (3, 2) box [[xmin, xmax], [ymin, ymax], [zmin, zmax]].

    Returns:
        near (N,): the entry clamped to 0 (rays start at their origin), and
        far (N,): the exit. A ray misses the box (or the box is behind it) when
        far <= near.

    Example:
        From the centre of the unit box [0, 1]^3 along +x: near 0, far 0.5.
    """
    bound = bound.to(device=origins.device, dtype=origins.dtype)
    parallel = directions.abs() < 1e-12
    safe = torch.where(parallel, torch.ones_like(directions), directions)
    t1 = (bound[:, 0] - origins) / safe
    t2 = (bound[:, 1] - origins) / safe
    inside = (origins >= bound[:, 0]) & (origins <= bound[:, 1])
    inf = torch.full_like(t1, float("inf"))
    lo = torch.where(parallel, torch.where(inside, -inf, inf), torch.minimum(t1, t2))
    hi = torch.where(parallel, torch.where(inside, inf, -inf), torch.maximum(t1, t2))
    near = lo.amax(dim=-1).clamp(min=0.0)
    far = hi.amin(dim=-1)
    return near, far


def ray_box_exit(
    origins: torch.Tensor, directions: torch.Tensor, bound: torch.Tensor
) -> torch.Tensor:
    """(N,) parameter where each ray leaves the box; see :func:`ray_box_intersection`."""
    return ray_box_intersection(origins, directions, bound)[1]


def midpoint_edges(z: torch.Tensor) -> torch.Tensor:
    """Bin edges that give each sample the interval between its neighbours' midpoints.

    edges = [z_0, (z_0 + z_1) / 2, ..., (z_{S-2} + z_{S-1}) / 2, z_{S-1}].

    Args:
        z: (N, S) sorted samples.

    Returns:
        (N, S + 1) edges; sample i owns [edges_i, edges_{i+1}].
    """
    mids = 0.5 * (z[:, 1:] + z[:, :-1])
    return torch.cat((z[:, :1], mids, z[:, -1:]), dim=1)


def importance_samples(
    edges: torch.Tensor,
    weights: torch.Tensor,
    n: int,
    perturb: bool,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Hierarchical sampling: draw ``n`` samples per ray from a piecewise-constant pdf.

    Bin b = [e_b, e_{b+1}] holds probability p_b = (w_b + eps) / sum_k (w_k + eps)
    (eps = PDF_EPSILON), spread uniformly inside it. With the cdf F_0 = 0,
    F_{b+1} = F_b + p_b, a fraction u in [0, 1] maps to the bin b with
    F_b <= u < F_{b+1} and to z = e_b + (u - F_b) / p_b (e_{b+1} - e_b) (inverse cdf).
    Without ``perturb`` u_k = (k + 0.5) / n (evenly spaced, deterministic); with it,
    u_k is uniform in [k / n, (k + 1) / n) (stratified).

    Args:
        edges: (N, B + 1) sorted bin edges.
        weights: (N, B) non-negative bin weights (need not sum to 1).

    Returns:
        (N, n) samples, sorted (u is sorted and the inverse cdf is monotone).

    Example:
        edges [0, 1, 2], weights [1, 1], n = 4, no perturb -> [0.25, 0.75, 1.25, 1.75].
        edges [0, 1, 2], weights [0, 1] -> every sample in [1, 2].
    """
    if edges.shape[-1] != weights.shape[-1] + 1:
        raise ValueError(
            f"importance_samples needs B + 1 edges for B weights, got edges "
            f"{tuple(edges.shape)} and weights {tuple(weights.shape)}"
        )
    count, bins = weights.shape
    pdf = weights.clamp(min=0.0) + PDF_EPSILON
    pdf = pdf / pdf.sum(dim=-1, keepdim=True)
    cdf = torch.cat((torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, dim=-1)), dim=-1)
    cdf[:, -1] = 1.0
    k = torch.arange(n, device=weights.device, dtype=weights.dtype).expand(count, n)
    if perturb:
        u = (k + _unit_rand((count, n), weights, generator)) / n
    else:
        u = (k + 0.5) / n
    u = u.contiguous()
    above = torch.searchsorted(cdf.contiguous(), u, right=True).clamp(1, bins)
    below = above - 1
    cdf_below = cdf.gather(1, below)
    cdf_above = cdf.gather(1, above)
    edge_below = edges.gather(1, below)
    edge_above = edges.gather(1, above)
    mass = cdf_above - cdf_below
    fraction = torch.where(mass > 0, (u - cdf_below) / mass.clamp(min=1e-12), 0.0)
    return edge_below + fraction.clamp(0.0, 1.0) * (edge_above - edge_below)
