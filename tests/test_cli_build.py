"""`aniso3d build`: in-process through aniso3d.app.cli.main, plus real subprocesses."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from aniso3d import AnisoTexture, PointCloud, build_texture, load_mesh, scenes
from aniso3d.app.cli import main

TABLE_ROWS = ("triangles", "sub-polygons", "occupied voxels", "bytes: texture", "seconds: clip")


@pytest.fixture
def mesh_file(tmp_path):
    path = tmp_path / "tree.ply"
    scenes.tree(levels=3, leaves_per_twig=10).to_trimesh().export(path)
    return path


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def table(out: str) -> dict[str, str]:
    rows = {}
    for line in out.splitlines():
        key, _, value = re.split(r"(\s{2,})", line.strip(), maxsplit=1)
        rows[key] = value
    return rows


def assert_one_line_error(err: str, *words: str):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("aniso3d build: error: ")
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert "Traceback" not in err


# ----------------------------------------------------------------------- works


def test_build_writes_texture_and_prints_table(mesh_file, tmp_path, capsys):
    out = tmp_path / "tree.a3d"
    code, stdout, err = run(["build", mesh_file, "-o", out, "-r", 12, "-k", 16, "-q"], capsys)
    assert code == 0, err
    assert err == ""
    rows = table(stdout)
    for key in TABLE_ROWS + ("seconds: register", "seconds: save", "bytes: mesh", "wrote"):
        assert key in rows, key
    mesh = load_mesh(mesh_file)
    tex = AnisoTexture.load(out)
    assert rows["triangles"] == f"{mesh.n_faces:,}"
    assert rows["sub-polygons"] == f"{tex.meta['n_subpolygons']:,}"
    assert rows["occupied voxels"].startswith(f"{tex.n_voxels:,} (")
    assert rows["grid"].startswith("x".join(str(s) for s in tex.shape))
    assert rows["wrote"] == str(out)
    for key in rows:
        if key.startswith("seconds:"):
            assert float(rows[key]) >= 0
    # the file holds what the library builds from the same mesh, as the
    # default (compact) encoding stores it
    ref = build_texture(mesh, 12, 16).as_stored()
    for name in AnisoTexture._ARRAYS:
        np.testing.assert_array_equal(getattr(tex, name), getattr(ref, name), err_msg=name)
    assert tex.meta["source"] == "tree"
    assert sorted(os.listdir(tmp_path)) == ["tree.a3d", "tree.ply"]


def test_build_to_ply_writes_points(mesh_file, tmp_path, capsys):
    out = tmp_path / "points.ply"
    code, stdout, err = run(
        ["build", mesh_file, "-o", out, "-r", 8, "-k", 8, "--placement", "center",
         "--points-per-entry", 2, "-q"],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    pc = PointCloud.load_ply(out)
    # the texture's points as the API makes them (a closed skin's hidden
    # backs take their share of the mesh's area out)
    want = build_texture(load_mesh(mesh_file), 8, 8).to_points("center", 2)
    assert len(pc) == len(want)
    assert pc.total_area() == pytest.approx(want.total_area(), rel=1e-5)
    assert table(stdout)["points"] == f"{len(pc):,} (center)"


def test_build_builtin_scene(tmp_path, capsys):
    code, stdout, err = run(
        ["build", "scene:cube", "-o", tmp_path / "c.a3d", "-r", 4, "-k", 8, "-q"], capsys
    )
    assert code == 0, err
    assert table(stdout)["triangles"] == "12"
    assert AnisoTexture.load(tmp_path / "c.a3d").total_area() == pytest.approx(6.0)


# ---------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "option, words",
    [
        (["-r", "0"], ["--resolution", "at least 1"]),
        (["-r", "-4"], ["--resolution", "at least 1"]),
        (["-r", "ten"], ["--resolution", "whole number"]),
        (["-k", "0"], ["--directions", "at least 1"]),
        (["--points-per-entry", "0"], ["--points-per-entry"]),
        (["--placement", "corner"], ["--placement", "invalid choice"]),
    ],
)
def test_bad_options_exit_2_with_a_clear_message(mesh_file, tmp_path, capsys, option, words):
    out = tmp_path / "x.a3d"
    with pytest.raises(SystemExit) as info:
        main(["build", str(mesh_file), "-o", str(out), *option])
    assert info.value.code == 2
    _, err = capsys.readouterr()
    assert_one_line_error(err, *words)  # no usage block, no traceback
    assert not out.exists()


def test_refuses_to_overwrite_its_input(mesh_file, capsys):
    before = mesh_file.read_bytes()
    # also when the same file is spelled differently
    other_spelling = mesh_file.parent / "." / ".." / mesh_file.parent.name / mesh_file.name
    for target in (mesh_file, other_spelling):
        code, stdout, err = run(["build", mesh_file, "-o", target, "-r", 4, "-q"], capsys)
        assert code == 2
        assert_one_line_error(err, "is the input file")
        assert stdout == ""
    assert mesh_file.read_bytes() == before


def test_refuses_bad_output_suffix(mesh_file, tmp_path, capsys):
    code, _, err = run(["build", mesh_file, "-o", tmp_path / "out.obj", "-q"], capsys)
    assert code == 2
    assert_one_line_error(err, ".a3d", ".ply")


def test_missing_input(tmp_path, capsys):
    code, _, err = run(["build", tmp_path / "nope.obj", "-o", tmp_path / "x.a3d", "-q"], capsys)
    assert code == 2
    assert_one_line_error(err, "does not exist")


def test_texture_as_input_is_refused(tmp_path, capsys):
    build_texture(scenes.quad(), 2, 4).save(tmp_path / "q.a3d")
    code, _, err = run(["build", tmp_path / "q.a3d", "-o", tmp_path / "x.a3d", "-q"], capsys)
    assert code == 2
    assert_one_line_error(err, "not a mesh")


def test_output_folder_is_checked_before_building(mesh_file, tmp_path, capsys, monkeypatch):
    import aniso3d.build.texture

    def must_not_build(*a, **k):
        raise AssertionError("built a texture that could never be written")

    monkeypatch.setattr(aniso3d.build.texture, "build_texture", must_not_build)
    code, _, err = run(["build", mesh_file, "-o", tmp_path / "missing" / "x.a3d", "-q"], capsys)
    assert code == 2
    assert_one_line_error(err, "does not exist")
    (tmp_path / "dir.a3d").mkdir()
    code, _, err = run(["build", mesh_file, "-o", tmp_path / "dir.a3d", "-q"], capsys)
    assert code == 2
    assert_one_line_error(err, "directory")


def test_write_failure_is_one_line_and_keeps_the_old_file(mesh_file, tmp_path, capsys, monkeypatch):
    import aniso3d.files

    out = tmp_path / "keep.a3d"
    out.write_bytes(b"old")

    def disk_full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(aniso3d.files.os, "fsync", disk_full)
    code, _, err = run(["build", mesh_file, "-o", out, "-r", 4, "-k", 4, "-q"], capsys)
    assert code == 2
    assert_one_line_error(err, "No space left on device", str(out))
    assert out.read_bytes() == b"old"
    assert sorted(os.listdir(tmp_path)) == ["keep.a3d", "tree.ply"]


# ------------------------------------------------------------------ subprocess


def test_subprocess_build_and_bad_option(mesh_file, tmp_path):
    exe = [sys.executable, "-m", "aniso3d.app.cli"]
    out = tmp_path / "sub.a3d"
    ok = subprocess.run(
        [*exe, "build", str(mesh_file), "-o", str(out), "-r", "8", "-k", "8"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert ok.returncode == 0, ok.stderr
    assert "occupied voxels" in ok.stdout and "Traceback" not in ok.stderr
    assert ok.stderr == ""  # no progress bar when stderr is not a terminal
    assert AnisoTexture.load(out).n_voxels > 0

    bad = subprocess.run(
        [*exe, "build", str(mesh_file), "-o", str(tmp_path / "b.a3d"), "--resolution", "0"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert bad.returncode == 2
    assert (
        bad.stderr == "aniso3d build: error: argument --resolution/-r: must be at least 1, got 0\n"
    )
    assert bad.stdout == ""
    assert not (tmp_path / "b.a3d").exists()
