"""GLSL sources from the ``shaders/`` folder, with a tiny preprocessor.

``#include "file.glsl"`` pastes another file of the folder (once per program,
with a cap on nesting against circular includes); injected ``#define``s follow
the ``#version`` line; ``#line`` markers keep compiler messages pointing at
the right file and line (file numbers are listed in the error text). No GPU
is needed here, so it is tested on plain strings.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

from aniso3d.errors import Aniso3DError

MAX_INCLUDE_DEPTH = 8
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')
_VERSION = re.compile(r"^\s*#version\s+.*$")


class ShaderSourceError(Aniso3DError):
    """A shader file is missing, includes itself, or is malformed."""


def shader_dir() -> Path:
    """The folder holding the GLSL files (installed package or source tree)."""
    try:
        d = Path(str(resources.files("aniso3d.shaders")))
        if (d / "lighting.glsl").exists():
            return d
    except ModuleNotFoundError:
        pass
    d = Path(__file__).resolve().parents[2] / "shaders"
    if not d.exists():
        raise ShaderSourceError(f"GLSL folder not found (looked in {d}); reinstall aniso3d")
    return d


def read_shader(name: str, folder: Path | None = None) -> str:
    path = (folder or shader_dir()) / name
    if not path.is_file():
        raise ShaderSourceError(f"shader file '{name}' not found in {path.parent}")
    return path.read_text()


def preprocess(
    name: str,
    defines: dict[str, object] | None = None,
    loader=None,
) -> str:
    """Expand includes of shader ``name`` and inject ``defines``.

    ``loader(name) -> str`` reads a file; by default from :func:`shader_dir`.
    """
    loader = loader or read_shader
    files: list[str] = []
    included: set[str] = set()

    def expand(fname: str, depth: int, stack: tuple[str, ...]) -> list[str]:
        if fname in stack:
            raise ShaderSourceError(f"circular #include: {' -> '.join(stack + (fname,))}")
        if depth > MAX_INCLUDE_DEPTH:
            raise ShaderSourceError(f"#include nested deeper than {MAX_INCLUDE_DEPTH} at '{fname}'")
        src = loader(fname)
        files.append(fname)
        index = len(files) - 1
        out = [f"#line 1 {index}"] if depth else []
        for lineno, line in enumerate(src.splitlines(), start=1):
            m = _INCLUDE.match(line)
            if m:
                inc = m.group(1)
                if inc in stack + (fname,):
                    chain = " -> ".join(stack + (fname, inc))
                    raise ShaderSourceError(f"circular #include: {chain}")
                if inc not in included:
                    included.add(inc)
                    out += expand(inc, depth + 1, stack + (fname,))
                    out.append(f"#line {lineno + 1} {index}")
                continue
            if depth and _VERSION.match(line):
                raise ShaderSourceError(f"'{fname}' is included but has a #version line")
            out.append(line)
        return out

    lines = expand(name, 0, ())
    if not lines or not _VERSION.match(lines[0]):
        raise ShaderSourceError(f"shader '{name}' must start with a #version line")
    header = [lines[0]]
    for key, value in (defines or {}).items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", str(key)):
            raise ShaderSourceError(f"invalid define name {key!r}")
        header.append(f"#define {key} {_glsl_value(value)}")
    header.append("#line 2 0")
    body = "\n".join(header + lines[1:]) + "\n"
    # Files are numbered in #line directives; keep the names for error messages.
    return body if not files else body + "// files: " + ", ".join(f"{i}={f}" for i, f in enumerate(files)) + "\n"


def _glsl_value(value) -> str:
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value) if "." in repr(value) or "e" in repr(value) else repr(value) + ".0"
    return str(value)
