"""``aniso3d bench``: the speed/size/accuracy sweep (see :mod:`aniso3d.bench`),
with ``--corpus`` the corpus bench (:mod:`aniso3d.bench.corpus`), and
``aniso3d bench peers`` the point renderers side by side (:mod:`aniso3d.bench.peers`)
and ``aniso3d bench forest`` frame time against instance count (:mod:`aniso3d.bench.forest`).

This module owns the command line: it parses the options, loads the input and
hands the bench a mesh, the settings and a progress bar; the bench itself knows
nothing of the command line.
"""

from __future__ import annotations

import argparse
import itertools
import shlex
import sys
from pathlib import Path

from aniso3d.app.common import Progress, image_size, load_input, positive_int
from aniso3d.errors import InputError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "bench",
        help="measure speed, size and error of every renderer and setting against a supersampled ground truth",
        description=(
            "Sweep resolution, directions K, point placement, splat shape, quality, renderer and camera "
            "distance for a scene; write results.csv, results.json, plots and report.md into OUTDIR. "
            "'aniso3d bench peers' draws one point cloud with aniso3d and other point renderers "
            "(see 'aniso3d bench peers --help'); 'aniso3d bench forest' times forests of 1 to 10,000 trees "
            "(see 'aniso3d bench forest --help')."
        ),
    )
    p.add_argument("mesh", nargs="?", default=None, help="mesh file or scene:NAME (default: the built-in tree)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help="a run of a few minutes (256x256, fewer settings)")
    mode.add_argument("--smoke", action="store_true", help="a run of seconds that exercises every path (tests)")
    p.add_argument("-o", "--output", default="bench-out", metavar="OUTDIR", help="output folder (default: ./bench-out)")
    p.add_argument("--size", type=image_size, default=None, help="image size, e.g. 512 or 800x600 (default: preset's)")
    p.add_argument("--frames", type=positive_int, default=None, help="timed frames per configuration")
    p.add_argument("--gt-ssaa", type=positive_int, default=None, help="ground-truth samples per pixel along each axis")
    p.add_argument("--no-flip", action="store_true", help="skip FLIP even when flip-evaluator is installed")
    p.add_argument("--no-plots", action="store_true", help="write CSV, JSON and the report only")
    p.add_argument("--backend", default="auto", help="OpenGL backend: auto, egl, osmesa, x11")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    corpus = p.add_argument_group("corpus bench")
    corpus.add_argument("--corpus", action="store_true",
                        help="run every built-in corpus scene at the default texture and write corpus_bench.md, "
                             ".csv and .json into OUTDIR (512x512; --quick: 256x256, few frames)")
    corpus.add_argument("--scenes", type=_scene_list, default=None, metavar="A,B",
                        help="corpus scenes to run (default: all of them)")
    corpus.add_argument("--meshes", type=_path_list, default=None, metavar="PATH,PATH",
                        help="your own meshes, measured like the corpus scenes: files, or folders whose mesh "
                             "files are all taken (instead of the built-in scenes, unless --scenes names some)")
    corpus.add_argument("--turntable", type=positive_int, default=None, metavar="N",
                        help="turntable frames for the flicker measurement (default: the preset's)")
    p.set_defaults(func=cmd_bench)
    _add_subcommands(p, {"peers": _peers_parser(p), "forest": _forest_parser(p)})


def _add_subcommands(bench: argparse.ArgumentParser, parsers: dict) -> None:
    """``aniso3d bench WORD ...``: the bench's first positional is a mesh, so
    its parser hands everything after one of these words to that word's parser."""
    original = bench.parse_known_args

    def parse_known_args(args=None, namespace=None):
        args = list(sys.argv[1:] if args is None else args)
        if args[:1] and args[0] in parsers:
            ns, rest = parsers[args[0]].parse_known_args(args[1:], namespace)
            ns.sub_argv = args[1:]
            return ns, rest
        return original(args, namespace)

    bench.parse_known_args = parse_known_args


def _forest_parser(bench: argparse.ArgumentParser) -> argparse.ArgumentParser:
    from aniso3d.bench.forest import COUNTS

    forest = type(bench)(
        prog="aniso3d bench forest",
        description=(
            "Frame time of aniso3d.scenes.forest(n) for each n, seen over the forest so that every forest "
            "covers the same screen area, per renderer (polygons up to 1,000 trees), and the error of splats "
            "and volume against 8x8 polygons up to 100 trees; writes forest.md and forest.png into OUTDIR "
            "(needs matplotlib: pip install 'aniso3d[plots]')."
        ),
    )
    forest.add_argument("--size", type=positive_int, default=512, help="square image size (default 512)")
    forest.add_argument("--reps", type=positive_int, default=3, help="timed frames per method and count")
    forest.add_argument("--error-size", type=positive_int, default=256, help="image size of the error table")
    forest.add_argument("--counts", type=positive_int, nargs="+", default=list(COUNTS), metavar="N",
                        help="tree counts (default: 1 10 100 1000 10000)")  # fmt: skip
    forest.add_argument("--no-passes", action="store_true",
                        help="leave out the volume drawn one pass per instance (the comparison)")  # fmt: skip
    forest.add_argument("-o", "--output", default="bench-out", metavar="OUTDIR", help="output folder")
    forest.add_argument("--backend", default="auto", help="OpenGL backend: auto, egl, osmesa, x11")
    forest.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    forest.set_defaults(func=cmd_forest, command="bench forest")
    return forest


def cmd_forest(args: argparse.Namespace) -> int:
    from aniso3d.bench.forest import ForestSettings, check_output, run_forest, write_report

    check_output(Path(args.output))  # before the run, not after it

    settings = ForestSettings(size=args.size, reps=args.reps, error_size=args.error_size, counts=tuple(args.counts),
                              no_passes=args.no_passes, backend=args.backend)  # fmt: skip
    progress = Progress("bench forest", enabled=False if args.quiet else None)
    rows, errors, load = run_forest(settings, progress=progress)
    for r in rows:
        print(f"{r['n']:>6} trees  {r['method']:<14} {r['median_ms']:8.1f} ms ({r['min_ms']:.1f}-{r['max_ms']:.1f})")
    command = "aniso3d bench forest " + shlex.join(args.sub_argv)
    print(f"wrote {write_report(rows, errors, load, settings, Path(args.output), command)}")
    return 0


def _peers_parser(bench: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``aniso3d bench peers``: the point renderers side by side (see :func:`_add_subcommands`)."""
    from aniso3d.bench.peers import CONTENDERS

    peers = type(bench)(
        prog="aniso3d bench peers",
        description=(
            "Draw one point cloud (default: a generated noisy torus, binary PLY without sizes) with aniso3d "
            "(splats fast and high), a bare GL_POINTS floor and the peers that are installed (PyVista points "
            "and points_gaussian, pyrender, Open3D: pip install 'aniso3d[peers]'), at one image size and "
            "camera path; report frame time, peak memory and the holes inside the truth's silhouette."
        ),
    )
    peers.add_argument("ply", nargs="?", default=None, help="a PLY point cloud (default: the generated torus)")
    peers.add_argument("--points", type=positive_int, default=1_000_000, help="points of the torus (default 1M)")
    peers.add_argument("--size", type=image_size, default=(1024, 1024), help="image size (default 1024)")
    peers.add_argument("--frames", type=positive_int, default=6, help="timed frames per contender (>= 5)")
    peers.add_argument("--rounds", type=positive_int, default=3, help="interleaved rounds the frames are split in")
    peers.add_argument("--contenders", type=_contender_list, default=tuple(CONTENDERS), metavar="A,B",
                       help=f"which to run (default all: {','.join(CONTENDERS)})")
    peers.add_argument("-o", "--output", default=None, metavar="FILE.md",
                       help="write the report here (between its markers if the file has them)")
    peers.add_argument("--images", default=None, metavar="DIR", help="save each contender's first view as PNG")
    peers.add_argument("--backend", default="auto", help="OpenGL backend of aniso3d's contenders")
    peers.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    peers.set_defaults(func=cmd_peers, command="bench peers")
    return peers


def _contender_list(text: str) -> tuple[str, ...]:
    from aniso3d.bench.peers import CONTENDERS

    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in CONTENDERS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown contender '{','.join(bad) or text}'; choose from "
                                         f"{', '.join(CONTENDERS)}")  # fmt: skip
    return names


def cmd_peers(args: argparse.Namespace) -> int:
    from aniso3d.bench.peers import PeerSettings, peers_command, run_peers, table, targets, write_report
    from aniso3d.build.ply import read_ply_header

    if args.ply is not None:
        from aniso3d.build.mesh import check_readable_file

        if not read_ply_header(check_readable_file(args.ply, "input")).is_point_cloud:
            raise InputError(f"'{args.ply}' has faces; bench peers draws point clouds (a PLY without faces)")
    if args.output is not None:
        from aniso3d.files import refuse_overwriting_input

        refuse_overwriting_input(args.output, args.ply)
    settings = PeerSettings(ply=Path(args.ply) if args.ply else None, points=args.points, size=args.size,
                            frames=args.frames, rounds=args.rounds, contenders=args.contenders,
                            backend=args.backend, images=Path(args.images) if args.images else None)  # fmt: skip
    progress = Progress("bench peers", enabled=False if args.quiet else None)
    result = run_peers(settings, progress=progress)
    print("\n".join(table(result) + [""] + targets(result)))
    for r in result.rows:
        if r.status == "skipped":
            print(f"skipped: {r.label}: {r.note}")
    if args.output is not None:
        print(f"wrote {write_report(result, args.output, peers_command(args.sub_argv))}")
    return 0


def _scene_list(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"expected scene names separated by commas, got '{text}'")
    return names


def _path_list(text: str) -> tuple[str, ...]:
    paths = tuple(n.strip() for n in text.split(",") if n.strip())
    if not paths:
        raise argparse.ArgumentTypeError(f"expected mesh files or folders separated by commas, got '{text}'")
    return paths


def mesh_files(paths: tuple[str, ...]) -> list[Path]:
    """The mesh files ``--meshes`` names: files as given, folders' mesh files
    (by suffix) in name order. A path that does not exist is an error."""
    from aniso3d.build.mesh import MESH_SUFFIXES

    files: list[Path] = []
    for text in paths:
        p = Path(text)
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in MESH_SUFFIXES)
            if not found:
                raise InputError(f"folder '{p}' holds no mesh files ({', '.join(sorted(MESH_SUFFIXES))})")
            files += found
        elif p.exists():
            files.append(p)
        else:
            raise InputError(f"--meshes: '{p}' does not exist; check the path")
    return files


def readable_meshes(files: list[Path], say=print):
    """(name, mesh) for each file, read when the run reaches it; a file that
    cannot be read is skipped with its one-line reason (a sweep over someone
    else's folder must not stop at its first broken file)."""
    from aniso3d.build.mesh import load_mesh

    names: dict[str, int] = {}
    for f in files:
        try:
            mesh = load_mesh(f)
        except InputError as exc:
            say(f"skipped {f}: {exc}")
            continue
        k = names.get(f.stem, 0)
        names[f.stem] = k + 1
        yield (f.stem if k == 0 else f"{f.stem}~{k}"), mesh


def corpus_command(args: argparse.Namespace) -> str:
    """The one command line that repeats this corpus run (printed atop its report)."""
    parts = ["aniso3d", "bench", "--corpus"]
    if args.quick:
        parts.append("--quick")
    if args.size:
        w, h = args.size
        parts += ["--size", str(w) if w == h else f"{w}x{h}"]
    for flag, value in (("--frames", args.frames), ("--gt-ssaa", args.gt_ssaa), ("--turntable", args.turntable)):
        if value:
            parts += [flag, str(value)]
    if args.scenes:
        parts += ["--scenes", ",".join(args.scenes)]
    if args.meshes:
        parts += ["--meshes", ",".join(args.meshes)]
    if args.no_flip:
        parts.append("--no-flip")
    if args.backend != "auto":
        parts += ["--backend", args.backend]
    return shlex.join([*parts, "-o", str(args.output)])


def cmd_corpus(args: argparse.Namespace) -> int:
    from aniso3d.bench.corpus import corpus_settings, run_corpus
    from aniso3d.bench.corpus_report import write_corpus

    if args.smoke:
        raise InputError("--corpus takes --quick or the full preset, not --smoke")
    if args.mesh:
        raise InputError(f"--corpus runs the built-in scenes, not '{args.mesh}'; choose them with --scenes")
    settings = corpus_settings("quick" if args.quick else "full", size=args.size, frames=args.frames,
                               gt_ssaa=args.gt_ssaa, turntable=args.turntable, scene_names=args.scenes)
    outdir = Path(args.output)
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"output '{outdir}' is a file; the corpus bench writes into a folder")
    pairs, n_meshes = None, None
    if args.meshes:
        from aniso3d.build import scenes

        files = mesh_files(args.meshes)
        own = readable_meshes(files, say=lambda text: print(text, file=sys.stderr))
        pairs = itertools.chain(scenes.corpus(args.scenes) if args.scenes else (), own)
        n_meshes = len(args.scenes or ()) + len(files)
    progress = Progress(f"corpus {settings.name}", enabled=False if args.quiet else None)
    result = run_corpus(settings, meshes=pairs, progress=progress, with_flip=False if args.no_flip else None,
                        backend=args.backend, n_meshes=n_meshes)
    for path in write_corpus(result, outdir, corpus_command(args)):
        print(f"wrote {path}")
    for s in result.scenes:
        verdicts = " ".join(f"{t}={'pass' if v else 'n/a' if v is None else 'FAIL'}" for t, v in s["targets"].items())
        print(f"{s['scene']}: {verdicts}")
    for r in result.failed:
        print(f"failed: {r['scene']} {r['camera']} {r['renderer']}: {r['reason']}", file=sys.stderr)
    return 1 if result.failed else 0


def cmd_bench(args: argparse.Namespace) -> int:
    from aniso3d.bench import label, preset_settings, run_bench, write_outputs
    from aniso3d.build.mesh import Mesh

    if args.corpus:
        return cmd_corpus(args)
    if args.scenes or args.turntable or args.meshes:
        raise InputError("--scenes, --meshes and --turntable apply to the corpus bench; add --corpus")
    preset = "smoke" if args.smoke else "quick" if args.quick else "full"
    settings = preset_settings(preset, size=args.size, frames=args.frames, gt_ssaa=args.gt_ssaa)
    outdir = Path(args.output)
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"output '{outdir}' is a file; bench writes a folder of results")
    if args.mesh and Path(args.mesh).exists() and Path(args.mesh).resolve() == outdir.resolve():
        raise InputError(f"output folder '{outdir}' is the input; choose another -o")
    mesh = load_input(args.mesh)
    if not isinstance(mesh, Mesh):
        raise InputError(f"'{args.mesh}' is not a polygon mesh; the bench needs the polygons for its ground truth")
    outdir.mkdir(parents=True, exist_ok=True)
    progress = Progress(f"bench {settings.name}", enabled=False if args.quiet else None)
    result = run_bench(mesh, settings, progress=progress, with_flip=False if args.no_flip else None,
                       backend=args.backend)  # fmt: skip
    inputs = (args.mesh,) if args.mesh else ()
    written, notes = write_outputs(result, outdir, inputs=inputs, with_plots=not args.no_plots)
    counts = {s: sum(r["status"] == s for r in result.rows) for s in ("ok", "skipped", "failed")}
    print(
        f"{len(result.rows)} configurations in {result.meta['seconds']:.0f} s: "
        f"{counts['ok']} measured, {counts['skipped']} skipped, {counts['failed']} failed"
    )
    for reason in sorted({r["reason"] for r in result.rows if r["status"] == "skipped"}):
        print(f"skipped: {reason}")
    for note in notes:
        print(f"note: {note}")
    for path in written:
        print(f"wrote {path}")
    for r in result.failed:
        print(f"failed: {label(r, verbose=True)} at {r['camera']}: {r['reason']}", file=sys.stderr)
    return 1 if result.failed else 0


__all__ = ["cmd_bench", "cmd_corpus", "cmd_peers", "corpus_command", "register"]
