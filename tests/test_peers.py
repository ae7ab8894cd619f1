"""``aniso3d bench peers``: the table machinery on a tiny torus with the
contenders that need nothing extra, hole counting against closed forms, and a
missing or broken peer skipped with a note instead of failing the run."""

from __future__ import annotations

import numpy as np
import pytest

from aniso3d import InputError
from aniso3d.app.cli import main
from aniso3d.bench.peers import (
    BACKGROUND,
    CORE,
    HOLE_TARGET,
    Cloud,
    PeerSettings,
    background_mask,
    camera_pose,
    erode,
    hole_stats,
    import_failure,
    markers,
    report,
    run_peers,
    torus_points,
    view_camera,
    write_cloud_ply,
    write_report,
)

MAGENTA = np.round(np.asarray(BACKGROUND) * 255).astype(np.uint8)


# ------------------------------------------------------------ no GPU needed


def test_torus_points_lie_on_the_torus_with_its_normals():
    pos, normal, colour = torus_points(20000, seed=3)
    ring = np.hypot(pos[:, 0], pos[:, 2])
    minor = np.hypot(ring - 1.0, pos[:, 1])  # distance from the tube's centre line
    assert np.abs(minor - 0.4).max() < 0.01  # noise 0.001: 10 sigma
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0)
    centre = np.stack([pos[:, 0] / ring, np.zeros(len(pos)), pos[:, 2] / ring], 1)
    radial = pos - centre
    assert np.all(np.einsum("ij,ij->i", radial / np.linalg.norm(radial, axis=1, keepdims=True), normal) > 0.999)
    assert colour.min() >= 0 and colour.max() <= 1
    # uniform by area: the outer half of the tube (cos v > 0) has (pi R + 2 r) / (2 pi R) of the area
    outer = np.mean(ring > 1.0)
    assert outer == pytest.approx((np.pi + 0.8) / (2 * np.pi), abs=0.01)


def test_ply_round_trip_has_no_sizes(tmp_path):
    from aniso3d.build.ply import read_ply_header

    pos, normal, colour = torus_points(500)
    path = write_cloud_ply(tmp_path / "t.ply", pos, normal, colour)
    header = read_ply_header(path)
    assert header.format == "binary_little_endian" and header.is_point_cloud
    assert "area" not in header.properties["vertex"] and "radius" not in header.properties["vertex"]
    cloud = Cloud.read(path)
    assert np.allclose(cloud.positions, pos, atol=1e-6)
    assert np.array_equal(cloud.colours, np.round(colour * 255).astype(np.uint8))


def test_hole_stats_closed_form():
    img = np.zeros((40, 40, 3), np.uint8) + 100
    img[:, :] = MAGENTA
    sil = np.zeros((40, 40), bool)
    sil[10:30, 10:30] = True  # 400 pixels
    img[10:30, 10:30] = (90, 120, 60)
    img[15, 15:22] = MAGENTA  # 7 holes, all 5 or more pixels inside the edge
    img[10, 10] = MAGENTA  # 1 hole on the edge: not in the eroded silhouette
    img[5, 5:9] = (1, 2, 3)  # 4 drawn pixels, 5 from the silhouette: overhang
    img[9, 12] = (1, 2, 3)  # 1 drawn pixel next to it: within the 2 px allowed
    holes, inner, over = hole_stats(img, sil)
    assert holes == 8 / 400 and inner == 7 / 400 and over == 4 / 400
    # a colour within the tolerance of the background is background
    img2 = img.copy()
    img2[20, 20] = MAGENTA - np.array([0, 0, 2], np.uint8)
    assert hole_stats(img2, sil)[0] == 9 / 400
    assert not background_mask(np.array([[[250, 10, 250]]], np.uint8))[0, 0]


def test_erode_matches_scipy():
    ndimage = pytest.importorskip("scipy.ndimage")
    rng = np.random.default_rng(1)
    mask = ndimage.binary_closing(rng.random((60, 70)) < 0.7, iterations=2)
    cross = ndimage.generate_binary_structure(2, 1)
    for px in (1, 2, 3):
        want = ndimage.binary_erosion(mask, cross, iterations=px, border_value=0)
        assert np.array_equal(erode(mask, px), want)


def test_camera_pose_is_the_inverse_view():
    cam = view_camera(np.array([[-1.4, -0.4, -1.4], [1.4, 0.4, 1.4]]))
    assert np.allclose(camera_pose(cam) @ cam.view_matrix(), np.eye(4), atol=1e-12)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"frames": 4}, "at least 5 frames"),
        ({"rounds": 7}, "rounds"),
        ({"contenders": ("aniso3d-fast", "blender")}, "blender"),
        ({"contenders": ()}, "none given"),
        ({"points": 10}, "at least 100 points"),
    ],
)
def test_bad_settings_are_one_clear_error(kwargs, words):
    with pytest.raises(InputError, match=words):
        PeerSettings(**kwargs)


def test_cli_refuses_bad_options_in_one_line(capsys, tmp_path):
    for argv, words in (
        (["bench", "peers", "--contenders", "aniso3d-fast,blender"], "blender"),
        (["bench", "peers", "--frames", "3"], "at least 5 frames"),
        (["bench", "peers", str(tmp_path / "none.ply")], "none.ply"),
    ):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and words in err and "Traceback" not in err, err


def test_bench_without_peers_keeps_its_positional(capsys):
    # 'peers' is a word only in the first place: the sweep's mesh argument is unchanged
    try:
        code = main(["bench", "scene:nonesuch", "--smoke", "-q", "-o", "/nonexistent/x"])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and "nonesuch" in err


# -------------------------------------------------------------- on the GPU


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The whole machinery on a 3,000-point torus at 96 x 96 with the
    contenders that need nothing beyond aniso3d's dependencies."""
    from aniso3d import ResourceError
    from aniso3d.rendering.context import GLContext

    try:
        GLContext().release()
    except ResourceError as exc:
        pytest.skip(str(exc))
    images = tmp_path_factory.mktemp("peer_images")
    settings = PeerSettings(points=3000, size=(96, 96), frames=5, rounds=2, contenders=CORE, images=images)
    return run_peers(settings), images


@pytest.mark.gpu
def test_tiny_run_measures_every_core_contender(tiny):
    result, images = tiny
    assert [r.name for r in result.rows] == list(CORE)
    for r in result.rows:
        assert r.status == "ok", r.note
        assert len(r.times) == 5 and all(t > 0 for t in r.times)
        assert r.setup_s > 0 and r.peak_mib > 10
        assert 0 <= r.holes_inner <= r.holes <= 1 and r.overhang >= 0
        assert (images / f"{r.name}.png").exists()
    rows = {r.name: r for r in result.rows}
    # aniso3d's neighbour-sized discs close the torus; 2-pixel points do not
    assert rows["aniso3d-fast"].holes < HOLE_TARGET and rows["aniso3d-high"].holes < HOLE_TARGET
    assert rows["gl-points-2px"].holes > 0.05
    # points as large as the splats close it too, and overhang the outline more than 2-px points
    assert rows["gl-points"].holes_inner < rows["gl-points-2px"].holes_inner
    assert rows["gl-points"].overhang > rows["gl-points-2px"].overhang
    assert result.meta["point_px"] >= 2 and result.meta["points"] == 3000


@pytest.mark.gpu
def test_images_agree_on_the_framing(tiny):
    # The same camera reaches every contender: their drawn pixels have one
    # centre, and overlap mostly (square points of the splats' size stick out
    # of the outline by up to half their width at this tiny size).
    from aniso3d.rendering.images import load_png

    result, images = tiny
    closed = [r for r in result.rows if r.holes < 0.01]  # 2-px points leave holes that move the centre
    assert len(closed) == 3
    drawn = {r.name: ~background_mask(load_png(images / f"{r.name}.png")) for r in closed}
    centres = {n: np.argwhere(m).mean(axis=0) for n, m in drawn.items()}
    for n, c in centres.items():
        assert np.abs(c - centres["aniso3d-fast"]).max() < 1.0, (n, c, centres["aniso3d-fast"])
    a, b = drawn["aniso3d-fast"], drawn["gl-points"]
    assert np.count_nonzero(a & b) / np.count_nonzero(a | b) > 0.75


@pytest.mark.gpu
def test_report_states_table_targets_and_load(tiny, tmp_path):
    result, _ = tiny
    text = report(result, "aniso3d bench peers --points 3000")
    assert "`aniso3d bench peers --points 3000`" in text
    assert "Machine load (1, 5, 15 min)" in text
    for r in result.rows:
        assert f"| {r.label} |" in text
    assert "within 1.2x the bare GL_POINTS 2 px floor:" in text
    assert "aniso3d fast: fewer than 0.1 % background pixels" in text
    begin, end = markers(result)
    assert begin == "<!-- bench peers:torus-3000:begin -->"
    page = tmp_path / "peers.md"
    other = "<!-- bench peers:torus-100:begin -->\nkept\n<!-- bench peers:torus-100:end -->"
    page.write_text(f"# Title\n\nprose before\n\n{begin}\nold numbers\n{end}\n\n{other}\nprose after\n")
    write_report(result, page, "aniso3d bench peers")
    new = page.read_text()
    assert new.startswith("# Title\n\nprose before\n\n") and new.endswith(f"{end}\n\n{other}\nprose after\n")
    assert "old numbers" not in new and "| aniso3d fast |" in new
    # a page without this run's section gets it appended
    page.write_text("# Title\n\nprose\n")
    write_report(result, page, "aniso3d bench peers")
    assert page.read_text().startswith("# Title\n\nprose\n\n" + begin) and page.read_text().endswith(end + "\n")


def test_import_failure_says_what_is_missing():
    """A peer that is not installed is told to pip install; one installed
    without a system library its compiled part needs (Open3D without libusb)
    is told which library, not to pip install what it has."""
    gone = ModuleNotFoundError("No module named 'pyvista'", name="pyvista")
    assert import_failure(gone) == "not installed (pyvista); pip install 'aniso3d[peers]'"
    lib = ImportError("libusb-1.0.so.0: cannot open shared object file: No such file or directory", name="pybind")
    text = import_failure(lib)
    assert text.startswith("installed but cannot load: libusb-1.0.so.0: cannot open shared object file")
    assert "pip install" not in text and "system library" in text


@pytest.mark.gpu
@pytest.mark.parametrize("how", ["missing", "crashing"])
def test_an_absent_peer_is_skipped_with_a_note(tmp_path, monkeypatch, capsys, how):
    # A pyvista that cannot be imported (or that kills its process), first on
    # the workers' path: the run goes on, the row says why, the command succeeds.
    fake = tmp_path / "fake" / "pyvista"
    fake.mkdir(parents=True)
    body = ("raise ImportError(\"No module named 'pyvista'\", name='pyvista')\n" if how == "missing"
            else "import os\nos._exit(3)\n")  # fmt: skip
    (fake / "__init__.py").write_text(body)
    monkeypatch.setenv("PYTHONPATH", str(tmp_path / "fake"))
    out = tmp_path / "peers.md"
    code = main(["bench", "peers", "--points", "2000", "--size", "64", "--frames", "5", "--rounds", "1",
                 "--contenders", "gl-points-2px,pyvista-points", "-o", str(out), "-q"])  # fmt: skip
    stdout = capsys.readouterr().out
    assert code == 0
    text = out.read_text()
    assert "| GL_POINTS 2 px | 2 px |" in text
    if how == "missing":
        assert "| PyVista points | skipped: not installed (pyvista); pip install 'aniso3d[peers]' |" in text
    else:
        assert "| PyVista points | skipped: cannot run here: the pyvista-points process ended (status 3)" in text
    assert "skipped: PyVista points:" in stdout
