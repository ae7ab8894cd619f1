"""Bad input never costs a user data (issue 6), end to end through the CLI.

Every bad file or option gets exactly one line on stderr, ``aniso3d CMD:
error: ...`` (no traceback, no argparse usage block) and exit status 2; no
output appears. Outputs are written atomically: a failed, interrupted or
killed run leaves an earlier output intact and no half-written file, and
aniso3d never writes over its input. A build that cannot fit in memory is
refused with the estimate and what to change.

Most runs go through ``aniso3d.app.cli.main`` in-process; a few are real
subprocesses (signals, a clean interpreter). Loading and option errors are
raised before any OpenGL context is made, so nothing here needs a GPU except
where marked.
"""

from __future__ import annotations

import io
import json
import os
import signal
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh

import aniso3d.build.texture
import aniso3d.files
from aniso3d import AnisoTexture, build_texture, scenes
from aniso3d.app.cli import main

EXE = [sys.executable, "-m", "aniso3d.app.cli"]


def run(argv, capsys) -> tuple[int, str, str]:
    """Run the CLI in-process: (status, stdout, stderr). argparse errors end
    in SystemExit; its code is the status."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str, command: str, *words: str) -> str:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"aniso3d {command}: error: "), lines[0]
    for w in words:
        assert w.lower() in lines[0].lower(), (w, lines[0])
    return lines[0]


def leftovers(folder: Path) -> list[str]:
    """Temporary files atomic_write would leave behind."""
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


# ------------------------------------------------------------------ bad files


def _sphere() -> trimesh.Trimesh:
    return scenes.sphere(1.0, subdivisions=2).to_trimesh()


def _cut(data: bytes, fraction: float = 0.5) -> bytes:
    return data[: int(len(data) * fraction)]


def _ply_header(n_vertices: int, n_faces: int) -> bytes:
    return (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {n_vertices}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {n_faces}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()


def _ply(vertices, faces) -> bytes:
    body = np.asarray(vertices, "<f4").tobytes()
    body += b"".join(struct.pack("<B3i", 3, *f) for f in faces)
    return _ply_header(len(vertices), len(faces)) + body


TRIANGLE = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]

#: name, file contents (None: no file; "dir": a directory), words the one
#: error line must contain
BAD_MESHES = [
    ("missing.obj", None, ["does not exist"]),
    ("folder.obj", "dir", ["is a directory"]),
    ("empty.obj", b"", ["is empty"]),
    (
        "cut.obj",
        lambda: _cut(trimesh.exchange.obj.export_obj(_sphere()).encode(), 0.3),
        ["truncated"],
    ),
    ("cut.ply", lambda: _cut(trimesh.exchange.ply.export_ply(_sphere())), ["truncated"]),
    (
        "cut_ascii.ply",
        lambda: _cut(trimesh.exchange.ply.export_ply(_sphere(), encoding="ascii")),
        ["declares 320 faces", "truncated"],
    ),
    (
        "cut.glb",
        lambda: _cut(trimesh.exchange.gltf.export_glb(trimesh.Scene(_sphere()))),
        ["truncated"],
    ),
    (
        "cut.stl",
        lambda: _cut(trimesh.exchange.stl.export_stl(_sphere())),
        ["declares 320 triangles", "truncated"],
    ),
    ("mesh.xyz", b"1 2 3\n", ["does not read as a mesh", ".obj"]),
    ("noise.glb", bytes(range(256)) * 8, ["not in the format its suffix says"]),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", ["no triangles"]),
    (
        "points.ply",
        _ply_header(3, 0) + np.asarray(TRIANGLE, "<f4").tobytes(),
        ["point cloud", "no faces"],
    ),
    ("nan.obj", b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", ["nan.obj", "NaN or Inf"]),
    (
        "inf.ply",
        _ply([[0, 0, 0], [np.inf, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
        ["inf.ply", "NaN or Inf"],
    ),
    ("index.ply", _ply(TRIANGLE, [[0, 1, 9]]), ["outside 0..2", "damaged"]),
    ("index.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", ["out of bounds"]),
    ("flat.obj", b"v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n", ["zero extent"]),
]


def make_input(folder: Path, name: str, content) -> Path:
    path = folder / name
    if content == "dir":
        path.mkdir()
    elif content is not None:
        path.write_bytes(content() if callable(content) else content)
    return path


@pytest.mark.parametrize("name, content, words", BAD_MESHES, ids=[c[0] for c in BAD_MESHES])
def test_bad_mesh_files_build(tmp_path, capsys, name, content, words):
    src = make_input(tmp_path, name, content)
    out = tmp_path / "out.a3d"
    code, stdout, err = run(["build", src, "-o", out, "-r", 8, "-k", 8, "-q"], capsys)
    assert code == 2
    one_line_error(err, "build", *words)
    assert stdout == "" and not out.exists() and leftovers(tmp_path) == []


@pytest.mark.parametrize("command", ["render", "frames"])
@pytest.mark.parametrize(
    "name, content, words", BAD_MESHES[:10], ids=[c[0] for c in BAD_MESHES[:10]]
)
def test_bad_mesh_files_render_and_frames(tmp_path, capsys, command, name, content, words):
    # The same files through the renderers' front ends: refused while loading,
    # before any OpenGL context is made.
    src = make_input(tmp_path, name, content)
    out = tmp_path / ("out.png" if command == "render" else "frames")
    code, _, err = run([command, src, "-o", out, "--size", "16"], capsys)
    assert code == 2
    # What the renderers read besides meshes is named too.
    one_line_error(err, command, *words, *([".a3d", "point cloud"] if name == "mesh.xyz" else []))
    assert not out.exists()


# -------------------------------------------------------------- bad textures


@pytest.fixture(scope="module")
def texture_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("tex") / "good.a3d"
    build_texture(scenes.sphere(1.0, subdivisions=2), 8, 8).save(path)
    return path


def _rewrite(src: Path, dst: Path, header=None, arrays=None, drop=()):
    """Copy a texture file member by member, changing what is asked: a
    well-formed zip (valid CRCs) with a changed content."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            if name in drop:
                continue
            data = zin.read(name)
            if name == "header.json" and header:
                h = json.loads(data)
                header(h)
                data = json.dumps(h).encode()
            if arrays and name in arrays:
                data = arrays[name](data)
            zout.writestr(name, data)


def _flip_last_byte(data: bytes) -> bytes:
    return data[:-1] + bytes([data[-1] ^ 0x01])


BAD_TEXTURES = [
    (
        "flipped byte",
        lambda src, dst: dst.write_bytes(
            (lambda b: b[: len(b) // 2] + bytes([b[len(b) // 2] ^ 0xFF]) + b[len(b) // 2 + 1 :])(
                src.read_bytes()
            )
        ),
        ["damaged", "rebuild"],
    ),
    (
        "truncated",
        lambda src, dst: dst.write_bytes(_cut(src.read_bytes(), 0.6)),
        ["not an aniso3d texture"],
    ),
    (
        "checksum",
        lambda src, dst: _rewrite(src, dst, arrays={"density.npy": _flip_last_byte}),
        ["checksum", "damaged"],
    ),
    (
        "newer version",
        lambda src, dst: _rewrite(src, dst, header=lambda h: h.update(version=99)),
        ["version 99", "Upgrade aniso3d"],
    ),
    (
        "other format",
        lambda src, dst: _rewrite(src, dst, header=lambda h: h.update(format="gltf")),
        ["not an aniso3d texture"],
    ),
    (
        "no header",
        lambda src, dst: _rewrite(src, dst, drop=("header.json",)),
        ["not an aniso3d texture"],
    ),
    (
        "missing array",
        lambda src, dst: _rewrite(src, dst, drop=("density.npy",)),
        ["missing", "damaged"],
    ),
    ("plain text", lambda src, dst: dst.write_text("hello"), ["not an aniso3d texture"]),
    (
        "a png",
        lambda src, dst: dst.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64)),
        ["not an aniso3d texture"],
    ),
]


@pytest.mark.parametrize("command", ["render", "frames"])
@pytest.mark.parametrize("case, make, words", BAD_TEXTURES, ids=[c[0] for c in BAD_TEXTURES])
def test_bad_texture_files(texture_file, tmp_path, capsys, command, case, make, words):
    bad = tmp_path / "bad.a3d"
    make(texture_file, bad)
    out = tmp_path / ("out.png" if command == "render" else "frames")
    code, _, err = run([command, bad, "-o", out, "--size", "16", "--method", "volume"], capsys)
    assert code == 2
    one_line_error(err, command, *words)
    assert not out.exists()


def test_texture_given_to_build_is_refused(texture_file, tmp_path, capsys):
    code, _, err = run(["build", texture_file, "-o", tmp_path / "x.a3d", "-q"], capsys)
    assert code == 2
    one_line_error(err, "build", "is not a mesh")


# ---------------------------------------------------------------- bad options

BAD_OPTIONS = [
    ("build", ["-r", "0"], ["--resolution", "at least 1"]),
    ("build", ["-r", "-5"], ["--resolution", "at least 1"]),
    ("build", ["-r", "1e9"], ["--resolution", "whole number"]),
    ("build", ["-r", "70000"], ["resolution 70000", "maximum"]),
    ("build", ["-k", "0"], ["--directions", "at least 1"]),
    ("build", ["-k", "100000"], ["100000 sphere directions", "maximum"]),
    ("build", ["--direction-set", "halton"], ["--direction-set", "invalid choice"]),
    ("render", ["--size", "0"], ["--size", ">= 1"]),
    ("render", ["--size", "0x64"], ["--size", ">= 1"]),
    ("render", ["--size", "big"], ["--size", "800x600"]),
    ("render", ["--size", "20000"], ["--size", "16384"]),
    ("render", ["--ssaa", "0"], ["--ssaa", "at least 1"]),
    ("render", ["--gt-ssaa", "0"], ["--gt-ssaa", "at least 1"]),
    ("render", ["--method", "raytrace"], ["--method", "invalid choice"]),
    ("render", ["-r", "0"], ["--resolution", "at least 1"]),
    ("render", ["-k", "0"], ["--directions", "at least 1"]),
    ("render", ["--distance", "0"], ["--distance", "positive"]),
    ("render", ["--distance", "nan"], ["--distance", "positive"]),
    ("render", ["--camera-position", "1,2"], ["--camera-position", "X,Y,Z"]),
    ("render", ["--fov", "0"], ["--fov", "between 0 and 180 degrees"]),
    ("render", ["--fov", "180"], ["--fov", "between 0 and 180 degrees"]),
    ("render", ["--fov", "nan"], ["--fov", "between 0 and 180 degrees"]),
    ("render", ["--camera-position", "0,0,0", "--camera-target", "0,0,0"], ["coincide"]),
    ("frames", ["--frames", "0"], ["--frames", "at least 1"]),
    ("frames", ["--method", "all"], ["--method", "invalid choice"]),
]


@pytest.mark.parametrize(
    "command, option, words", BAD_OPTIONS, ids=[" ".join([c, *o]) for c, o, _ in BAD_OPTIONS]
)
def test_bad_options(tmp_path, capsys, command, option, words):
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    out = tmp_path / {"build": "out.a3d", "render": "out.png", "frames": "frames"}[command]
    code, stdout, err = run([command, mesh, "-o", out, *option], capsys)
    assert code == 2
    one_line_error(err, command, *words)
    assert stdout == "" and not out.exists()


def test_no_command_and_unknown_command(capsys):
    code, _, err = run([], capsys)
    assert code == 2
    one_line_error(err.replace("aniso3d: error", "aniso3d -: error"), "-", "COMMAND", "--help")
    code, _, err = run(["frobnicate"], capsys)
    assert code == 2
    one_line_error(err.replace("aniso3d: error", "aniso3d -: error"), "-", "frobnicate", "--help")


# --------------------------------------------------------------------- memory


def test_build_that_cannot_fit_is_refused_up_front(tmp_path, capsys, monkeypatch):
    # 1 GiB available and K = 4096 on the default tree at 256^3: the
    # density spheres alone are several GiB. Refused after loading, before
    # any clipping (must_not_clip), with the estimate and what to lower.
    monkeypatch.setattr(aniso3d.build.texture, "_available_memory", lambda: 2**30)

    def must_not_clip(*a, **k):
        raise AssertionError("clipping started on a build that cannot fit")

    monkeypatch.setattr(aniso3d.build.stream, "clip_to_grid", must_not_clip)
    out = tmp_path / "tree.a3d"
    code, stdout, err = run(["build", "-o", out, "-r", 256, "-k", 4096, "-q"], capsys)
    assert code == 2
    line = one_line_error(
        err,
        "build",
        "resolution 256",
        "4096 directions",
        "needs an estimated",
        "more than the 1.0 GiB available",
        "lower --resolution or --directions",
    )
    need = float(line.split("needs an estimated ")[1].split(" GiB")[0])
    assert need > 2.0
    assert stdout == "" and not out.exists()


def test_exact_check_after_clipping_refuses_before_the_big_arrays(monkeypatch):
    # Before clipping, occupied voxels are counted from the triangles'
    # centroids, which cannot overcount: 12 big triangles of a cube have 12.
    # Once clipping has found the real 23816 voxels, K = 1024 needs ~0.2 GiB
    # of density alone: refused there, before the density array exists.
    from aniso3d.build.texture import _build_bytes, estimate_build_bytes

    cube = scenes.cube(1.0)
    up_front = estimate_build_bytes(cube, 64, 1024)
    exact = _build_bytes(cube.n_faces, 24960, 23816, 1024)
    assert up_front < exact
    limit = (up_front + exact) // 2
    real_zeros = np.zeros

    def no_density(shape, *a, **k):
        if isinstance(shape, tuple) and len(shape) == 2 and shape[1] == 1024:
            raise AssertionError("allocated the density spheres of a build that cannot fit")
        return real_zeros(shape, *a, **k)

    monkeypatch.setattr(aniso3d.build.texture.np, "zeros", no_density)
    with pytest.raises(
        aniso3d.InputError, match="needs an estimated .* GiB, more than the .* GiB available"
    ):
        build_texture(cube, 64, 1024, memory_limit=limit)
    monkeypatch.undo()
    tex = build_texture(cube, 64, 1024, memory_limit=2 * exact)  # and with room, it builds
    assert tex.n_voxels == 23816


def test_memory_estimate_is_an_upper_bound_of_the_real_peak():
    # The exact check uses the counts clipping found; its estimate must not be
    # below the real peak (else a build could be killed halfway), nor far
    # above it (else builds that fit are refused): measured with tracemalloc.
    import tracemalloc

    from aniso3d.build.texture import _build_bytes

    for mesh, res, k in [
        (scenes.tree(levels=4, leaves_per_twig=20), 64, 256),
        (scenes.sphere(1.0, subdivisions=3), 96, 64),
        (scenes.cube(1.0), 160, 4),
    ]:
        tracemalloc.start()
        try:
            tex = build_texture(mesh, res, k)
            tex.to_points()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        est = _build_bytes(mesh.n_faces, tex.meta["n_subpolygons"], tex.n_voxels, k)
        assert peak <= est <= 2.5 * peak, (res, k, peak / 2**20, est / 2**20)


# ------------------------------------------------------------- atomic output


@pytest.fixture
def small_mesh(tmp_path):
    path = tmp_path / "small.ply"
    scenes.tree(levels=3, leaves_per_twig=10).to_trimesh().export(path)
    return path


def _fail_midway(monkeypatch, exc):
    """Make every atomic write die after some bytes have gone out."""
    real = aniso3d.files.os.fdopen

    class Dying(io.RawIOBase):
        def __init__(self, fh):
            self.fh, self.n = fh, 0

        def writable(self):
            return True

        def seekable(self):
            return self.fh.seekable()

        def tell(self):
            return self.fh.tell()

        def seek(self, *a):
            return self.fh.seek(*a)

        def write(self, b):
            if self.n + len(b) > 200:  # half of it goes out, then the failure
                self.fh.write(bytes(b)[: max(0, 200 - self.n)])
                raise exc
            self.n += len(b)
            return self.fh.write(b)

        def flush(self):
            if not self.fh.closed:
                self.fh.flush()

        def fileno(self):
            return self.fh.fileno()

        def close(self):
            if not self.closed:
                self.fh.close()
                super().close()

    monkeypatch.setattr(aniso3d.files.os, "fdopen", lambda fd, mode: Dying(real(fd, mode)))


@pytest.mark.parametrize("suffix", [".a3d", ".ply"])
@pytest.mark.parametrize("failure", ["disk full", "interrupt"])
def test_failed_or_interrupted_write_keeps_the_earlier_output(
    small_mesh, tmp_path, capsys, monkeypatch, suffix, failure
):
    out = tmp_path / f"result{suffix}"
    out.write_bytes(b"the earlier result")
    before = sorted(os.listdir(tmp_path))
    exc = OSError(28, "No space left on device") if failure == "disk full" else KeyboardInterrupt()
    _fail_midway(monkeypatch, exc)
    code, _, err = run(["build", small_mesh, "-o", out, "-r", 8, "-k", 8, "-q"], capsys)
    if failure == "disk full":
        assert code == 2
        one_line_error(err, "build", "could not write", "No space left on device")
    else:
        assert code == 130
        assert err.strip() == "aniso3d build: interrupted; no output was written"
    assert out.read_bytes() == b"the earlier result"
    assert sorted(os.listdir(tmp_path)) == before  # no temporary file left


def test_new_outputs_get_normal_permissions_and_replacements_keep_theirs(
    small_mesh, tmp_path, capsys
):
    # The temporary file is private (0600); the result must not be.
    umask = os.umask(0o022)
    try:
        out = tmp_path / "new.a3d"
        assert run(["build", small_mesh, "-o", out, "-r", 4, "-k", 4, "-q"], capsys)[0] == 0
        assert out.stat().st_mode & 0o777 == 0o644
        out.chmod(0o640)
        assert run(["build", small_mesh, "-o", out, "-r", 5, "-k", 4, "-q"], capsys)[0] == 0
        assert out.stat().st_mode & 0o777 == 0o640
        assert AnisoTexture.load(out).resolution == 5
    finally:
        os.umask(umask)


# The writer stalls in short sleeps, not one long one: a signal sent to the
# process may be taken by any of its threads (numpy's BLAS starts some), and
# then the main thread sees it only when it next runs Python code; a single
# sleep(60) would hide the signal for a minute, like no real write does.
# It also restores Ctrl-C's handler: a test run started in the background
# (CI scripts, nohup) ignores SIGINT, its children inherit that, and Python
# then leaves SIGINT ignored, as a user's interactive terminal never does.
SLOW_WRITER = r"""
import signal, sys, time, numpy
signal.signal(signal.SIGINT, signal.default_int_handler)
real = numpy.save
def slow(*a, **k):
    real(*a, **k)
    print("WRITING", flush=True)
    for _ in range(600):
        time.sleep(0.1)
numpy.save = slow
from aniso3d.app.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize(
    "sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGKILL, -9)]
)
def test_signal_during_the_write(small_mesh, tmp_path, sig, status):
    # A real process, stopped while it is writing the texture file. Ctrl-C and
    # kill (SIGTERM) unwind: the earlier output is intact and the temporary
    # file is gone. SIGKILL cannot be caught: the earlier output is still
    # intact (the rename never happened), a hidden temporary file remains.
    out = tmp_path / "result.a3d"
    out.write_bytes(b"the earlier result")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            SLOW_WRITER,
            "build",
            str(small_mesh),
            "-o",
            str(out),
            "-r",
            "8",
            "-k",
            "8",
            "-q",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "WRITING"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == status, err
    assert out.read_bytes() == b"the earlier result"
    if sig == signal.SIGKILL:
        assert len(leftovers(tmp_path)) == 1 and leftovers(tmp_path)[0].startswith(".result.a3d.")
    else:
        assert "Traceback" not in err
        assert err.strip() == "aniso3d build: interrupted; no output was written"
        assert leftovers(tmp_path) == []


# ------------------------------------------------------------- never the input


def test_build_never_overwrites_its_input(small_mesh, tmp_path, capsys):
    before = small_mesh.read_bytes()
    link = tmp_path / "link.ply"
    link.symlink_to(small_mesh)
    for target in (small_mesh, link, tmp_path / "." / small_mesh.name):
        code, stdout, err = run(["build", small_mesh, "-o", target, "-r", 4, "-q"], capsys)
        assert code == 2 and stdout == ""
        one_line_error(err, "build", "is the input file", "never overwrites")
    # through the link as input, to the real file as output
    code, _, err = run(["build", link, "-o", small_mesh, "-r", 4, "-q"], capsys)
    assert code == 2
    one_line_error(err, "build", "is the input file")
    assert small_mesh.read_bytes() == before


def test_writing_to_a_hard_link_of_the_input_leaves_the_input_intact(small_mesh, tmp_path, capsys):
    # A hard link is a second name for the same file and cannot be told from
    # another file by its path; the atomic rename replaces the name written
    # to, so the input's own name still holds the input.
    before = small_mesh.read_bytes()
    twin = tmp_path / "twin.ply"
    os.link(small_mesh, twin)
    code, _, err = run(["build", small_mesh, "-o", twin, "-r", 4, "-k", 4, "-q"], capsys)
    assert code == 0, err
    assert small_mesh.read_bytes() == before
    assert twin.read_bytes() != before


def test_render_and_frames_never_overwrite_their_input(small_mesh, tmp_path, capsys):
    png = tmp_path / "picture.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    before = png.read_bytes()
    code, _, err = run(["render", png, "-o", png], capsys)
    assert code == 2
    one_line_error(err, "render", "is the input file")
    assert png.read_bytes() == before
    mesh_before = small_mesh.read_bytes()
    code, _, err = run(["render", small_mesh, "-o", small_mesh], capsys)
    assert code == 2
    one_line_error(err, "render", "must end in .png")
    code, _, err = run(["frames", small_mesh, "-o", small_mesh], capsys)
    assert code == 2
    one_line_error(err, "frames", "not a folder")
    assert small_mesh.read_bytes() == mesh_before


# ---------------------------------------------------------------- subprocess


def test_subprocess_bad_input_and_bad_option(tmp_path):
    # A clean interpreter, the way a user runs it.
    missing = subprocess.run(
        [*EXE, "render", str(tmp_path / "nope.obj"), "-o", str(tmp_path / "x.png")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert missing.returncode == 2 and missing.stdout == ""
    one_line_error(missing.stderr, "render", "does not exist")
    bad = subprocess.run(
        [*EXE, "render", "--size", "0x0"], capture_output=True, text=True, timeout=120
    )
    assert bad.returncode == 2
    one_line_error(bad.stderr, "render", "--size")
    assert not (tmp_path / "x.png").exists()
