"""The sweep plan: which configuration (:class:`Case`) to measure at which camera.

The sweep is not the full cartesian product. Around the baseline it runs

- the **grid**: every renderer (polygons at 1, 2x2 and 4x4 samples per pixel,
  volume, splat) at every camera distance;
- the **level-of-detail block**: the baseline volume and splats drawn from the
  texture's pyramid, at every camera;
- the **one-axis blocks**: each setting varied alone around the baseline, at
  the ``near`` and ``far`` cameras (:func:`~aniso3d.bench.cameras.near_far`).

A configuration shared by several blocks (the baseline itself) is measured once
and lists every block it belongs to. New measurements plug in as another block
in :func:`plan_cases`; a case's ``extra`` options go to ``Renderer.render`` and
become columns.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from aniso3d.bench.cameras import CameraSpec, near_far
from aniso3d.bench.settings import MESH_LABEL, SPLAT_AXES, Settings


@dataclass(frozen=True)
class Case:
    """One configuration at one camera. Unused fields are None (a polygon
    rendering has no resolution; a volume rendering has no splat shape)."""

    renderer: str
    method: str
    camera: str
    ssaa: int = 1
    resolution: int | None = None
    directions: int | None = None
    placement: str | None = None
    per_entry: int | None = None
    point_normal: str | None = None
    splat: str | None = None
    quality: str | None = None
    #: Further ``Renderer.render`` options as (name, value) pairs, e.g.
    #: ``(("lod", True),)`` for a level-of-detail block; each is also a column.
    extra: tuple[tuple[str, object], ...] = ()

    @property
    def lod(self) -> bool:
        """Drawn from the texture's pyramid (``Renderer.render(..., lod=True)``)."""
        return bool(dict(self.extra).get("lod"))

    @property
    def texture_key(self) -> tuple | None:
        """Cases with the same key share one texture build."""
        return None if self.resolution is None else (self.resolution, self.directions)

    @property
    def points_key(self) -> tuple | None:
        """Cases with the same key share one point set (None: no separate points)."""
        if self.method != "splat" or self.lod:
            return None
        return (self.resolution, self.directions, self.placement, self.per_entry, self.point_normal)

    def columns(self) -> dict:
        """The case as row columns: its fields, and each ``extra`` option by name."""
        return {**{k: v for k, v in asdict(self).items() if k != "extra"}, **dict(self.extra)}

    def render_options(self) -> dict:
        """Options for ``Renderer.render``: the splat shape and quality, and the
        volume renderer's shading normal (the points carry theirs), and
        ``extra``. Level-of-detail splats are made by the renderer from the
        texture, so they also take the point build options."""
        if self.method == "volume":
            opts = {} if self.point_normal is None else {"normal": self.point_normal}
        else:
            pairs = [("splat", self.splat), ("quality", self.quality)]
            if self.lod:
                pairs += [("placement", self.placement), ("per_entry", self.per_entry),
                          ("point_normal", self.point_normal)]  # fmt: skip
            opts = {k: v for k, v in pairs if v is not None}
        return {**opts, **dict(self.extra)}


def volume_case(camera: str, cfg: dict) -> Case:
    """The volume rendering of configuration ``cfg`` (a baseline-like dict)."""
    return Case(
        "volume",
        "volume",
        camera,
        resolution=cfg["resolution"],
        directions=cfg["directions"],
        point_normal=cfg["point_normal"],
    )


def splat_case(camera: str, cfg: dict) -> Case:
    """The splat rendering of configuration ``cfg`` (a baseline-like dict)."""
    return Case(
        "splat",
        "splat",
        camera,
        resolution=cfg["resolution"],
        directions=cfg["directions"],
        placement=cfg["placement"],
        per_entry=cfg["per_entry"],
        point_normal=cfg["point_normal"],
        splat=cfg["splat"],
        quality=cfg["quality"],
    )


def plan_cases(settings: Settings, cameras: list[CameraSpec]) -> dict[Case, list[str]]:
    """Every case to measure, each with the blocks it belongs to (in order)."""
    plan: dict[Case, list[str]] = {}

    def add(case: Case, block: str) -> None:
        blocks = plan.setdefault(case, [])
        if block not in blocks:
            blocks.append(block)

    base = settings.baseline
    for cam in cameras:
        for s in settings.mesh_ssaa:
            add(Case(MESH_LABEL.get(s, f"mesh-{s}x{s}"), "mesh", cam.label, ssaa=s), "grid")
        add(volume_case(cam.label, base), "grid")
        add(splat_case(cam.label, base), "grid")
        # The same two drawn from the texture's pyramid: only what the view
        # needs, a voxel per pixel.
        lod = (("lod", True),)
        add(replace(volume_case(cam.label, base), extra=lod), "lod")
        add(replace(splat_case(cam.label, base), extra=lod), "lod")
    for cam in near_far(cameras):
        for axis, vals in settings.axis_values().items():
            for v in vals:
                cfg = {**base, axis: v}
                if axis not in SPLAT_AXES:
                    add(volume_case(cam.label, cfg), axis)
                add(splat_case(cam.label, cfg), axis)
    return plan
