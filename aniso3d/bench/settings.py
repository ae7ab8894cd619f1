"""What one bench run sweeps: the :class:`Settings` and the named presets.

The sweep varies one setting at a time around a *baseline*, which is the
configuration ``aniso3d render`` draws by default, so that the report speaks
about what users get without options.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from aniso3d.errors import InputError
from aniso3d.rendering.renderer import BuildOptions

#: The renderers of the grid block, in the order tables and plots list them.
RENDERERS = ("mesh-1spp", "mesh-2x2", "mesh-4x4", "volume", "splat")
MESH_LABEL = {1: "mesh-1spp", 2: "mesh-2x2", 4: "mesh-4x4"}
#: The one-axis blocks and the Case field each one varies.
AXES = {
    "resolution": "resolution",
    "directions": "directions",
    "placement": "placement",
    "per_entry": "per_entry",
    "point_normal": "point_normal",
    "splat": "splat",
    "quality": "quality",
}
#: Axes that only the splat renderer has (the volume renderer draws the texture;
#: it has a shading normal of its own, swept with the points' normal).
SPLAT_AXES = ("placement", "per_entry", "splat", "quality")
#: The Settings field holding each axis' values.
AXIS_VALUES = {
    "resolution": "resolutions",
    "directions": "directions",
    "placement": "placements",
    "per_entry": "per_entry",
    "point_normal": "point_normals",
    "splat": "splats",
    "quality": "qualities",
}


@dataclass(frozen=True)
class Settings:
    """What one bench run sweeps.

    Attributes:
        name: preset name ("full", "quick", "smoke").
        size: (width, height) of every image, pixels.
        gt_ssaa: samples per pixel along each axis of the polygon ground truth.
        mesh_ssaa: supersampling factors of the polygon renderer rows.
        resolutions, directions, placements, per_entry, point_normals, splats,
            qualities: the values of each one-axis block.
        baseline: the configuration the one-axis blocks vary around; each value
            must be among its axis' values.
        footprints: camera distances of the grid, as the width in pixels of a
            baseline voxel (the frame-filling camera is always added first).
        frames: timed frames per configuration (median reported).
        warmup: untimed frames first (the first one also uploads).
        frame_budget: seconds after which a configuration stops timing more
            frames (at least one is always timed).
    """

    name: str
    size: tuple[int, int]
    gt_ssaa: int
    mesh_ssaa: tuple[int, ...]
    resolutions: tuple[int, ...]
    directions: tuple[int, ...]
    placements: tuple[str, ...]
    per_entry: tuple[int, ...]
    point_normals: tuple[str, ...]
    splats: tuple[str, ...]
    qualities: tuple[str, ...]
    baseline: dict = field(default_factory=dict)
    footprints: tuple[float, ...] = (1.0,)
    frames: int = 5
    warmup: int = 1
    frame_budget: float = 10.0

    def __post_init__(self) -> None:
        for axis, fieldname in AXIS_VALUES.items():
            values = getattr(self, fieldname)
            if not values:
                raise InputError(f"bench settings: no values for {fieldname}")
            if self.baseline.get(axis) not in values:
                raise InputError(
                    f"bench settings: baseline {axis}={self.baseline.get(axis)!r} is not in {values}"
                )
        if self.frames < 1 or self.warmup < 1:
            raise InputError("bench settings: need at least 1 warm-up frame and 1 timed frame")
        if self.gt_ssaa < 2:
            raise InputError(f"the ground truth needs supersampling (>= 2 samples a side), got {self.gt_ssaa}")

    def axis_values(self) -> dict[str, tuple]:
        """Each one-axis block's values, by axis name."""
        return {axis: getattr(self, fieldname) for axis, fieldname in AXIS_VALUES.items()}


#: What ``aniso3d render`` draws by default: the renderer's default build
#: (resolution, K, placement, points per entry, point normal) and disc splats in
#: high (coverage-aware) quality.
_DEFAULT_BUILD = BuildOptions()
BASELINE = {**{name: getattr(_DEFAULT_BUILD, name) for name in BuildOptions.names() if name != "lod"},
            "splat": "disc", "quality": "high"}  # fmt: skip

PRESETS = {
    # 1024 x 1024 images; at 1024 pixels a 128^3 voxel of a frame-filling object
    # spans about 4.6 pixels. See docs/bench/README.md for its run time.
    "full": Settings(
        name="full",
        size=(1024, 1024),
        gt_ssaa=8,
        mesh_ssaa=(1, 2, 4),
        resolutions=(32, 64, 128, 256),
        directions=(16, 64, 256),
        placements=("centroid", "center", "sphere"),
        per_entry=(1, 4),
        point_normals=("mean", "sample"),
        splats=("square", "disc", "ellipse"),
        qualities=("fast", "high", "blend"),
        baseline=dict(BASELINE),
        footprints=(2.0, 1.5, 1.0, 0.7, 0.5, 0.35, 0.25),
        frames=7,
        warmup=1,
        frame_budget=10.0,
    ),
    # 256 x 256 images and a 64^3 baseline (a voxel of the frame-filling object
    # spans about 2.3 pixels): a few minutes.
    "quick": Settings(
        name="quick",
        size=(256, 256),
        gt_ssaa=8,
        mesh_ssaa=(1, 2, 4),
        resolutions=(32, 64, 128),
        directions=(16, 64),
        placements=("centroid", "center", "sphere"),
        per_entry=(1,),
        point_normals=("mean",),
        splats=("square", "disc", "ellipse"),
        qualities=("fast", "high", "blend"),
        baseline={**BASELINE, "resolution": 64},
        footprints=(1.0, 0.5),
        frames=3,
        warmup=1,
        frame_budget=2.0,
    ),
    # Seconds: for the test suite; every code path, no meaningful numbers.
    "smoke": Settings(
        name="smoke",
        size=(96, 96),
        gt_ssaa=4,
        mesh_ssaa=(1, 2),
        resolutions=(16, 32),
        directions=(16,),
        placements=("centroid", "sphere"),
        per_entry=(1,),
        point_normals=("mean",),
        splats=("square", "disc"),
        qualities=("fast", "high"),
        baseline={**BASELINE, "resolution": 16, "directions": 16},
        footprints=(1.0,),
        frames=1,
        warmup=1,
        frame_budget=1.0,
    ),
}


def preset_settings(
    name: str,
    size: tuple[int, int] | None = None,
    frames: int | None = None,
    gt_ssaa: int | None = None,
) -> Settings:
    """The preset ``name`` with the given fields overridden (None keeps the preset's)."""
    if name not in PRESETS:
        raise InputError(f"unknown bench preset {name!r}; choose one of {', '.join(PRESETS)}")
    overrides: dict = {}
    if size:
        overrides["size"] = tuple(size)
    if frames:
        overrides["frames"] = frames
    if gt_ssaa:
        overrides["gt_ssaa"] = gt_ssaa
    return replace(PRESETS[name], **overrides)
