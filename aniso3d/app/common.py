"""What the commands share: argparse value types, the progress bar, and
reading an input (mesh, texture, point cloud or built-in scene) by its suffix."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

TEXTURE_SUFFIX = ".a3d"


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def image_size(text: str) -> tuple[int, int]:
    """'800x600' or '512' (square)."""
    parts = text.lower().split("x")
    try:
        dims = [int(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"image size must look like 800x600 or 512, got '{text}'") from None
    if len(dims) == 1:
        dims = dims * 2
    if len(dims) != 2 or min(dims) < 1:
        raise argparse.ArgumentTypeError(f"image size must be two numbers >= 1, got '{text}'")
    if max(dims) > 16384:
        raise argparse.ArgumentTypeError(f"image size {text} is above the maximum of 16384 pixels a side")
    return dims[0], dims[1]


class Progress:
    """A one-line progress bar on stderr (silent when stderr is not a terminal
    unless forced), for long builds and frame sequences.

    With ``total``, the line also shows how many of the ``unit`` (e.g.
    triangles) are done, reading the fraction as that share of the total, and
    the time left at the rate so far.
    """

    def __init__(self, label: str, enabled: bool | None = None, stream=None, total: int | None = None,
                 unit: str = "triangles"):  # fmt: skip
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.label = label
        self.total = total
        self.unit = unit
        self.t0 = time.perf_counter()
        self._last = -1.0
        self._width = 0

    def __call__(self, fraction: float, stage: str = "") -> None:
        if not self.enabled or self._last >= 1.0:  # finished: the line is complete
            return
        fraction = min(max(fraction, 0.0), 1.0)
        if fraction < 1.0 and fraction - self._last < 0.01:
            return
        self._last = fraction
        self.stream.write("\r" + self.line(fraction, stage, time.perf_counter() - self.t0))
        if fraction >= 1.0:
            self.stream.write("\n")
        self.stream.flush()

    def line(self, fraction: float, stage: str, elapsed: float) -> str:
        """The bar at ``fraction`` done after ``elapsed`` seconds."""
        width = 30
        filled = int(round(width * fraction))
        text = f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {100 * fraction:5.1f}% "
        if self.total:
            text += f"{int(round(fraction * self.total)):,}/{self.total:,} {self.unit} "
        text += f"{stage:<10} {elapsed:6.1f}s"
        if 0.0 < fraction < 1.0 and elapsed > 0.0:
            text += f", ~{elapsed * (1.0 - fraction) / fraction:.0f}s left"
        # pad over the end of a longer previous line
        self._width, pad = max(self._width, len(text)), self._width - len(text)
        return text + " " * max(0, pad)


def add_point_cloud_options(p: argparse.ArgumentParser) -> None:
    """The options of a PLY point-cloud input (see :func:`point_cloud_options`)."""
    g = p.add_argument_group("point-cloud inputs (PLY without faces)")
    g.add_argument("--splat-size", type=positive_float, default=None, metavar="RADIUS",
                   help="one splat radius for every point, world units (default: the file's "
                        "area/radius/scale properties, else each point's from its 8 nearest neighbours)")
    g.add_argument("--splat-scale", type=positive_float, default=None, metavar="FACTOR",
                   help="multiply every splat radius (>1 closes holes, <1 sharpens)")
    g.add_argument("--estimate-normals", action="store_true",
                   help="fit the normals a file lacks to the 8 nearest neighbours (PCA)")


def point_cloud_options(args: argparse.Namespace) -> dict:
    """The point-cloud options given on the command line, as keyword arguments
    of :meth:`~aniso3d.build.points.PointCloud.load_ply` (only those set)."""
    opts = {
        "splat_size": getattr(args, "splat_size", None),
        "splat_scale": getattr(args, "splat_scale", None),
        "estimate_normals": getattr(args, "estimate_normals", False) or None,
    }
    return {k: v for k, v in opts.items() if v is not None}


def load_input(path: str | None, scene_options: dict | None = None, point_options: dict | None = None):
    """A mesh, texture or point cloud from ``path`` by its suffix; the built-in
    tree when ``path`` is None; ``scene:NAME`` for another built-in scene.
    ``point_options`` go to :meth:`~aniso3d.build.points.PointCloud.load_ply`
    and are refused for any other input."""
    from aniso3d.build import scenes
    from aniso3d.build.mesh import MESH_SUFFIXES, check_readable_file, load_mesh
    from aniso3d.build.points import PointCloud
    from aniso3d.build.texture import AnisoTexture
    from aniso3d.errors import InputError

    if point_options and (path is None or not (Path(path).suffix.lower() == ".ply" and ply_is_point_cloud(path))):
        flags = ", ".join("--" + k.replace("_", "-") for k in point_options)
        verb = "is" if len(point_options) == 1 else "are"
        raise InputError(f"{flags} {verb} for PLY point clouds only; '{path or 'the built-in tree'}' is not one")
    if path is None:
        return scenes.tree(**(scene_options or {}))
    if path.startswith("scene:"):
        return scenes.get_scene(path.split(":", 1)[1])
    suffix = Path(path).suffix.lower()
    if suffix == TEXTURE_SUFFIX:
        return AnisoTexture.load(path)
    if suffix == ".ply" and ply_is_point_cloud(path):
        return PointCloud.load_ply(path, **(point_options or {}))
    if suffix not in MESH_SUFFIXES:
        check_readable_file(path, "input")
        raise InputError(
            f"'{Path(path).name}' has suffix '{suffix or '(none)'}', which aniso3d does not read as a mesh "
            f"({', '.join(sorted(MESH_SUFFIXES))}), a saved texture ({TEXTURE_SUFFIX}) or a PLY point cloud"
        )
    return load_mesh(path)


def load_scene_input(spec: str, trees: int = 100):
    """A :class:`~aniso3d.build.scene.Scene` of instances: ``forest`` (the
    built-in forest of ``trees`` trees) or a glTF file whose nodes share
    meshes or use ``EXT_mesh_gpu_instancing``."""
    from aniso3d.build import scenes
    from aniso3d.build.scene import GLTF_SUFFIXES, load_scene
    from aniso3d.errors import InputError

    if spec == "forest":
        return scenes.forest(trees)
    if Path(spec).suffix.lower() in GLTF_SUFFIXES:
        return load_scene(spec)
    raise InputError(f"--scene takes 'forest' or a glTF file (.gltf, .glb) of instances, got '{spec}'")


def ply_is_point_cloud(path: str) -> bool:
    """True if a PLY file declares no faces (or zero of them)."""
    from aniso3d.build.mesh import check_readable_file
    from aniso3d.build.ply import read_ply_header

    return read_ply_header(check_readable_file(path, "input")).is_point_cloud


def byte_size(text: str) -> int:
    """'2G', '512M', '1.5GiB', '800000' -> bytes (K, M, G, T: powers of 1024)."""
    t = text.strip().upper().removesuffix("IB").removesuffix("B")
    scale = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}.get(t[-1:], 1)
    try:
        value = float(t[:-1] if scale > 1 else t) * scale
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a size such as 2G, 512M or 800000, got '{text}'") from None
    if not (value >= 1 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"a memory size must be at least 1 byte, got '{text}'")
    return int(value)


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} GiB"
