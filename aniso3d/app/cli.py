"""The ``aniso3d`` command: build, render, frames, bench, view.

Every subcommand turns :class:`~aniso3d.errors.Aniso3DError` into one line on
stderr and exit status 2; outputs are written atomically, never over an input.
Each subcommand lives in its own module and registers its parser here.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from aniso3d.app import bench_cmd, build_cmd, render_cmd, view_cmd
from aniso3d.errors import Aniso3DError, InputWarning
from aniso3d.rendering.video import is_video_path


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


    for register in (build_cmd.register, render_cmd.register, bench_cmd.register, view_cmd.register):
        register(sub)
    return parser


class _Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that a run killed by ``kill`` or a
    job scheduler unwinds like Ctrl-C: no temporary file left behind."""


def _on_sigterm(signum, frame):
    raise _Terminated


def _one_line_warnings(command: str, show):
    """``warnings.showwarning`` that prints an
    :class:`~aniso3d.errors.InputWarning` as one line on stderr (what was not
    read, and what to do) and hands any other warning to ``show``."""

    def one_line(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, InputWarning):
            print(f"aniso3d {command}: warning: {message}", file=sys.stderr)
        else:
            show(message, category, filename, lineno, file, line)

    return one_line


def main(argv: list[str] | None = None) -> int:
    import signal
    import threading

    parser = build_parser()
    args = parser.parse_args(argv)
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if in_main else None
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warnings(args.command, warnings.showwarning)
            return int(args.func(args) or 0)
    except Aniso3DError as exc:
        print(f"aniso3d {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        # Every file is written atomically: what was being written is not
        # there, and earlier outputs (or frames already finished) are whole.
        pngs = args.command == "frames" and not is_video_path(args.output)
        what = "frames finished so far are complete" if pngs else "no output was written"
        print(f"aniso3d {args.command}: interrupted; {what}", file=sys.stderr)
        return 128 + signal.SIGTERM if isinstance(exc, _Terminated) else 130
    except OSError as exc:
        # A file or folder that cannot be read or written (read-only, full,
        # no permission): one line; outputs are atomic, so nothing half-written.
        where = f" '{exc.filename}'" if exc.filename else ""
        print(f"aniso3d {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
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
