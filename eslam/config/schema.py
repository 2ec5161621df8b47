"""The configuration tree: one dataclass per section, a docstring under every field.

A ``__post_init__`` check raises ValueError starting with the field's name ("threads
must be >= 0, ...") so the loader can name the file that set that field.

Over 400 lines on purpose: the whole schema, one dataclass per section with every
key's docstring, in one file that the loader, ``eslam run --help`` and the test holding
configs/base.yaml to its defaults read as one.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from typing import Literal


def _at_least(section: object, name: str, least: float, unit: str = "") -> None:
    """Raise ValueError naming ``name`` unless ``section.name`` is >= ``least`` (NaN fails).

    One check per field, so the loader names the exact key (and the file that set it).
    """
    value = getattr(section, name)
    if not value >= least:
        raise ValueError(f"{name} must be >= {least}{unit}, got {value}")


def _positive(section: object, name: str, unit: str = "") -> None:
    """Raise ValueError naming ``name`` unless ``section.name`` is > 0 (NaN fails); one
    check per field, as :func:`_at_least`."""
    value = getattr(section, name)
    if not value > 0:
        raise ValueError(f"{name} must be > 0{unit}, got {value}")


@dataclass
class TopicsConfig:
    """Topics of a ROS bag (``data.format: rosbag``, docs/live.md); null = automatic."""

    colour: str | None = None
    """sensor_msgs/Image colour topic; null = /camera/color/image_raw, else the bag's only
    colour image topic."""
    depth: str | None = None
    """sensor_msgs/Image depth topic (16UC1/mono16 mm, 32FC1 m); null =
    /camera/aligned_depth_to_color/image_raw, else the bag's only depth image topic."""
    camera_info: str | None = None
    """sensor_msgs/CameraInfo of the colour camera; null = /camera/color/camera_info, else
    the bag's only CameraInfo topic."""
    pose: str | None = None
    """Ground-truth camera pose topic (geometry_msgs/PoseStamped, nav_msgs/Odometry or
    tf2_msgs/TFMessage) of the camera's optical frame; null = no ground truth."""
    pose_frames: tuple[str, str] | None = None
    """TF pose topics only: [parent, child] frame ids of the transform to read; null =
    the topic's only transform."""


@dataclass
class DataConfig:
    """Which sequence to read and how it is laid out on disk."""

    format: str = "replica"
    """Dataset layout of the sequence folder (e.g. replica, folder, redwood) or recording
    (rosbag, realsense); when data.path is a recording (.bag, .db3, .mcap, a ROS 2 bag
    folder) and this names a folder layout, the recording's format is detected."""
    path: str | None = None
    """Folder or recording of the sequence; `--data PATH` on the command line sets it."""
    start: int = 0
    """First frame to use (0-based position in the folder's frame order); `--start`."""
    stride: int = 1
    """Use every stride-th frame from `start` on; `--stride`."""
    max_frames: int | None = None
    """Use at most this many frames (after start and stride); null = all; `--max-frames`."""
    depth_scale: float | None = None
    """Depth image units per metre; null = the layout's own (Replica 6553.5 or its
    cam_params.json, ScanNet and 7-Scenes 1000, TUM 5000, folder: its intrinsics file)."""
    depth_check: bool = True
    """Refuse depth whose median or far end no indoor RGB-D sensor sees (a wrong
    depth_scale or unit; eslam.data.depth_units); false for close-range or outdoor
    captures that are right as they are."""
    resize: tuple[int, int] | None = None
    """Resize colour and depth to [width, height] before cropping; null = the layout's
    default (TUM 512x384 as the release, others none). Intrinsics follow."""
    crop: int | None = None
    """Pixels removed on every border after resizing; null = the layout's default
    (ScanNet 10, TUM 8, others 0). Intrinsics follow."""
    depth_downsample: int = 1
    """Keep every k-th depth pixel per side and show it at full size (nearest): depth at
    1/k resolution, colour and intrinsics unchanged; 8 is the paper's depth / 8 (suppl.
    Tab. 1; eslam.data.depth_resolution). 1 = the depth as read."""
    camera: str | None = None
    """TUM only: fr1, fr2 or fr3 (intrinsics and distortion); null = from the folder name."""
    pairing: Literal["release", "associate"] = "release"
    """TUM only: how colour and depth images make frames. release = the ESLAM release's
    rule (nearest depth within 0.08 s, a frame within 1/32 s of the last one dropped: 759
    of fr1/xyz's 798); associate = TUM's associate.py (unique pairs within 0.02 s: 792)."""
    stamp: Literal["colour", "depth"] = "colour"
    """TUM only: whose time stamps a frame (trajectory.txt) and picks its ground-truth
    pose. colour = the colour image's (the release); depth = the depth image's, when
    the camera was where the depth shows it (the Kinect's two streams are not
    synchronised; docs/data.md). The images read are the same."""
    register_colour: bool = True
    """7-Scenes only: resample the colour image into the depth camera (its own focal length
    and a 2.5 cm baseline; eslam.data.registration) so texture lies on the geometry;
    false = the raw colour with the depth camera's intrinsics, tens of pixels off near
    the border."""
    prefetch: int = 4
    """Frames read ahead on a background thread while the loop works (the same frames in
    the same order: results do not change); 0 = read each frame when the loop asks."""
    realtime: bool = False
    """Real-time mode (`--realtime`, always on for a live camera): frames that arrive while
    the system is busy are dropped, keeping the newest; a recording is replayed at its
    recorded rate. Such a run cannot be resumed (docs/live.md)."""
    replay_fps: float | None = None
    """Real-time replay of a recording: release frames at this rate; null = at their
    timestamps (needed when the timestamps are frame numbers, e.g. Replica folders)."""
    topics: TopicsConfig = field(default_factory=TopicsConfig)
    """Topics read from a ROS bag (data.format: rosbag)."""

    def __post_init__(self) -> None:
        if self.start < 0:
            raise ValueError(f"start must be >= 0, got {self.start}")
        if self.stride < 1:
            raise ValueError(f"stride must be >= 1, got {self.stride}")
        if self.max_frames is not None and self.max_frames < 1:
            raise ValueError(f"max_frames must be >= 1 or null, got {self.max_frames}")
        if self.depth_scale is not None and not self.depth_scale > 0:
            raise ValueError(f"depth_scale must be > 0 or null, got {self.depth_scale}")
        if self.resize is not None and (len(self.resize) != 2 or min(self.resize) < 1):
            raise ValueError(f"resize must be [width, height] or null, got {self.resize}")
        if self.crop is not None and self.crop < 0:
            raise ValueError(f"crop must be >= 0 or null, got {self.crop}")
        if self.prefetch < 0:
            raise ValueError(f"prefetch must be >= 0 frames (0 = off), got {self.prefetch}")
        if self.replay_fps is not None and not self.replay_fps > 0:
            raise ValueError(f"replay_fps must be > 0 or null, got {self.replay_fps}")
        _at_least(self, "depth_downsample", 1)


@dataclass
class SceneConfig:
    """The region of space the map covers."""

    bound: list[list[float]] | None = None
    """Scene box [[xmin, xmax], [ymin, ymax], [zmin, zmax]] in metres; null = automatic:
    the box of frame 0's depth points (0.5-99.5 percentiles per axis) and camera centre,
    seen from frame 0's pose (ground truth or identity), plus ``auto_bound_margin``."""
    auto_bound_margin: float = 0.5
    """Metres added on every side of the automatic bound (frame 0 sees only part of a room;
    growth covers the rest as the camera moves)."""
    grow: bool = True
    """Grow the bound (and the feature planes, keeping learnt features) when a keyframe's
    depth points leave it; off: warn once with the share of points outside."""
    grow_threshold: float = 0.01
    """Share of a keyframe's depth points outside the bound above which it grows (or warns)."""
    grow_margin: float = 0.5
    """Metres beyond the keyframe's points (0.5-99.5 percentiles) on each side that grows."""
    max_extent: float = 30.0
    """Largest side (m) an automatic or grown bound may have; beyond it growth is refused
    with a warning (a lost track or far depth outliers would otherwise fill memory)."""

    def __post_init__(self) -> None:
        if self.bound is not None and (
            len(self.bound) != 3 or any(len(p) != 2 or not p[0] < p[1] for p in self.bound)
        ):
            raise ValueError(f"bound must be 3 pairs [min, max] with min < max, got {self.bound}")
        _at_least(self, "auto_bound_margin", 0, " metres")
        _at_least(self, "grow_margin", 0, " metres")
        if not 0.0 <= self.grow_threshold < 1.0:
            raise ValueError(f"grow_threshold must be in [0, 1), got {self.grow_threshold}")
        _positive(self, "max_extent", " metres")


@dataclass
class FieldConfig:
    """The scene representation: feature planes and decoders (docs/method.md section 1)."""

    channels: int = 32
    """Feature channels of every plane (paper: 32)."""
    geometry_resolution: tuple[float, float] = (0.24, 0.06)
    """Cell size (m) of the coarse and fine geometry planes (paper: 24 cm, 6 cm)."""
    appearance_resolution: tuple[float, float] = (0.24, 0.03)
    """Cell size (m) of the coarse and fine appearance planes (paper: 24 cm, 3 cm)."""
    levels: Literal["both", "coarse", "fine"] = "both"
    """Plane levels used; coarse or fine alone are the ablations b and c (suppl. Tab. 3)."""
    level_fusion: Literal["concat", "sum"] = "concat"
    """How the levels combine: concatenation (paper) or sum (ablation d)."""
    shared_planes: bool = False
    """One set of planes for geometry and appearance (ablation a); resolution = geometry's."""
    init_std: float = 0.01
    """Standard deviation of the normal initialisation of plane features (release)."""
    decoder_hidden: int = 32
    """Hidden width of both decoders (paper: 32; release: 16)."""
    decoder_layers: int = 1
    """Hidden layers of both decoders (paper: 1; release: 2)."""
    truncation: float = 0.06
    """Truncation distance T of the TSDF, metres (paper: 6 cm)."""
    beta_init: float = 10.0
    """Initial sharpness beta of the SDF-to-density map (paper and release: 10)."""
    learn_beta: bool = True
    """Optimise beta with the decoders (release keeps it fixed at 10 for TUM)."""
    bound_multiple: float = 0.24
    """The bound's upper corner grows so each side is a multiple of this (release), metres."""
    plane_sampling: Literal["reference", "fast", "fused", "triton"] = "fused"
    """Plane interpolation, all bilinear with border padding and the same results:
    reference = one grid_sample per plane (readable); fast = one batched grid_sample per
    level; fused = every level of the field in one op of row gathers from channels-last
    planes with a hand-written backward (eslam/field/fused_sampling.py); triton = the
    fused maths in Triton kernels, for CUDA devices (eslam/field/triton_sampling.py; needs
    the triton package; refused on other devices unless TRITON_INTERPRET=1 runs Triton's
    slow CPU interpreter; not yet run on a GPU)."""

    def __post_init__(self) -> None:
        for name in ("geometry_resolution", "appearance_resolution"):
            values = getattr(self, name)
            if len(values) != 2 or min(values) <= 0:
                raise ValueError(f"{name} must be two positive cell sizes, got {values}")
        for name in ("channels", "decoder_hidden", "decoder_layers"):
            _at_least(self, name, 1)
        for name in ("truncation", "beta_init", "bound_multiple"):
            _positive(self, name)


@dataclass
class RenderConfig:
    """Ray sampling and SDF volume rendering (docs/method.md section 2)."""

    samples_stratified: int = 32
    """Samples uniform on [0, far_factor * D] per ray with depth (Replica 32; ScanNet, TUM 48)."""
    samples_surface: int = 8
    """Samples uniform on [D - band T, D + band T] per ray with depth (paper: 8)."""
    surface_band: float = 1.5
    """Half-width of the surface sample interval, in units of the truncation T (release)."""
    far_factor: float = 1.2
    """Stratified samples reach far_factor times the measured depth (release: 1.2)."""
    perturb: bool = True
    """Jitter samples within their bins while optimising (release)."""
    samples_no_depth: int = 64
    """Uniform samples up to the bound's exit for rays without depth (novel views)."""
    density: Literal["eslam", "bell"] = "eslam"
    """eslam: sigma = beta sigmoid(-beta s) (paper); bell: w ~ sigmoid(beta s) sigmoid(-beta s)."""
    render_colour: bool = True
    """Render colour; off is ablation f (depth only, no colour loss)."""

    def __post_init__(self) -> None:
        _at_least(self, "samples_stratified", 1)
        _at_least(self, "samples_surface", 0)
        _at_least(self, "samples_no_depth", 2)
        _positive(self, "surface_band")
        if not self.far_factor > 1.0:
            raise ValueError(f"far_factor must be > 1, got {self.far_factor}")


@dataclass
class LossWeights:
    """Weights of the five loss terms (docs/method.md section 3)."""

    free_space: float = 5.0
    """lambda_fs: (s - 1)^2 on samples in front of the truncation band."""
    trunc_middle: float = 200.0
    """lambda_Tm: (z + s T - D)^2 on samples with |z - D| < 0.4 T."""
    trunc_tail: float = 10.0
    """lambda_Tt: the same residual on samples with 0.4 T <= |z - D| <= T."""
    depth: float = 0.1
    """lambda_d: (rendered depth - D)^2 per ray."""
    colour: float = 5.0
    """lambda_c: ||rendered colour - C||^2 per ray."""


@dataclass
class LossConfig:
    """How the loss terms are formed, shared by tracking and mapping."""

    middle_fraction: float = 0.4
    """|z - D| below this fraction of T is the truncation middle (paper: 0.4)."""
    single_band: bool = False
    """One loss (with the middle weight) for the whole truncation band: ablation g."""
    reduction: Literal["per_ray", "points"] = "per_ray"
    """SDF terms averaged per ray then over rays (paper) or over all points (release)."""


@dataclass
class RenderTrackerConfig:
    """The paper's tracker (``tracking.method: render``): Adam on the rendering loss
    (docs/method.md section 4; Replica values)."""

    iterations: int = 8
    """Optimisation steps per frame (Replica 8, ScanNet 30, TUM 200)."""
    rays: int = 2000
    """Rays sampled per step (Replica and ScanNet 2000, TUM 5000)."""
    lr_translation: float = 0.001
    """Adam learning rate of the translation (paper, Replica; release 0.002)."""
    lr_rotation: float = 0.001
    """Adam learning rate of the quaternion (paper, Replica)."""
    adam_betas: tuple[float, float] = (0.5, 0.999)
    """Adam betas of the pose optimiser (release)."""
    outlier_factor: float = 10.0
    """Rays whose depth residual exceeds this times the batch median are dropped (release)."""
    weights: LossWeights = field(default_factory=lambda: LossWeights(10.0, 200.0, 50.0, 1.0, 5.0))
    """Loss weights while tracking (paper: 10, 200, 50, 1, 5)."""

    def __post_init__(self) -> None:
        _at_least(self, "iterations", 1)
        _at_least(self, "rays", 1)


@dataclass
class SdfTrackerConfig:
    """The SDF tracker (``tracking.method: sdf``): Levenberg-Marquardt on the map's TSDF
    at back-projected depth points (docs/tracking.md)."""

    levels: tuple[int, ...] = (1000, 4000)
    """Points used per level, coarse to fine: the first N of one seeded subset of the
    frame's valid pixels (the last level's count is drawn)."""
    iterations: int = 20
    """Cap on Levenberg-Marquardt iterations per level (a level stops earlier once a
    step is below the convergence thresholds)."""
    robust: Literal["huber", "geman_mcclure"] = "huber"
    """Robust loss on the SDF residuals (metres)."""
    robust_scale: float = 0.01
    """Scale c of the robust loss, metres (Huber: quadratic below c)."""
    max_sdf: float = 0.9
    """Points with |TSDF| at or above this (units of T) get weight 0: the truncated field
    is flat there and says nothing about the pose."""
    damping: float = 0.0001
    """Initial Levenberg-Marquardt damping lambda (relative to diag(J^T W J))."""
    converged_translation: float = 0.0001
    """A step shorter than this (metres) ..."""
    converged_rotation: float = 0.0002
    """... and turning less than this (radians) ends the level."""
    min_inlier_fraction: float = 0.5
    """Below this share of points fitting the map (in the band, |r| <= c) the frame
    counts as failed: it keeps the motion model's pose and is no keyframe."""
    max_residual: float = 0.02
    """A robust RMS residual of the inliers above this (metres) also fails the frame."""
    degeneracy: float = 0.0
    """Pose directions whose per-point information falls below this are held at the
    guess (Zhang et al. 2016; sliding along a plane); 0 turns the test off."""
    colour_weight: float = 0.0
    """Weight lambda of the photometric term, metres per unit colour: each point also
    has the residuals lambda (c(T q) - C), decoded minus observed colour in [0, 1], so
    0.05 makes a colour error of 0.1 weigh like a 5 mm SDF error; 0 turns it off (the
    default: it made whole demo runs worse; docs/tracking.md)."""
    colour_robust_scale: float = 0.1
    """Scale of the robust loss on the colour residual, in colour units [0, 1]."""
    colour_when: Literal["always", "degenerate"] = "always"
    """With ``colour_weight`` > 0: ``always`` adds the photometric term on every frame;
    ``degenerate`` only on frames whose geometry alone leaves a pose direction below
    ``degeneracy`` at the motion model's guess (a wall, a corridor), so other frames
    keep the geometric tracker's cost and result."""
    noise_reference_depth: float | None = None
    """Depth z0 (metres) at which a point's SDF residual keeps its size: each residual
    (and Jacobian row) is divided by (z / z0)^2, the quadratic growth of a depth
    sensor's noise with distance (structured light, stereo: Khoshelham and Elberink
    2012), so near points, measured more precisely, weigh more; null = every point
    alike (the default)."""

    def __post_init__(self) -> None:
        reference = self.noise_reference_depth
        if reference is not None and not reference > 0:
            raise ValueError(f"noise_reference_depth must be > 0 metres or null, got {reference}")
        _at_least(self, "colour_weight", 0)
        _positive(self, "colour_robust_scale")
        if not self.levels or min(self.levels) < 6 or list(self.levels) != sorted(self.levels):
            raise ValueError(f"levels must be increasing point counts >= 6, got {self.levels}")
        _at_least(self, "iterations", 1)
        _positive(self, "robust_scale", " metres")
        if not 0 < self.max_sdf <= 1:
            raise ValueError(f"max_sdf must be in (0, 1], got {self.max_sdf}")
        _at_least(self, "degeneracy", 0)
        if self.colour_when == "degenerate" and self.colour_weight > 0 and self.degeneracy <= 0:
            raise ValueError(
                "colour_when: degenerate needs degeneracy > 0 (the test that finds those "
                f"frames), got degeneracy {self.degeneracy}"
            )
        if not 0 <= self.min_inlier_fraction < 1:
            raise ValueError(
                f"min_inlier_fraction must be in [0, 1), got {self.min_inlier_fraction}"
            )
        _positive(self, "max_residual", " metres")


@dataclass
class HybridTrackerConfig:
    """``tracking.method: hybrid``: the SDF tracker, then the rendering tracker's loss."""

    render_iterations: int = 3
    """Rendering-tracker iterations after the SDF tracker converged (its other settings:
    ``tracking.render``)."""
    lr_factor: float = 1.0
    """Factor on ``tracking.render``'s learning rates for these iterations. Adam's first
    step moves every pose parameter by about its learning rate whatever the gradient's
    size, so after a converged SDF stage a smaller rate polishes instead of jumping
    (docs/tracking.md)."""

    def __post_init__(self) -> None:
        _at_least(self, "render_iterations", 1)
        _positive(self, "lr_factor")


@dataclass
class RecoveryConfig:
    """What the tracking front end tries when the tracker fails a frame, in this order,
    until a try passes the tracker's own tests and ``min_inlier_fraction``
    (docs/tracking.md, "Recovery"). Nothing runs for a frame that tracks: such runs are
    unchanged. Needs a tracker that judges itself (``sdf``, ``hybrid``)."""

    enabled: bool = True
    """Off: a failed frame keeps the motion model's guess and is no keyframe."""
    min_inlier_fraction: float = 0.75
    """Share of inliers a recovered try needs (a frame tracked from the guess needs
    ``tracking.sdf.min_inlier_fraction``): a try from another pose can fit part of a
    view at a wrong pose (the floor, a wall), and a recovered frame becomes a keyframe."""
    keyframe_starts: int = 2
    """First try from the last pose held still and from the poses of this many
    keyframes nearest the guess (translation in metres plus rotation in radians)."""
    relocalise_after: int = 2
    """Relocalise once this many frames in a row failed (this one included): the
    keyframes that look most alike (a global image descriptor, then feature matches and
    a rigid fit of the matched features' depth points; OpenCV, SciPy) are verified by
    tracking from there.
    0 = never."""
    candidates: int = 3
    """Keyframes verified per relocalisation (the most alike first)."""
    min_matches: int = 20
    """Feature matches that must agree on one pose (RANSAC inliers within 3 cm) before a
    candidate's pose is tried; with fewer, the candidate keyframe's own pose is tried."""
    carried: bool | None = None
    """Whether a failed frame whose start came from its features (``tracking.start:
    features``; such a frame keeps that pose) goes through the tries too. null: not in
    real time (a live camera, ``--realtime``), where the camera's frames are dropped
    while the tries run, yes on recorded data (docs/tracking.md, "Recovery")."""

    def __post_init__(self) -> None:
        if not 0 <= self.min_inlier_fraction <= 1:
            raise ValueError(
                f"min_inlier_fraction must be in [0, 1], got {self.min_inlier_fraction}"
            )
        _at_least(self, "keyframe_starts", 0)
        _at_least(self, "relocalise_after", 0)
        _at_least(self, "candidates", 1)
        _at_least(self, "min_matches", 6)


@dataclass
class FeaturesConfig:
    """ORB features of frames and keyframes: the starting pose (``tracking.start:
    features``), relocalisation and loop candidates by appearance (docs/tracking.md,
    "Starting pose")."""

    count: int = 3000
    """Features kept per image at most (the strongest corners first)."""
    fast_threshold: int = 7
    """The FAST corner test's contrast in grey levels (OpenCV's default 20): a frame
    blurred by a fast turn has few corners above 20 and then matches nothing."""

    def __post_init__(self) -> None:
        _at_least(self, "count", 1)
        if not 1 <= self.fast_threshold <= 255:
            raise ValueError(f"fast_threshold must be in [1, 255], got {self.fast_threshold}")


@dataclass
class TrackingConfig:
    """Camera tracking, once per frame (docs/method.md section 4)."""

    method: Literal["render", "sdf", "hybrid"] = "render"
    """Tracker: render = Adam on the rendering loss (paper); sdf = Levenberg-Marquardt on
    the map's TSDF at the depth points; hybrid = sdf, then a few render iterations. Its
    settings are in ``tracking.<method>`` (docs/tracking.md)."""
    border: int = 75
    """Pixels at the image border never used (release: 75 Replica and ScanNet, 20 TUM)."""
    constant_velocity: bool = True
    """Motion model: start from the constant-velocity prediction on SE(3); off starts from
    the last pose."""
    start: Literal["motion", "features"] = "motion"
    """Where the tracker starts each frame: motion = the motion model's guess;
    features = the pose from the frame's ORB features matched to the previous tracked
    frame's (else the latest keyframe's), a rigid fit of the matched depth points (the
    guess when fewer than ``start_min_matches`` agree): frames far apart (a stride, real
    time) and jerks stay within the tracker's reach (docs/tracking.md, "Starting pose")."""
    start_min_matches: int = 20
    """Feature matches that must agree on the starting pose (RANSAC inliers within 3 cm)."""
    start_alike: int = 3
    """With ``start: features``: when neither the previous frame's features nor the
    latest keyframe's give a start, the keyframes (this many) whose images look most
    like the frame are matched (the recovery's global descriptor), and the one most
    matches agree on gives it (0: none; docs/tracking.md, "Starting pose")."""
    start_coarse: int = 500
    """With ``start: features``: this many of the frame's features (spread over its
    list) are matched to all of the previous frame's (or the latest keyframe's) first,
    and the rough pose they give guides the matching of the rest, each to the features
    within 3 cm of where that pose puts it; all are matched with all when that gives no
    start. 0: all with all at once (docs/tracking.md, "Starting pose")."""
    start_overrule_matches: int = 300
    """With ``start: features``: a start this many matches agree on (0: never) overrules
    the tracker when the map pulls the camera more than ``start_overrule_shift`` from
    it: the frame keeps its features' pose and counts failed (the map cannot confirm
    it; docs/tracking.md, "When the features overrule the map")."""
    start_overrule_shift: float = 0.05
    """Metres between the tracker's camera centre and its start beyond which a start of
    ``start_overrule_matches`` overrules the tracker."""
    start_overrule_frames: int = 3
    """The most frames in a row the features overrule; the next one takes the map's
    pose (features alone drift: the map must get the camera back)."""
    keyframe_offset: bool = False
    """After each mapping call, track its newest keyframe again on the new map and move
    every frame tracked until the next call by the offset from that pose to the one the
    call gave the keyframe: the frames follow the mapper's estimate instead of leaving a
    step at each keyframe (one tracking more per call; docs/tracking.md, "Keyframe
    offset")."""
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    """The ORB features the starting pose, relocalisation and loop closure match."""
    observed_only: bool = False
    """Track on observed space only: a pixel whose depth point, at the motion model's
    guess, no keyframe observed (outside every keyframe's view, or further than the
    truncation behind its depth) is not used; there the map holds no measurement, only
    the field's extrapolation. Off: on 7-Scenes it changed nothing (docs/tracking.md)."""
    render: RenderTrackerConfig = field(default_factory=RenderTrackerConfig)
    """Settings of the rendering tracker (``method: render``, and hybrid's refinement)."""
    sdf: SdfTrackerConfig = field(default_factory=SdfTrackerConfig)
    """Settings of the SDF tracker (``method: sdf`` and ``hybrid``)."""
    hybrid: HybridTrackerConfig = field(default_factory=HybridTrackerConfig)
    """Settings of the hybrid tracker (``method: hybrid``)."""
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    """What is tried when the tracker fails a frame (``sdf`` and ``hybrid``)."""

    def __post_init__(self) -> None:
        if self.border < 0:
            raise ValueError(f"border must be >= 0, got {self.border}")
        _at_least(self, "start_min_matches", 6)
        _at_least(self, "start_alike", 0)
        _at_least(self, "start_coarse", 0)
        _at_least(self, "start_overrule_matches", 0)
        _at_least(self, "start_overrule_frames", 1)
        if not self.start_overrule_shift > 0:
            raise ValueError(
                f"start_overrule_shift must be > 0 metres, got {self.start_overrule_shift}"
            )


MOVED_KEYS = {
    f"tracking.{name}": f"tracking.render.{name}"
    for name in (
        "iterations",
        "rays",
        "lr_translation",
        "lr_rotation",
        "adam_betas",
        "outlier_factor",
        "weights",
    )
}
"""Keys that moved to another section (old name -> new name): the loader names the new one."""


@dataclass
class LoopClosureConfig:
    """Loop closure (eslam/slam/loops, docs/loops.md): after each keyframe's mapping call,
    earlier keyframes that may see the same place are registered to it (projective ICP);
    an accepted loop that disagrees with the estimate is closed by a pose graph (GTSAM,
    the ``loops`` extra) and the map is fitted again at the corrected poses."""

    enabled: bool = False
    """Look for loops (off in the paper's configs)."""
    min_keyframes_back: int = 50
    """A candidate lies at least this many keyframes back ..."""
    min_travel: float = 2.0
    """... or at least this far back along the path, metres."""
    min_overlap: float = 0.3
    """A keyframe is a candidate by pose when at least this share of the new keyframe's
    points, placed with the estimate, falls in its view."""
    candidates: int = 2
    """Candidates tried per keyframe by pose, and as many again by appearance (global
    image descriptor, then ORB matches for a first relative pose)."""
    min_inlier_fraction: float = 0.6
    """Accept a registration only when this share of the new keyframe's points that
    fall in the candidate's view lands on its surface (within 2 cm, normals agreeing) ..."""
    max_residual: float = 0.01
    """... with an RMS point-to-plane residual of at most this, metres ..."""
    min_eigenvalue: float = 0.001
    """... and no direction left unconstrained (smallest eigenvalue of ICP's normal
    equations per inlier; a flat wall gives about 0) ..."""
    min_colour_agreement: float = 0.7
    """... and this share of those points showing the candidate's colour there (grey
    within 0.1 after removing the median difference: exposure): a box-shaped room fits
    itself turned round, its texture does not."""
    min_correction: float = 0.01
    """A loop whose relative pose differs from the estimate's by less than this (metres)
    and ``min_correction_deg`` is kept in the graph but closes nothing (no solve, no
    refit): registration has errors of its own (on TUM fr1/xyz depth-only ICP differs
    from motion capture by about 1 degree), a correction below them is noise."""
    min_correction_deg: float = 0.3
    """See ``min_correction``, degrees."""
    min_keyframes_between: int = 10
    """Solve and refit at most once per this many keyframes; loops accepted in between
    add their edges for the next solve."""
    odometry_sigma: tuple[float, float] = (0.002, 0.005)
    """Pose-graph noise of the edge between consecutive keyframes: rotation (rad) and
    translation (m) per component."""
    odometry: Literal["estimate", "icp"] = "estimate"
    """What the edge between consecutive keyframes measures: estimate = their relative
    pose as tracked and mapped; icp = the later keyframe's depth registered to the
    earlier one's (the loops' ICP, from the estimate; measured when a graph is first
    solved and kept), where it passes the loops' tests (else the estimate's). Measured
    edges do not hold the tracker's error, so a loop's correction can reach the
    keyframes between (with ``anchor_sigma: null``)."""
    loop_sigma: tuple[float, float] = (0.002, 0.005)
    """The same for a loop edge."""
    anchor_sigma: tuple[float, float] | None = (0.01, 0.02)
    """A prior on every keyframe at its pose as tracked (rotation rad, translation m):
    the tracker registers each frame to the global map, so its errors do not add up
    along the chain, and the anchors keep a loop's correction near the loop instead of
    spreading it back to keyframe 0; a loop that finds the estimate further off widens
    them to twice its correction (docs/loops.md); null = no anchors."""
    robust_k: float = 5.0
    """Width of the loop edges' Cauchy kernel, in sigmas: a loop far outside it hardly
    moves the graph (one false loop cannot bend the trajectory)."""
    map: Literal["refit", "rebuild"] = "refit"
    """How the map follows a correction: refit = ``refit_passes`` over the keyframes
    the correction moved, at their corrected poses, from the current field; rebuild = a
    new field, its TSDF regressed on every keyframe at its corrected pose
    (``rebuild_warm_start``), fitted with the first frame's schedule on the first
    window, then the refit passes over every keyframe."""
    rebuild_warm_start: int = 20
    """With ``map: rebuild``: TSDF warm-start steps per keyframe (the first frame's
    ``first_warm_start_points`` each, the keyframes in turn) before the rendering steps;
    0 = none (the first window's first-frame warm start, when ``first_warm_start`` is
    tsdf)."""
    refit_passes: int = 1
    """Passes after a correction over the keyframes it moved (at least 5 mm or 0.25
    degrees), poses held: mapping calls of ``mapping.iterations`` steps on windows of
    ``mapping.window`` keyframes that together hold each once per pass (shuffled)."""
    final_passes: int = 0
    """At the end of the run, passes as ``refit_passes`` with every keyframe's pose
    optimised too but the first's (a global refinement); 0 = off."""

    def __post_init__(self) -> None:
        self.odometry_sigma = _pair(self.odometry_sigma, "odometry_sigma")
        self.loop_sigma = _pair(self.loop_sigma, "loop_sigma")
        if self.anchor_sigma is not None:
            self.anchor_sigma = _pair(self.anchor_sigma, "anchor_sigma")
        _at_least(self, "min_keyframes_back", 1)
        _at_least(self, "min_keyframes_between", 1)
        _at_least(self, "candidates", 0)
        _at_least(self, "refit_passes", 0)
        _at_least(self, "rebuild_warm_start", 0)
        _at_least(self, "final_passes", 0)
        for name in ("min_travel", "max_residual", "robust_k"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("min_overlap", "min_inlier_fraction", "min_colour_agreement"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {getattr(self, name)}")
        if self.map not in ("refit", "rebuild"):
            raise ValueError(f"map must be refit or rebuild, got {self.map!r}")
        if self.odometry not in ("estimate", "icp"):
            raise ValueError(f"odometry must be estimate or icp, got {self.odometry!r}")


def _pair(value, name: str) -> tuple[float, float]:
    """Two positive floats (rotation sigma in rad, translation sigma in m)."""
    pair = tuple(float(v) for v in value)
    if len(pair) != 2 or not all(v > 0 for v in pair):
        raise ValueError(f"{name} must be two positive numbers [rad, m], got {list(value)}")
    return pair


@dataclass
class MappingConfig:
    """Joint optimisation of map and keyframe poses (docs/method.md section 5; Replica values)."""

    back_end: Literal["keyframes"] = "keyframes"
    """Mapping back end (eslam/slam/mapping/backend.py): keyframes = the paper's (a keyframe every
    ``every`` frames, mapped with a window of earlier ones)."""
    every: int = 4
    """Map every k-th frame (plus the last); every mapped frame becomes a keyframe."""
    concurrent: bool | None = None
    """Map beside the tracker (eslam/slam/mapping/concurrent_mapping.py, docs/live.md):
    mapping calls run in a worker (``concurrent_worker``) while frames are tracked on the
    last whole map, a newer keyframe replacing one still waiting. null = on in real time
    (``--realtime``, a live camera) unless loop closure is on, off for recorded data (in
    turn: deterministic); a resumed run maps in turn."""
    concurrent_worker: Literal["auto", "thread", "process"] = "auto"
    """Where a concurrent run maps (eslam/slam/mapping/workers.py): a process of its own
    (CPU only: the tracker and the mapper then share no Python interpreter), a thread of
    the run's process (on CUDA, on a stream of its own); auto = the process on a CPU,
    the thread on a GPU."""
    keyframe_coverage: float = 0.0
    """Also make a tracked frame a keyframe when less than this share of its pixels lay
    in observed space (needs ``tracking.observed_only``, which measures the share): the
    map grows as fast as a turning camera brings new space into view. 0 = off."""
    window: int = 20
    """Keyframes optimised together: current, two latest, the rest drawn from the list."""
    selection: Literal["random", "overlap", "recent"] = "random"
    """Window policy: random over all keyframes (paper), over overlapping ones (release),
    or the latest keyframes only (a sliding window)."""
    rays: int = 4000
    """Rays per step in total over the window, split evenly (Replica 4000, TUM 5000)."""
    iterations: int = 15
    """Optimisation steps per mapped frame (Replica 15, ScanNet 30, TUM 60)."""
    realtime_iterations: int | None = None
    """Steps per mapped frame (after the first) when frames arrive in real time (a live
    camera, ``--realtime``): while a call runs the camera moves on, so fewer steps a
    call map more of its views (docs/live.md). null = ``iterations``; recorded data
    always takes ``iterations``."""
    realtime_first_iterations: int | None = None
    """The first call's rendering steps (after its warm start) when frames arrive in real
    time: beside the tracker, frames are tracked on the warm-started map while these
    run, and the map they make replaces it under the track (docs/live.md). null =
    ``first_iterations``; recorded data always takes ``first_iterations``."""
    realtime_warm_start: int = 0
    """While frames arrive in real time: TSDF regression steps (``first_warm_start_points``
    points each, the window's keyframes in turn, at their poses) at the start of every
    mapping call after the first; beside the tracker the tracker gets the map they leave
    before the call's rendering steps run (a new keyframe's geometry within a fraction of
    a call). 0 = none; recorded data never takes them."""
    first_iterations: int = 1000
    """Steps on the first frame (release: 1000)."""
    first_lr_factor: float = 5.0
    """Learning-rate multiplier for the first frame (release: 5)."""
    first_rays: int | None = None
    """Rays per step on the first frame; null = ``rays`` (release)."""
    first_lr_decay: float = 1.0
    """The first frame's map learning rates fall (cosine) from ``first_lr_factor`` times
    their value to this fraction of that by the last step; 1 = constant (release)."""
    first_warm_start: Literal["none", "tsdf"] = "none"
    """Before the first frame's rendering steps: none (release) or tsdf, a regression of
    the geometry planes and SDF decoder onto the first depth image's projective TSDF
    (eslam/slam/mapping/warm_start.py; with it 30 rendering steps match 1000 without)."""
    first_warm_start_steps: int = 400
    """Adam steps of the tsdf warm start."""
    first_warm_start_points: int = 4000
    """Points per step of the tsdf warm start (one geometry query each, no rendering)."""
    first_warm_start_lead: int | None = None
    """Mapping beside the tracker (``concurrent``): the warm-start steps run before the
    tracker gets the map; the others run beside it, before the first call's rendering
    steps (the first pose comes sooner, on a rougher map). null = all of them."""
    lr_decoders: float = 0.001
    """Adam learning rate of the decoders and beta (paper)."""
    lr_planes: float = 0.005
    """Adam learning rate of the feature planes (paper)."""
    lr_poses: float = 0.001
    """Adam learning rate of the window's keyframe poses (paper)."""
    optimise_poses: bool = True
    """Refine keyframe poses with the map (paper's BA); off is ablation h."""
    carry_frames: bool = False
    """The frames between two keyframes follow the keyframes' refined poses (blended by
    where they lie between them: eslam/slam/mapping/carry.py); false = they keep their
    tracked pose (paper, release)."""
    colour_motion: bool = False
    """Move each keyframe's colour to its depth image's time by the camera's motion (a
    sensor whose colour and depth are not taken together: TUM's Kinect; the reader's
    Frame.colour_delay, 0 elsewhere: no change; eslam/slam/mapping/colour_motion.py);
    recorded data only (in real time the colour is kept as read); false = as read."""
    keyframe_device: str | None = None
    """Device holding keyframe images (uint8 colour, 16-bit depth); null = the run's device."""
    view_cache_mb: float = 1024.0
    """Memory (MB, on the run's device) for keyframes' mapping views (float colour, depth
    and sampling table: 24 bytes a pixel, 20 MB at 1200x680), built once per keyframe
    instead of at every mapping call; the least recently used leave when it is full.
    0 = build them at every call (same results)."""
    weights: LossWeights = field(default_factory=LossWeights)
    """Loss weights while mapping (paper: 5, 200, 10, 0.1, 5)."""
    weigh_depth_noise: bool = False
    """Weigh each ray's depth and TSDF terms by D^-4, the inverse variance of depth whose
    noise grows as D^2 (structured light, stereo: Khoshelham and Elberink 2012), in
    weighted means (only the balance between near and far rays changes, not the terms'
    scale); colour stays unweighted. false = every ray alike (the paper; the default)."""
    loops: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    """Loop closure: a pose graph over the keyframes and a map that follows it."""

    def __post_init__(self) -> None:
        _at_least(self, "every", 1)
        if not 0 <= self.keyframe_coverage < 1:
            raise ValueError(f"keyframe_coverage must be in [0, 1), got {self.keyframe_coverage}")
        _at_least(self, "window", 3)
        _at_least(self, "rays", 1)
        _at_least(self, "iterations", 0)
        for name in ("realtime_iterations", "realtime_first_iterations"):
            if getattr(self, name) is not None:
                _at_least(self, name, 0)
        _at_least(self, "realtime_warm_start", 0)
        _at_least(self, "first_iterations", 0)
        _at_least(self, "first_warm_start_steps", 0)
        _at_least(self, "first_warm_start_points", 1)
        if self.first_warm_start_lead is not None:
            _at_least(self, "first_warm_start_lead", 0)
        if self.first_warm_start not in ("none", "tsdf"):
            raise ValueError(
                f"first_warm_start must be none or tsdf, got {self.first_warm_start!r}"
            )
        if self.view_cache_mb < 0:
            raise ValueError(f"view_cache_mb must be >= 0 (0 = off), got {self.view_cache_mb}")
        if self.first_rays is not None and self.first_rays < 1:
            raise ValueError(f"first_rays must be >= 1 or null, got {self.first_rays}")
        if not 0.0 < self.first_lr_decay <= 1.0:
            raise ValueError(f"first_lr_decay must be in (0, 1], got {self.first_lr_decay}")
        if self.concurrent and self.loops.enabled:
            raise ValueError(
                "concurrent mapping does not close loops yet: set mapping.concurrent=false "
                "or mapping.loops.enabled=false"
            )


@dataclass
class OutputConfig:
    """What a run writes besides the trajectory (README.md, run folder)."""

    checkpoint_every: int = 20
    """Save map.pt (everything needed to resume) every this many frames, and at the end."""
    mesh: bool = True
    """Extract mesh.ply from the field at the end of the run."""
    mesh_resolution: float = 0.02
    """Marching-cubes grid step of mesh.ply, metres (paper evaluation: 1 cm Replica/TUM)."""
    progress: bool = True
    """Show a progress bar (frames/s, current ATE when ground truth exists)."""

    def __post_init__(self) -> None:
        _at_least(self, "checkpoint_every", 1)
        _positive(self, "mesh_resolution", " metres")


@dataclass
class ViewerConfig:
    """What the live viewer shows (`eslam run --viewer rerun` or `--viewer-save FILE.rrd`,
    docs/live.md); without a viewer these keys do nothing."""

    render_every: int = 10
    """Render the current frame from the map (depth and colour, no input depth) every
    this many frames; 0 = never. Each render pauses the run (seconds on a CPU)."""
    render_downscale: int = 2
    """Render at 1/this of the camera's width and height (1 = full size)."""
    mesh_every: int = 5
    """Extract and show the mesh every this many keyframes, and at the end; 0 = never.
    Each extraction pauses the run."""
    mesh_resolution: float = 0.05
    """Marching-cubes grid step of the viewer's mesh, metres (coarser than
    output.mesh_resolution: it is extracted again and again while the run waits)."""

    def __post_init__(self) -> None:
        _at_least(self, "render_every", 0)
        _at_least(self, "render_downscale", 1)
        _at_least(self, "mesh_every", 0)
        _positive(self, "mesh_resolution", " metres")


@dataclass
class ComputeConfig:
    """How the optimisation iterations run on the device (docs/live.md, speed settings)."""

    cuda_graphs: Literal["auto", "off"] = "off"
    """auto: on a CUDA device whose torch can capture them (CUDAGraph with
    register_generator_state, capturable Adam), each tracking and mapping iteration is
    one CUDA-graph replay (eslam.slam.cuda_graphs), captured again when the planes grow (a
    graph per window size); otherwise, and always on CPU or MPS, the eager steps run.
    off: the eager steps everywhere. Results equal the eager path within float
    tolerance; the default stays off until the graphed path has been checked on a GPU."""

    compile: Literal["off", "tracking"] = "off"
    """tracking: the rendering tracker's loss (forward and backward) runs through
    torch.compile (inductor), after a compilation on the first tracked frame (speed and
    compile time: docs/benchmarks.md "torch.compile"); the field query and the mapping
    loss were slower compiled, so they stay eager.
    off: nothing is compiled."""

    def __post_init__(self) -> None:
        if self.compile not in ("off", "tracking"):
            raise ValueError(f"compile must be off or tracking, got '{self.compile}'")
        if self.cuda_graphs not in ("auto", "off"):
            raise ValueError(f"cuda_graphs must be auto or off, got '{self.cuda_graphs}'")


@dataclass
class ESLAMConfig:
    """Everything a run needs; saved fully resolved as config.yaml in the run folder."""

    seed: int = 0
    """Seed of every random generator; the same seed gives the same numbers on CPU."""
    device: str = "cpu"
    """Torch device to run on: cpu, cuda, cuda:N, mps, or auto (CUDA, else MPS, else CPU)."""
    threads: int = 2
    """Torch intra-op CPU threads; 0 leaves torch's default."""
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    """The input sequence."""
    scene: SceneConfig = dataclasses.field(default_factory=SceneConfig)
    """The mapped region of space."""
    field: FieldConfig = dataclasses.field(default_factory=FieldConfig)
    """Feature planes and decoders."""
    render: RenderConfig = dataclasses.field(default_factory=RenderConfig)
    """Ray sampling and volume rendering."""
    loss: LossConfig = dataclasses.field(default_factory=LossConfig)
    """How the loss terms are formed."""
    tracking: TrackingConfig = dataclasses.field(default_factory=TrackingConfig)
    """Camera tracking."""
    mapping: MappingConfig = dataclasses.field(default_factory=MappingConfig)
    """Mapping and keyframes."""
    output: OutputConfig = dataclasses.field(default_factory=OutputConfig)
    """Checkpoints, mesh and progress display."""
    viewer: ViewerConfig = dataclasses.field(default_factory=ViewerConfig)
    """The live viewer (used only with --viewer or --viewer-save)."""
    compute: ComputeConfig = dataclasses.field(default_factory=ComputeConfig)
    """How the iterations run on the device (CUDA graphs)."""

    def __post_init__(self) -> None:
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if self.threads < 0:
            raise ValueError(f"threads must be >= 0 (0 = torch's default), got {self.threads}")
        if self.mapping.keyframe_coverage > 0 and not self.tracking.observed_only:
            raise ValueError(
                "mapping.keyframe_coverage needs tracking.observed_only=true (which measures"
                " the share of a frame in observed space); set it, or keyframe_coverage=0"
            )
        if not re.fullmatch(r"auto|cpu|mps|cuda(:\d+)?", self.device):
            raise ValueError(f"device must be auto, cpu, cuda, cuda:N or mps, got '{self.device}'")
