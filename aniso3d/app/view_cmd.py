"""``aniso3d view``: the interactive window (the package :mod:`aniso3d.app.viewer`).

Registered by :func:`aniso3d.app.cli.build_parser`. Errors (a bad input, no
display, no OpenGL, pyglet missing) are :class:`~aniso3d.errors.Aniso3DError`
and reach the user as one line and exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from aniso3d.app.common import add_point_cloud_options, image_size, load_input, point_cloud_options, positive_int


def register(sub) -> None:
    from aniso3d.app.render_cmd import AUTO, resolution_arg
    from aniso3d.app.viewer import CONTROLS, METHODS, QUALITIES, SPLATS
    from aniso3d.build.scenes import SCENES
    from aniso3d.build.texture import DEFAULT_DIRECTIONS

    keys = "\n".join(f"  {k:<20}{a}" for k, a in CONTROLS)
    p = sub.add_parser(
        "view",
        help="open an interactive window on a mesh, texture or point cloud (needs a display)",
        description=(
            "Look around a scene live with the three renderers. Needs a display and the "
            "optional extra: pip install 'aniso3d[viewer]'. Without a display, use "
            "'aniso3d render'."
        ),
        epilog="controls:\n" + keys,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", nargs="?", default=None,
                   help="mesh file, saved texture (.a3d), PLY point cloud, or scene:NAME "
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
    add_point_cloud_options(p)
    p.set_defaults(func=cmd_view)


def cmd_view(args) -> int:
    from aniso3d.app.viewer import Settings, check_display, run_viewer

    check_display()  # no display: say so before spending time on loading
    thing = load_input(args.input, point_options=point_cloud_options(args))
    settings = Settings(
        method=args.method,
        splat=args.splat,
        quality=args.quality,
        placement=args.placement,
        resolution=args.resolution,
        directions=args.directions,
    )
    name = "tree" if args.input is None else Path(args.input).name
    return run_viewer(
        thing, name, size=args.size, settings=settings, screenshot_dir=args.screenshot_dir
    )
