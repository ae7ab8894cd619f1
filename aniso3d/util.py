"""Small helpers shared by every stage: atomic file output, timing."""

from __future__ import annotations

import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder.

    A failed or interrupted run leaves any earlier file at ``path`` intact and
    never a half-written one: the rename is the only step that touches it.
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise InputError(f"output '{p}' is a directory; name a file to write")
    if not folder.exists():
        raise InputError(f"output folder '{folder}' does not exist; create it first")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
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


@contextmanager
def stopwatch(record: dict, key: str):
    """Add the seconds spent in the block to ``record[key]``."""
    t0 = time.perf_counter()
    try:
        yield
    finally:
        record[key] = record.get(key, 0.0) + time.perf_counter() - t0
