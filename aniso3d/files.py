"""Small helpers shared by every stage: atomic file output."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from aniso3d.errors import InputError


def atomic_write(path: str | os.PathLike, data: bytes | Callable[[BinaryIO], object]) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder.

    ``data`` is bytes, or a callable that writes to the binary file object it
    is given (so large outputs are streamed, not built in memory first).
    A failed or interrupted run leaves any earlier file at ``path`` intact and
    never a half-written one: the rename is the only step that touches it.
    The file gets the permissions of the file it replaces, else the usual
    ones (0666 less the umask), not the temporary file's private 0600.
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise InputError(f"output '{p}' is a directory; name a file to write")
    if not folder.exists():
        raise InputError(f"output folder '{folder}' does not exist; create it first")
    try:
        mode = p.stat().st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh:
            if callable(data):
                data(fh)
            else:
                fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return p


def refuse_overwriting_input(output: str | os.PathLike, *inputs: str | os.PathLike | None) -> None:
    """Raise if ``output`` names the same file as one of ``inputs``."""
    out = Path(output).resolve()
    for i in inputs:
        if i is not None and Path(i).exists() and Path(i).resolve() == out:
            raise InputError(
                f"output '{output}' is the input file; aniso3d never overwrites its input. "
                "Choose another output name"
            )
