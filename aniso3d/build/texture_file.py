"""The ``.a3d`` texture file: a versioned container of named arrays.

An ``.a3d`` file is a zip (stored, not compressed) of one ``.npy`` member per
array and a JSON ``header.json`` holding the format name and version, the
voxel size, provenance (``meta``) and a SHA-256 of the arrays. It loads
without pickle, refuses foreign, damaged and newer files with a message that
says what to do, and equal textures give byte-equal files (fixed member
timestamps).

This module knows the container only: which arrays a texture has and what
they mean is :class:`aniso3d.build.texture.AnisoTexture`'s business, which
calls :func:`write_texture_file` and :func:`read_texture_file` from its
``save`` and ``load``. A new encoding of the arrays (a new ``FORMAT_VERSION``)
changes this module alone.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aniso3d.build.mesh import check_readable_file
from aniso3d.errors import FormatError
from aniso3d.files import atomic_write

FORMAT_NAME = "aniso3d-texture"
FORMAT_VERSION = 1

#: The arrays a texture file holds, one ``.npy`` member each.
ARRAYS = ("origin", "shape", "coords", "directions", "density", "entry_offsets",
          "entry_direction", "entry_area", "entry_kd", "entry_ks", "entry_shininess",
          "entry_centroid", "entry_normal")  # fmt: skip


@dataclass(frozen=True, eq=False)
class TextureFile:
    """What a texture file holds, checked against its header and checksum.

    Attributes:
        arrays: every name of :data:`ARRAYS` -> its array, as stored.
        voxel_size: voxel edge h, world units.
        meta: provenance (JSON values only).
    """

    arrays: dict[str, np.ndarray]
    voxel_size: float
    meta: dict


def write_texture_file(
    path: str | os.PathLike, arrays: dict[str, np.ndarray], voxel_size: float, meta: dict
) -> Path:
    """Write ``arrays`` (every name of :data:`ARRAYS`) with the voxel size and
    the JSON-representable part of ``meta``, atomically, streamed into the
    file (no second copy of the arrays in memory)."""
    arrays = {n: np.ascontiguousarray(arrays[n]) for n in ARRAYS}
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "voxel_size": float(voxel_size),
        "sha256": _digest(arrays),
        "meta": _jsonable(meta),
    }

    def write(fh) -> None:
        # Streamed into the temporary file: no copy of the texture in
        # memory (a 1 GiB texture used to need 2 GiB more to be saved).
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED) as zf:
            zf.writestr(_member("header.json"), json.dumps(header, indent=1))
            for n, a in arrays.items():
                with zf.open(_member(n + ".npy"), "w", force_zip64=a.nbytes > 2**30) as out:
                    np.save(out, a, allow_pickle=False)

    return atomic_write(path, write)


def read_texture_file(path: str | os.PathLike) -> TextureFile:
    """Read a file written by :func:`write_texture_file`; refuse foreign,
    damaged or newer files with a :class:`~aniso3d.errors.FormatError`."""
    p = check_readable_file(path, "texture")
    try:
        zf = zipfile.ZipFile(p)
    except (zipfile.BadZipFile, OSError):
        raise FormatError(
            f"'{p}' is not an aniso3d texture file (not a zip container); "
            "make one with 'aniso3d build MESH -o out.a3d'"
        ) from None
    with zf:
        try:
            header = json.loads(zf.read("header.json"))
        except KeyError:
            raise FormatError(f"'{p}' is a zip file but not an aniso3d texture (no header.json)") from None
        except (ValueError, zipfile.BadZipFile, OSError) as exc:
            raise FormatError(f"'{p}' has a damaged header: {exc}") from None
        if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
            got = header.get("format") if isinstance(header, dict) else type(header).__name__
            raise FormatError(f"'{p}' is not an aniso3d texture file (format is {got!r})")
        version = header.get("version")
        if not isinstance(version, int) or version > FORMAT_VERSION or version < 1:
            raise FormatError(
                f"'{p}' has texture format version {version!r}; this aniso3d reads version "
                f"{FORMAT_VERSION}. Upgrade aniso3d or rebuild the texture from its mesh"
            )
        arrays = {}
        try:
            for n in ARRAYS:
                # Read each array straight from its member: no second copy
                # of the file's bytes in memory; the zip CRC is still checked.
                with zf.open(n + ".npy") as member:
                    arrays[n] = np.lib.format.read_array(member, allow_pickle=False)
        except KeyError as exc:
            raise FormatError(f"'{p}' is missing array {exc}; the file is damaged") from None
        except (ValueError, zipfile.BadZipFile, OSError, EOFError) as exc:
            raise FormatError(f"'{p}' is damaged ({type(exc).__name__}: {exc}); rebuild it") from None
    if _digest(arrays) != header.get("sha256"):
        raise FormatError(f"'{p}' failed its checksum: the file is damaged; rebuild it from its mesh")
    voxel_size = header.get("voxel_size")
    if isinstance(voxel_size, bool) or not isinstance(voxel_size, (int, float)):
        raise FormatError(f"'{p}' has a damaged header: voxel_size is {voxel_size!r}")
    meta = header.get("meta", {})
    if not isinstance(meta, dict):
        raise FormatError(f"'{p}' has a damaged header: meta is not an object; rebuild it")
    return TextureFile(arrays, float(voxel_size), meta)


def _member(name: str) -> zipfile.ZipInfo:
    """A zip entry with a fixed timestamp, so equal textures give equal files."""
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = 0o600 << 16
    return info


def _digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over each array's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for n in sorted(arrays):
        a = np.ascontiguousarray(arrays[n])
        h.update(f"{n}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _jsonable(meta: dict) -> dict:
    """The entries of ``meta`` a JSON header can hold (numpy scalars as Python ones)."""
    out = {}
    for key, value in meta.items():
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, (str, int, float, bool)) or value is None:
            out[str(key)] = value
    return out
