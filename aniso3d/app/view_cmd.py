"""``aniso3d view``: the interactive window (the package :mod:`aniso3d.app.viewer`).

Registered by :func:`aniso3d.app.cli.build_parser`. Errors (a bad input, no
display, no OpenGL, pyglet missing) are :class:`~aniso3d.errors.Aniso3DError`
and reach the user as one line and exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from aniso3d.app.common import (
    add_point_cloud_options,
    image_size,
    load_input,
    load_scene_input,
    point_cloud_options,
    positive_int,
)

#: Trees of ``--scene forest`` when ``--trees`` is not given.
FOREST_TREES = 100


def register(sub) -> None:
    from aniso3d.app.render_cmd import AUTO, resolution_arg
    from aniso3d.app.viewer import CONTROLS, METHODS, QUALITIES, SPLATS
    from aniso3d.build.scenes import SCENES
    from aniso3d.build.texture import DEFAULT_DIRECTIONS

    keys = "\n".join(f"  {k:<20}{a}" for k, a in CONTROLS)
    p = sub.add_parser(
        "view",
        help="open an interactive window on a mesh, texture, point cloud or scene (needs a display)",
        description=(
            "Look around a scene live with the three renderers. Needs a display and the "
            "optional extra: pip install 'aniso3d[viewer]'. Without a display, use "
            "'aniso3d render'."
        ),
        epilog="controls:\n" + keys,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", nargs="?", default=None,
                   help="mesh file, saved texture (.a3d), PLY point cloud, glTF file (.gltf, .glb: a scene "
                        "when its nodes place meshes more than once), or scene:NAME "
                        f"({', '.join(SCENES)}); default: the built-in tree")  # fmt: skip
    p.add_argument("--size", type=image_size, default=(960, 640), help="window size, e.g. 1280x800")
    p.add_argument("--method", choices=METHODS, default=None,
                   help="renderer to start with (default: what the input is)")  # fmt: skip
    p.add_argument("--resolution", "-r", type=resolution_arg, default=AUTO,
                   help="voxels along the longest axis when a mesh is converted, or 'auto' (default): "
                        "as many as the start view needs (a power of two from 8 to 256); [ and ] step it")  # fmt: skip
    p.add_argument(
        "--directions", "-k", type=positive_int, default=DEFAULT_DIRECTIONS,
        help="sphere sample directions K"
    )
    p.add_argument("--placement", choices=("centroid", "center", "sphere"), default="centroid")
    p.add_argument("--splat", choices=SPLATS, default="disc")
    p.add_argument("--quality", choices=QUALITIES, default="fast")
    p.add_argument("--screenshot-dir", default=".", help="folder for screenshots (key c or F12)")
    p.add_argument("--scene", default=None, metavar="forest|FILE.gltf",
                   help="view a scene of instances instead of one input: the built-in forest or a glTF file "
                        "whose nodes share meshes (EXT_mesh_gpu_instancing too)")  # fmt: skip
    p.add_argument("--trees", type=positive_int, default=None,
                   help=f"trees of --scene forest (default {FOREST_TREES})")  # fmt: skip
    add_point_cloud_options(p)
    p.set_defaults(func=cmd_view)


def check_view_arguments(args) -> None:
    """One :class:`~aniso3d.errors.InputError` for a bad combination of the
    input, ``--scene``, ``--trees`` and the point-cloud options (before any
    window or file is opened)."""
    from aniso3d.build.scene import GLTF_SUFFIXES
    from aniso3d.errors import InputError

    points = point_cloud_options(args)
    if args.scene is not None:
        if args.input is not None:
            raise InputError(f"give either an input ('{args.input}') or --scene, not both")
        if points:
            flags = ", ".join("--" + k.replace("_", "-") for k in points)
            raise InputError(f"{flags} for PLY point clouds only; --scene is not one")
        if args.scene != "forest" and Path(args.scene).suffix.lower() not in GLTF_SUFFIXES:
            load_scene_input(args.scene)  # its one error for anything else
        if args.trees is not None and args.scene != "forest":
            raise InputError(f"--trees applies to --scene forest, not to --scene '{args.scene}'")
    elif args.trees is not None:
        raise InputError("--trees applies to --scene forest; add --scene forest (or leave --trees out)")


def read_view_input(args):
    """What ``aniso3d view`` opens: ``--scene`` (a :class:`~aniso3d.build.scene.Scene`),
    a glTF input whose nodes place meshes more than once (a Scene too), or
    the input as ``aniso3d render`` reads it (a glTF of one placed mesh: that mesh)."""
    from aniso3d.build.scene import GLTF_SUFFIXES

    check_view_arguments(args)
    points = point_cloud_options(args)
    if args.scene is not None:
        return load_scene_input(args.scene, FOREST_TREES if args.trees is None else args.trees)
    if args.input is not None and not points and Path(args.input).suffix.lower() in GLTF_SUFFIXES:
        scene = load_scene_input(args.input)
        if scene.n_instances > 1:
            return scene
    return load_input(args.input, point_options=points)


def cmd_view(args) -> int:
    from aniso3d.app.viewer import Settings, check_display, run_viewer
    from aniso3d.app.viewer.worker import builds_running
    from aniso3d.build.scene import Scene

    check_view_arguments(args)  # a bad combination of arguments: say so first
    check_display()  # no display: say so before spending time on loading
    thing = read_view_input(args)
    settings = Settings(
        method=args.method,
        splat=args.splat,
        quality=args.quality,
        placement=args.placement,
        resolution=args.resolution,
        directions=args.directions,
    )
    if isinstance(thing, Scene):
        name = f"{thing.name} ({thing.n_instances:,} instances)"
    else:
        name = "tree" if args.input is None else Path(args.input).name
    status = run_viewer(
        thing, name, size=args.size, settings=settings, screenshot_dir=args.screenshot_dir
    )
    if builds_running():
        # Quit mid-build: the window, its GPU objects and every file are
        # closed; end the process here rather than finalise the interpreter
        # under the build thread (see builds_running).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status
