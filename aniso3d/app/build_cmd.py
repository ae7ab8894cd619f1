"""``aniso3d build``: mesh -> texture (.a3d) or points (.ply), with a summary table."""

from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

from aniso3d.app.common import (
    TEXTURE_SUFFIX,
    Progress,
    byte_size,
    format_bytes,
    load_input,
    ply_is_point_cloud,
    positive_int,
)
from aniso3d.build.texture import DEFAULT_DIRECTIONS, DEFAULT_RESOLUTION
from aniso3d.errors import InputError, ResourceError


def cmd_build(args) -> int:
    from aniso3d.build.mesh import MESH_SUFFIXES, Mesh
    from aniso3d.build.mesh_stream import open_source
    from aniso3d.build.texture import build_texture
    from aniso3d.files import refuse_overwriting_input

    out = Path(args.output)
    if out.suffix.lower() not in (TEXTURE_SUFFIX, ".ply"):
        raise InputError(f"output '{out}' must end in {TEXTURE_SUFFIX} (texture) or .ply (points)")
    refuse_overwriting_input(out, args.mesh)
    # Check where the output goes before a long build, not after it.
    if out.is_dir():
        raise InputError(f"output '{out}' is a directory; name a file to write")
    if not out.parent.is_dir():
        raise InputError(f"output folder '{out.parent}' does not exist; create it first")
    if args.mesh and Path(args.mesh).suffix.lower() == ".ply" and ply_is_point_cloud(args.mesh):
        raise InputError(
            f"'{args.mesh}' is a point cloud (no faces); 'aniso3d build' needs a polygon mesh"
        )
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if args.mesh and not args.mesh.startswith("scene:") and Path(args.mesh).suffix.lower() in MESH_SUFFIXES:
        # A mesh file: binary STL and PLY are streamed in chunks, the rest loaded whole.
        source = open_source(args.mesh)
    else:
        mesh = load_input(args.mesh)
        if not isinstance(mesh, Mesh):
            raise InputError(f"'{args.mesh}' is not a mesh; 'aniso3d build' needs a polygon mesh")
        source = open_source(mesh)
    timings["load"] = time.perf_counter() - t0
    progress = Progress("building", enabled=None if not args.quiet else False, total=source.n_faces)
    stats: dict = {}
    with _executor(args) as client:
        tex = build_texture(
            source,
            resolution=args.resolution,
            directions=args.directions,
            direction_set=args.direction_set,
            seed=args.seed,
            progress=progress,
            timings=timings,
            memory_budget=args.memory_budget,
            workers=args.workers,
            client=client,
            stats=stats,
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
    m = tex.meta
    rows = [
        ("mesh", m["source"]),
        ("read", source.note),
        ("triangles", f"{m['n_triangles']:,}"),
        ("chunks", f"{stats['chunks']:,} of up to {stats['chunk_size']:,} triangles, {_how(args, stats)}"),
        ("sub-polygons", f"{m['n_subpolygons']:,}"),
        ("grid", "x".join(str(int(s)) for s in tex.shape) + f" (h = {tex.voxel_size:.4g})"),
        ("occupied voxels", f"{tex.n_voxels:,} ({100 * tex.n_voxels / max(1, int(tex.shape.prod())):.2f}% of grid)"),
        ("shading entries", f"{tex.n_entries:,} of {tex.n_voxels * tex.n_directions:,} samples"),
        ("points", f"{len(points):,} ({args.placement})"),
        ("bytes: mesh", format_bytes(m["mesh_nbytes"])),
        ("bytes: texture", format_bytes(tex.nbytes)),
        ("bytes: points", format_bytes(points.nbytes)),
    ]
    rows += [(f"seconds: {k}", f"{v:.3f}") for k, v in timings.items()]
    rows.append(("wrote", str(out)))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0


def _how(args, stats: dict) -> str:
    if stats["executor"] == "dask":
        where = "a local Dask cluster" if args.scheduler == "local" else f"the Dask cluster at {args.scheduler}"
        return f"on {where}"
    if stats["executor"] == "process pool":
        return f"on {stats['workers']} local worker processes"
    return "in this process"


@contextlib.contextmanager
def _executor(args):
    """None (local workers), or a Dask client: of the cluster at
    ``--scheduler``, or of a LocalCluster of ``--workers`` processes made here
    and closed after the build."""
    if args.scheduler is None:
        yield None
        return
    try:
        from distributed import Client
    except ImportError:
        raise ResourceError(
            "--scheduler needs dask.distributed, which is not installed; "
            "install it with: pip install 'aniso3d[cluster]'"
        ) from None
    if args.scheduler == "local":
        from aniso3d.build.stream import local_cluster

        with local_cluster(args.workers) as cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(args.scheduler, timeout=30)
    except OSError as exc:
        raise ResourceError(f"cannot reach the Dask scheduler at '{args.scheduler}': {exc}") from None
    with client:
        yield client


def register(sub: argparse._SubParsersAction) -> None:
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
    b.add_argument("--workers", "-j", type=positive_int, default=1,
                   help="local worker processes (a process pool); with --scheduler local, the processes "
                        "of the Dask cluster made for the build. The texture is the same for any number")
    b.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="build on the Dask cluster whose scheduler is at ADDRESS (e.g. tcp://host:8786), or "
                        "'local' for a LocalCluster of --workers processes; needs aniso3d[cluster]")
    b.add_argument("--memory-budget", type=byte_size, default=None, metavar="SIZE",
                   help="memory the build plans to use (e.g. 1G; on a Dask cluster, per worker): chunk "
                        "sizes follow from it. Default: half the available memory")
    b.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    b.set_defaults(func=cmd_build)
