"""The ``aniso3d`` command: build, render, frames, bench, view.

Every subcommand turns :class:`~aniso3d.errors.Aniso3DError` into one line on
stderr and exit status 2; outputs are written atomically, never over an input.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .errors import Aniso3DError, InputError
from .texture import DEFAULT_DIRECTIONS, DEFAULT_RESOLUTION

TEXTURE_SUFFIX = ".a3d"


# ------------------------------------------------------------------ shared bits


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
    unless forced), for long builds and frame sequences."""

    def __init__(self, label: str, enabled: bool | None = None, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.label = label
        self.t0 = time.perf_counter()
        self._last = -1.0

    def __call__(self, fraction: float, stage: str = "") -> None:
        if not self.enabled:
            return
        fraction = min(max(fraction, 0.0), 1.0)
        if fraction < 1.0 and fraction - self._last < 0.01:
            return
        self._last = fraction
        width = 30
        filled = int(round(width * fraction))
        elapsed = time.perf_counter() - self.t0
        self.stream.write(
            f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {100 * fraction:5.1f}% "
            f"{stage:<10} {elapsed:6.1f}s"
        )
        if fraction >= 1.0:
            self.stream.write("\n")
        self.stream.flush()


def load_input(path: str | None, scene_options: dict | None = None):
    """A mesh, texture or point cloud from ``path`` by its suffix; the built-in
    tree when ``path`` is None; ``scene:NAME`` for another built-in scene."""
    from . import scenes
    from .mesh import load_mesh
    from .points import PointCloud
    from .texture import AnisoTexture

    if path is None:
        return scenes.tree(**(scene_options or {}))
    if path.startswith("scene:"):
        return scenes.get_scene(path.split(":", 1)[1])
    suffix = Path(path).suffix.lower()
    if suffix == TEXTURE_SUFFIX:
        return AnisoTexture.load(path)
    if suffix == ".ply" and _ply_is_point_cloud(path):
        return PointCloud.load_ply(path)
    return load_mesh(path)


def _ply_is_point_cloud(path: str) -> bool:
    """True if a PLY file declares no faces (or zero of them)."""
    from .mesh import check_readable_file

    p = check_readable_file(path, "input")
    with open(p, "rb") as fh:
        head = fh.read(4096)
    if not head.startswith(b"ply"):
        raise InputError(f"'{path}' does not start with 'ply': it is not a PLY file")
    for line in head.split(b"\n"):
        parts = line.split()
        if len(parts) == 3 and parts[0] == b"element" and parts[1] == b"face":
            return parts[2] == b"0"
        if line.strip() == b"end_header":
            break
    return True


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} GiB"


# ------------------------------------------------------------------------ build


def cmd_build(args) -> int:
    from .errors import ResourceError
    from .mesh import Mesh
    from .texture import build_texture
    from .util import refuse_overwriting_input

    out = Path(args.output)
    if out.suffix.lower() not in (TEXTURE_SUFFIX, ".ply"):
        raise InputError(f"output '{out}' must end in {TEXTURE_SUFFIX} (texture) or .ply (points)")
    refuse_overwriting_input(out, args.mesh)
    # Check where the output goes before a long build, not after it.
    if out.is_dir():
        raise InputError(f"output '{out}' is a directory; name a file to write")
    if not out.parent.is_dir():
        raise InputError(f"output folder '{out.parent}' does not exist; create it first")
    if args.mesh and Path(args.mesh).suffix.lower() == ".ply" and _ply_is_point_cloud(args.mesh):
        raise InputError(
            f"'{args.mesh}' is a point cloud (no faces); 'aniso3d build' needs a polygon mesh"
        )
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    mesh = load_input(args.mesh)
    if not isinstance(mesh, Mesh):
        raise InputError(f"'{args.mesh}' is not a mesh; 'aniso3d build' needs a polygon mesh")
    timings["load"] = time.perf_counter() - t0
    progress = Progress("building", enabled=None if not args.quiet else False)
    tex = build_texture(
        mesh,
        resolution=args.resolution,
        directions=args.directions,
        direction_set=args.direction_set,
        seed=args.seed,
        progress=progress,
        timings=timings,
    )
    t0 = time.perf_counter()
    points = tex.to_points(placement=args.placement, per_entry=args.points_per_entry)
    timings["points"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    try:
        if out.suffix.lower() == ".ply":
            points.save_ply(out)
        else:
            tex.save(out)
    except OSError as exc:  # disk full, permissions: one line, not a traceback
        raise ResourceError(f"could not write '{out}': {exc.strerror or exc}") from None
    timings["save"] = time.perf_counter() - t0
    rows = [
        ("mesh", mesh.name),
        ("triangles", f"{mesh.n_faces:,}"),
        ("sub-polygons", f"{tex.meta['n_subpolygons']:,}"),
        ("grid", "x".join(str(int(s)) for s in tex.shape) + f" (h = {tex.voxel_size:.4g})"),
        ("occupied voxels", f"{tex.n_voxels:,} ({100 * tex.n_voxels / max(1, int(tex.shape.prod())):.2f}% of grid)"),
        ("shading entries", f"{tex.n_entries:,} of {tex.n_voxels * tex.n_directions:,} samples"),
        ("points", f"{len(points):,} ({args.placement})"),
        ("bytes: mesh", _fmt_bytes(mesh.nbytes)),
        ("bytes: texture", _fmt_bytes(tex.nbytes)),
        ("bytes: points", _fmt_bytes(points.nbytes)),
    ]
    rows += [(f"seconds: {k}", f"{v:.3f}") for k, v in timings.items()]
    rows.append(("wrote", str(out)))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0


# ------------------------------------------------------------------------- main


class _Parser(argparse.ArgumentParser):
    """argparse, but a bad option is one line on stderr (status 2), like every
    other error, instead of the usage block followed by the message."""

    def error(self, message: str):
        hint = "; see 'aniso3d --help' for the commands" if self.prog == "aniso3d" else ""
        self.exit(2, f"{self.prog}: error: {message}{hint}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="aniso3d",
        description="Render finely structured 3D objects via an anisotropic 3D texture and point splats.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    b = sub.add_parser("build", help="mesh -> anisotropic 3D texture (.a3d) or points (.ply)")
    b.add_argument("mesh", nargs="?", default=None, help="mesh file (default: the built-in tree)")
    b.add_argument("-o", "--output", default="tree.a3d", help="output .a3d texture or .ply points")
    b.add_argument("--resolution", "-r", type=positive_int, default=DEFAULT_RESOLUTION,
                   help="voxels along the longest axis")
    b.add_argument("--directions", "-k", type=positive_int, default=DEFAULT_DIRECTIONS,
                   help="sphere sample directions K")
    b.add_argument("--direction-set", choices=("fibonacci", "random"), default="fibonacci")
    b.add_argument("--seed", type=int, default=0, help="seed of the random direction set")
    b.add_argument("--placement", choices=("centroid", "center", "sphere"), default="centroid")
    b.add_argument("--points-per-entry", type=positive_int, default=1)
    b.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    b.set_defaults(func=cmd_build)

    # Other front ends register themselves here; each lives in its own module.
    for register in _extra_commands():
        register(sub)
    return parser


def _extra_commands():
    import importlib

    found = []
    for module in ("render_cli", "bench", "viewer_cli"):
        try:
            mod = importlib.import_module(f".{module}", __package__)
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.endswith(module):
                continue
            raise
        found.append(mod.register)
    return found


class _Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that a run killed by ``kill`` or a
    job scheduler unwinds like Ctrl-C: no temporary file left behind."""


def _on_sigterm(signum, frame):
    raise _Terminated


def main(argv: list[str] | None = None) -> int:
    import signal
    import threading

    parser = build_parser()
    args = parser.parse_args(argv)
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if in_main else None
    try:
        return int(args.func(args) or 0)
    except Aniso3DError as exc:
        print(f"aniso3d {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        # Every file is written atomically: what was being written is not
        # there, and earlier outputs (or frames already finished) are whole.
        what = "frames finished so far are complete" if args.command == "frames" else "no output was written"
        print(f"aniso3d {args.command}: interrupted; {what}", file=sys.stderr)
        return 128 + signal.SIGTERM if isinstance(exc, _Terminated) else 130
    except MemoryError:
        print(
            f"aniso3d {args.command}: error: out of memory; lower --resolution or --directions",
            file=sys.stderr,
        )
        return 2
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
