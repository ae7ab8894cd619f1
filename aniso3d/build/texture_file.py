"""The ``.a3d`` texture file: a versioned container of named arrays.

An ``.a3d`` file is a zip of one ``.npy`` member per array and a JSON
``header.json`` holding the format name and version, the voxel size,
provenance (``meta``) and a SHA-256 of the arrays. It loads without pickle,
refuses foreign, damaged and newer files with a message that says what to
do, and equal textures give byte-equal files (fixed member timestamps, a
fixed compression level).

Versions:

- **7** (written): the header names an *encoding*. ``"compact"`` (the
  default) stores the members of :func:`aniso3d.build.encoding.encode`,
  quantised and predicted from neighbouring voxels, LZMA-compressed, and the
  numbers :func:`~aniso3d.build.encoding.decode` needs (``params``, inside
  the checksum); ``"exact"`` stores the texture's arrays as they are,
  deflated.
- **6** (read only): as 7, but the compact members store every entry's
  in-plane centroid codes in ``bits.centroid`` bits (version 7 gives closed
  surfaces' entries ``centroid_closed``, not in version 6's ``params``).
- **5** (read only): as 6, without ``entry_side`` (which entries lie on
  closed surfaces, and on which side: their points are one-sided; read as
  0, every entry two-sided).
- **4** (read only): as 5, but the compact members store every entry at
  its field's bits (no coarser steps for spread normals, no ``normal_shifts``
  and ``depth_shifts`` in ``params``) and in entry order; ``entry_mask``
  is (M, K/8), ``entry_parent`` one code per entry.
- **3** (read only): as 4, without ``entry_cover`` (the share of each
  entry's facets that is not hidden behind its own voxel's closed surface;
  read as 1, every facet covering).
- **2** (read only): as 3, but the compact members are version 2's
  (:data:`~aniso3d.build.encoding.MEMBERS_V2`: no copying from neighbours,
  centroids per axis) and deflated.
- **1** (read only): the texture's arrays as they are, not compressed.

This module knows the container only: which arrays a texture has and what
they mean is :class:`aniso3d.build.texture.AnisoTexture`'s business, which
calls :func:`write_texture_file` and :func:`read_texture_file` from its
``save`` and ``load``; how they are quantised is
:mod:`aniso3d.build.encoding`'s.
"""

from __future__ import annotations

import hashlib
import io
import json
import lzma
import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from aniso3d.build.encoding import (
    ARRAYS,
    ARRAYS_V3,
    ARRAYS_V5,
    DEFAULT_BITS,
    MEMBERS,
    MEMBERS_V2,
    MEMBERS_V3,
    MEMBERS_V5,
    Bits,
    decode,
    encode,
)  # fmt: skip
from aniso3d.build.mesh import check_readable_file
from aniso3d.errors import FormatError, InputError
from aniso3d.files import atomic_write

__all__ = ["ARRAYS", "ENCODINGS", "FORMAT_NAME", "FORMAT_VERSION", "TextureFile", "encoded_size",
           "read_texture_file", "write_texture_file"]  # fmt: skip

FORMAT_NAME = "aniso3d-texture"
#: The version written; every version from 1 up to it is read.
FORMAT_VERSION = 7
#: The encodings of versions 2 to 7: quantised (default) or the arrays as they are.
ENCODINGS = ("compact", "exact")
REBUILD = "rebuild it from its mesh ('aniso3d build MESH -o out.a3d')"


@dataclass(frozen=True, eq=False)
class TextureFile:
    """What a texture file holds, checked against its header and checksum.

    Attributes:
        arrays: every name of :data:`ARRAYS` -> its array (decoded).
        voxel_size: voxel edge h, world units.
        meta: provenance (JSON values only).
        version: the file's format version (1 to 7).
        encoding: "compact" or "exact" (version 1 files are "exact").
    """

    arrays: dict[str, np.ndarray]
    voxel_size: float
    meta: dict
    version: int = FORMAT_VERSION
    encoding: str = "exact"


def write_texture_file(
    path: str | os.PathLike,
    arrays: dict[str, np.ndarray],
    voxel_size: float,
    meta: dict,
    encoding: str = "compact",
    bits: Bits = DEFAULT_BITS,
) -> Path:
    """Write ``arrays`` (every name of :data:`ARRAYS`) with the voxel size and
    the JSON-representable part of ``meta``, atomically, as format version 7
    in ``encoding`` ("compact", quantised with ``bits``, or "exact"), streamed
    into the file. The texture is encoded before the file is touched, so a
    texture that cannot be encoded leaves no file behind."""
    members, header = _prepare(arrays, voxel_size, meta, encoding, bits)
    return atomic_write(path, lambda fh: _write_zip(fh, members, header))


def encoded_size(
    arrays: dict[str, np.ndarray], voxel_size: float, meta: dict, encoding: str = "compact",
    bits: Bits = DEFAULT_BITS,
) -> int:  # fmt: skip
    """Bytes of the file :func:`write_texture_file` writes for these arguments
    (made in memory, not written)."""
    members, header = _prepare(arrays, voxel_size, meta, encoding, bits)
    buf = io.BytesIO()
    _write_zip(buf, members, header)
    return buf.tell()


def _prepare(arrays, voxel_size, meta, encoding, bits) -> tuple[dict[str, np.ndarray], dict]:
    if encoding not in ENCODINGS:
        raise InputError(f"unknown texture encoding {encoding!r}; choose one of {', '.join(ENCODINGS)}")
    if encoding == "compact":
        if not isinstance(bits, Bits):
            raise InputError(f"bits must be an aniso3d.build.encoding.Bits, got {type(bits).__name__}")
        members, params = encode(arrays, voxel_size, bits)
    else:
        members, params = {n: arrays[n] for n in ARRAYS}, {}
    members = {n: np.ascontiguousarray(a) for n, a in members.items()}
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "voxel_size": float(voxel_size),
        "encoding": encoding,
        "params": params,
        "sha256": _digest(members, _signed(encoding, params)),
        "meta": _jsonable(meta),
    }
    return members, header


def _write_zip(fh: BinaryIO, members: dict[str, np.ndarray], header: dict) -> None:
    # Streamed into the file: no second copy of the arrays in memory.
    with zipfile.ZipFile(fh, "w") as zf:
        # deflated since version 5 (its parameters' tables: 1.9 KiB stored, 0.5 deflated)
        zf.writestr(_member("header.json", deflate=True), json.dumps(header, indent=1))
        lzma = header["encoding"] == "compact"
        for n, a in members.items():
            with zf.open(_member(n + ".npy", deflate=True, lzma=lzma), "w", force_zip64=a.nbytes > 2**30) as out:
                np.save(out, a, allow_pickle=False)


def read_texture_file(path: str | os.PathLike) -> TextureFile:
    """Read a file written by :func:`write_texture_file` (or a version 1
    file); refuse foreign, damaged or newer files with a
    :class:`~aniso3d.errors.FormatError` that says what to do."""
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
        except (ValueError, zipfile.BadZipFile, OSError, EOFError, zlib.error, lzma.LZMAError) as exc:
            raise FormatError(f"'{p}' has a damaged header: {exc}; {REBUILD}") from None
        if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
            got = header.get("format") if isinstance(header, dict) else type(header).__name__
            raise FormatError(f"'{p}' is not an aniso3d texture file (format is {got!r})")
        version = header.get("version")
        if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
            raise FormatError(
                f"'{p}' has texture format version {version!r}; this aniso3d reads versions 1 to "
                f"{FORMAT_VERSION}. Upgrade aniso3d, or {REBUILD}"
            )
        encoding, params = "exact", {}
        if version >= 2:
            encoding, params = header.get("encoding"), header.get("params")
            if encoding not in ENCODINGS:
                raise FormatError(
                    f"'{p}' has texture encoding {encoding!r}; this aniso3d reads "
                    f"{', '.join(ENCODINGS)}. Upgrade aniso3d, or {REBUILD}"
                )
            if not isinstance(params, dict):
                raise FormatError(f"'{p}' has a damaged header: params is not an object; {REBUILD}")
        exact = ARRAYS if version >= 6 else ARRAYS_V5 if version >= 4 else ARRAYS_V3
        names = exact if encoding == "exact" else _compact_members(params, version)
        members = {}
        for n in names:
            try:
                # Straight from the member: no second copy of the file's bytes
                # in memory; the zip CRC is still checked.
                with zf.open(n + ".npy") as member:
                    members[n] = np.lib.format.read_array(member, allow_pickle=False)
            except KeyError:
                raise FormatError(f"'{p}' is missing array '{n}'; the file is damaged: {REBUILD}") from None
            except (ValueError, zipfile.BadZipFile, OSError, EOFError, zlib.error, lzma.LZMAError) as exc:
                raise FormatError(f"'{p}' is damaged ({type(exc).__name__}: {exc}); {REBUILD}") from None
    signed = _signed(encoding, params) if version >= 2 else None
    if _digest(members, signed) != header.get("sha256"):
        raise FormatError(f"'{p}' failed its checksum: the file is damaged; {REBUILD}")
    voxel_size = header.get("voxel_size")
    if isinstance(voxel_size, bool) or not isinstance(voxel_size, (int, float)):
        raise FormatError(f"'{p}' has a damaged header: voxel_size is {voxel_size!r}; {REBUILD}")
    meta = header.get("meta", {})
    if not isinstance(meta, dict):
        raise FormatError(f"'{p}' has a damaged header: meta is not an object; {REBUILD}")
    if encoding == "compact":
        try:
            arrays = decode(members, params, float(voxel_size), version)
        except FormatError as exc:
            raise FormatError(f"'{p}' is damaged: {exc}; {REBUILD}") from None
    else:
        arrays = dict(members)
        if "entry_cover" not in arrays:  # files before version 4: every facet covers
            arrays["entry_cover"] = np.ones(len(arrays["entry_direction"]), dtype=np.float32)
        if "entry_side" not in arrays:  # files before version 6: every entry two-sided
            arrays["entry_side"] = np.zeros(len(arrays["entry_direction"]), dtype=np.int8)
    return TextureFile(arrays, float(voxel_size), meta, version, encoding)


def _compact_members(params: dict, version: int) -> tuple[str, ...]:
    """The members a compact file of ``version`` must hold: all of
    :data:`MEMBERS` (version 3: :data:`MEMBERS_V3`, 2: :data:`MEMBERS_V2`), but ``density`` only
    when its residual is stored."""
    bits = params.get("bits")
    stored = not isinstance(bits, dict) or bits.get("density", 1) != 0
    names = MEMBERS if version >= 6 else MEMBERS_V5 if version >= 4 else MEMBERS_V3 if version >= 3 else MEMBERS_V2
    return tuple(n for n in names if n != "density" or stored)


def _member(name: str, deflate: bool = False, lzma: bool = False) -> zipfile.ZipInfo:
    """A zip entry with a fixed timestamp (and zlib's default level when
    deflated, LZMA's default preset with ``lzma``), so equal textures give
    equal files."""
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = 0o600 << 16
    if deflate:
        info.compress_type = zipfile.ZIP_LZMA if lzma else zipfile.ZIP_DEFLATED
    return info


def _signed(encoding: str, params: dict) -> str:
    """The header values the checksum covers besides the arrays (versions 2 and later)."""
    return json.dumps({"encoding": encoding, "params": params}, sort_keys=True)


def _digest(arrays: dict[str, np.ndarray], signed: str | None = None) -> str:
    """SHA-256 over each array's name, dtype, shape and bytes, in name order,
    then (versions 2 and later) the encoding and its parameters."""
    h = hashlib.sha256()
    for n in sorted(arrays):
        a = np.ascontiguousarray(arrays[n])
        h.update(f"{n}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    if signed is not None:
        h.update(signed.encode())
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
