"""The bench command: sweep planning and geometry without a GPU, and a smoke
run end to end (CSV, JSON, report, plots) on the software rasteriser."""

from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import replace

import numpy as np
import pytest

from aniso3d import bench, scenes
from aniso3d.app import cli
from aniso3d.bench import analyse, plots, run
from aniso3d.rendering.camera import Camera

# ------------------------------------------------------------ without a GPU


def test_pareto_front():
    pts = [(1.0, 0.5), (2.0, 0.4), (3.0, 0.45), (0.5, 0.9), (2.0, 0.3), (5.0, 0.1)]
    assert bench.pareto_front(pts) == [3, 0, 4, 5]
    rows = [{"status": "ok", "camera": "a", "frame_s": c, "error": e} for c, e in pts] + [
        {"status": "skipped", "camera": "a", "frame_s": None, "error": None}
    ]
    bench.mark_pareto(rows)
    assert [r["pareto"] for r in rows] == [True, False, False, True, True, True, False]


def test_cameras_put_a_baseline_voxel_at_the_stated_width():
    settings = bench.PRESETS["full"]
    bounds = np.array([[0.0, 0.0, 0.0], [8.0, 12.0, 6.0]])
    cams = bench.make_cameras(bounds, settings)
    assert cams[0].label == "fill" and cams[0].scale == 1.0
    h = 12.0 / settings.baseline["resolution"]
    for c in cams:
        # Project a voxel-wide segment at the target, across the view.
        right = c.camera.basis()[0]
        target = np.asarray(c.camera.target)
        xy = c.camera.project(np.stack([target, target + h * right]), settings.size, bounds)
        assert np.linalg.norm(xy[1] - xy[0]) == pytest.approx(c.voxel_px, rel=1e-6)
        x0, y0, x1, y1 = c.crop
        assert 0 <= x0 < x1 <= settings.size[0] and 0 <= y0 < y1 <= settings.size[1]
        assert min(x1 - x0, y1 - y0) >= 16
    labels = [c.label for c in cams]
    assert "1px" in labels and bench.near_far(cams)[1].label == "1px"
    assert all(a.scale < b.scale for a, b in zip(cams, cams[1:], strict=False))


def test_plan_is_one_axis_at_a_time_plus_the_grid():
    settings = bench.PRESETS["full"]
    bounds = np.array([[0.0, 0.0, 0.0], [10.0, 10.0, 10.0]])
    cams = bench.make_cameras(bounds, settings)
    plan = bench.plan_cases(settings, cams)
    grid = [c for c, blocks in plan.items() if "grid" in blocks]
    assert len(grid) == len(cams) * 5
    # The level-of-detail block: the baseline volume and splats at every camera.
    lod = [c for c, blocks in plan.items() if blocks == ["lod"]]
    assert len(lod) == len(cams) * 2 and all(c.lod for c in lod)
    assert {(c.method, c.camera) for c in lod} == {
        (m, c.label) for m in ("volume", "splat") for c in cams
    }
    near, far = bench.near_far(cams)
    base = settings.baseline
    for case, blocks in plan.items():
        if case.method == "mesh":
            assert blocks == ["grid"]
            continue
        differs = [
            a for a, f in bench.AXES.items()
            if getattr(case, f) is not None and getattr(case, f) != base[a]
        ]  # fmt: skip
        assert len(differs) <= 1, (case, differs)
        if "grid" not in blocks and "lod" not in blocks:
            assert case.camera in (near.label, far.label)
    # The baseline splat at the near camera serves every block.
    baseline_splat = next(c for c, b in plan.items() if c.method == "splat" and len(b) > 5)
    assert baseline_splat.camera == near.label
    # Splat-only axes never make volume cases.
    for case, blocks in plan.items():
        if case.method == "volume":
            assert not set(blocks) & set(bench.SPLAT_AXES)


def _row(method, axis, value, error, frame_s, nbytes, camera="fill"):
    row = {c: None for c in bench.COLUMNS}
    row.update(
        status="ok",
        method=method,
        renderer=method,
        blocks=axis,
        camera=camera,
        error=error,
        frame_s=frame_s,
        points_bytes=nbytes,
        texture_bytes=nbytes,
    )
    row[bench.AXES[axis]] = value
    return row  # fmt: skip


def test_recommend_prefers_cheaper_values_only_within_tolerance():
    rows = [
        # K: 16 is within 1% of 64 and smaller -> 16; 256 is no better.
        _row("volume", "directions", 16, 0.1005, 0.10, 10),
        _row("volume", "directions", 64, 0.1000, 0.10, 30),
        _row("volume", "directions", 256, 0.1001, 0.10, 90),
        # Resolution: 32 is the most accurate and the smallest; 64 is faster but
        # larger, so it does not win on time.
        _row("volume", "resolution", 32, 0.1000, 0.30, 10),
        _row("volume", "resolution", 64, 0.1001, 0.10, 40),
        # Shape: same bytes; ellipse within 1% and faster -> ellipse.
        _row("splat", "splat", "square", 0.2000, 0.20, 5),
        _row("splat", "splat", "disc", 0.2500, 0.05, 5),
        _row("splat", "splat", "ellipse", 0.2010, 0.10, 5),
        # Placement: centroid clearly best, the others cheaper but worse.
        _row("splat", "placement", "centroid", 0.10, 0.3, 5),
        _row("splat", "placement", "center", 0.12, 0.1, 5),
        _row("splat", "placement", "centroid", 0.20, 0.3, 5, camera="far"),
        _row("splat", "placement", "center", 0.21, 0.1, 5, camera="far"),
    ]
    rec = {(r["axis"], r["renderer"]): r for r in bench.recommend(rows)}
    assert rec["directions", "volume"]["value"] == 16 and rec["directions", "volume"]["best"] == 64
    assert rec["splat", "splat"]["value"] == "ellipse" and rec["splat", "splat"]["best"] == "square"
    assert rec["placement", "splat"]["value"] == "centroid"
    assert rec["resolution", "volume"]["value"] == 32
    assert rec["placement", "splat"]["table"]["centroid"][0] == pytest.approx(0.15)
    assert ("placement", "volume") not in rec


def test_default_changes_keep_the_baseline_within_tolerance():
    rows = [
        # quality: high is the baseline; fast is far worse, so high stays recommended.
        _row("splat", "quality", "high", 0.020, 0.15, 5),
        _row("splat", "quality", "fast", 0.085, 0.04, 5),
        # splat shape: ellipse is the most accurate by 0.5%, no cheaper: a tie, keep disc.
        _row("splat", "splat", "disc", 0.0202, 0.15, 5),
        _row("splat", "splat", "ellipse", 0.0201, 0.16, 5),
        # resolution: 128 is 30% more accurate than the baseline 64: change.
        _row("volume", "resolution", 64, 0.0346, 0.05, 10),
        _row("volume", "resolution", 128, 0.0240, 0.07, 40),
        # K: 64 within 1% of 16 but not smaller or cheaper: recommend 16, the baseline.
        _row("volume", "directions", 16, 0.0346, 0.05, 10),
        _row("volume", "directions", 64, 0.0345, 0.07, 30),
    ]
    rec = bench.recommend(rows)
    base = {"quality": "high", "splat": "disc", "resolution": 64, "directions": 16}
    change, keep = analyse.default_changes(rec, base)
    assert [(r["axis"], r["value"]) for r in change] == [("resolution", 128)]
    assert [(r["axis"], r["value"]) for r in keep] == [("splat", "ellipse")]
    # A baseline the block did not measure cannot be kept.
    change, _ = analyse.default_changes(rec, {**base, "resolution": 256})
    assert ("resolution", 128) in [(r["axis"], r["value"]) for r in change]


def test_renderer_by_distance_and_frame_spread():
    def grid(camera, scale, renderer, error, cpu, lo, mid, hi):
        return {"status": "ok", "blocks": "grid", "camera": camera, "distance_scale": scale,
                "camera_voxel_px": 2.0 / scale, "renderer": renderer, "method": renderer, "error": error,
                "frame_s": mid, "frame_cpu_s": cpu, "frame_min_s": lo, "frame_max_s": hi, "frames": 7}  # fmt: skip

    rows = [
        grid("far", 2.0, "mesh-1spp", 0.060, 0.04, 0.04, 0.05, 0.06),
        grid("far", 2.0, "mesh-4x4", 0.013, 0.10, 0.10, 0.10, 0.10),
        grid("far", 2.0, "volume", 0.0140, 0.03, 0.02, 0.04, 0.08),
        grid("fill", 1.0, "mesh-1spp", 0.040, 0.05, 0.05, 0.05, 0.05),
        grid("fill", 1.0, "mesh-4x4", 0.007, 0.30, 0.30, 0.30, 0.30),
        grid("fill", 1.0, "volume", 0.070, 0.50, 0.50, 0.50, 0.50),
    ]
    by = {d["camera"]: d for d in analyse.renderer_by_distance(rows)}
    assert list(by) == ["fill", "far"]  # nearest first
    assert by["fill"]["best"]["renderer"] == by["fill"]["pick"]["renderer"] == "mesh-4x4"
    assert by["fill"]["beats_1spp"]["renderer"] == "mesh-4x4"  # the volume is worse than 1 spp
    # 0.0140 is within 10% of 0.013 and a third of the CPU time.
    assert by["far"]["best"]["renderer"] == "mesh-4x4" and by["far"]["pick"]["renderer"] == "volume"
    assert analyse.frame_spread(rows[2]) == pytest.approx((0.08 - 0.02) / 0.04)
    assert math.isnan(analyse.frame_spread({"frame_min_s": None, "frame_s": 0.1, "frame_max_s": 0.2}))
    t = analyse.timing_summary(rows)
    spreads = [0.4, 0.0, 1.5, 0.0, 0.0, 0.0]
    assert t["rows"] == 6 and t["spread_max"] == pytest.approx(1.5) and t["worst"] is rows[2]
    assert t["spread_median"] == pytest.approx(float(np.median(spreads)))
    assert t["per_renderer"]["volume"]["spread_median"] == pytest.approx(0.75)


def test_code_version_is_the_checkout_commit():
    import subprocess
    from pathlib import Path

    root = Path(bench.__file__).resolve().parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True,
                              check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("the package is not in a git checkout")
    version = run.code_version()
    assert version["commit"] == head and isinstance(version["dirty"], bool)


def test_case_render_options():
    base = bench.PRESETS["full"].baseline
    splat = bench.splat_case("fill", base)
    assert splat.render_options() == {"splat": base["splat"], "quality": "high"}
    assert splat.points_key is not None
    vol = bench.volume_case("fill", base)
    assert vol.render_options() == {"normal": "mean"}
    # Level of detail: the renderer makes the points, so it gets their options.
    lod = replace(splat, extra=(("lod", True), ("pixel_error", 2.0)))
    assert lod.lod and lod.points_key is None
    assert lod.render_options() == {
        "splat": base["splat"], "quality": "high", "placement": "centroid", "per_entry": 1,
        "point_normal": "mean", "lod": True, "pixel_error": 2.0,
    }  # fmt: skip
    quick = bench.PRESETS["quick"]
    cam = bench.make_cameras(np.array([[0.0, 0, 0], [1, 1, 1]]), quick)[0]
    row = bench.blank_row(lod, ["lod"], cam, quick, scenes.quad())
    assert row["lod"] is True and row["pixel_error"] == 2.0 and "extra" not in row
    assert bench.label(row).endswith("lod")


def test_not_implemented_is_skipped_other_errors_fail():
    status, reason = bench.classify_failure(NotImplementedError("aniso3d.rendering.splat is off"), "splat")
    assert status == "skipped" and "rendering.splat" in reason
    assert bench.classify_failure(NotImplementedError("soon"), "volume")[0] == "skipped"
    assert bench.classify_failure(ValueError("bad"), "volume") == ("failed", "ValueError: bad")
    # Every renderer module exists: a missing one is a broken install, not a skip.
    for name in ("aniso3d.rendering.splat", "numpy"):
        missing = ModuleNotFoundError(f"No module named '{name}'", name=name)
        assert bench.classify_failure(missing, "splat")[0] == "failed"


def test_csv_and_json_keep_every_column_and_mark_unmeasured_values():
    rows = [
        {**{c: None for c in bench.COLUMNS}, "status": "ok", "psnr": math.inf, "ssim": 1.0,
         "flip": math.nan, "lod_level": 3},
    ]  # fmt: skip
    text = bench.to_csv(rows).decode()
    header, line = list(csv.reader(text.splitlines()))
    assert header[: len(bench.COLUMNS)] == list(bench.COLUMNS) and header[-1] == "lod_level"
    cell = dict(zip(header, line, strict=True))
    assert cell["psnr"] == "inf" and cell["flip"] == "" and cell["lod_level"] == "3"
    doc = json.loads(bench.to_json(bench.BenchResult(rows, {"x": math.inf}, {})))
    assert doc["rows"][0]["psnr"] is None and doc["meta"]["x"] is None


# --------------------------------------------------------------- on the GPU


@pytest.fixture(scope="module")
def gl_available():
    from aniso3d.errors import ResourceError
    from aniso3d.rendering.context import GLContext

    try:
        GLContext().release()
    except ResourceError as exc:
        pytest.skip(f"no OpenGL 3.3 context: {exc}")


def _check_outputs(out, expect_plots: bool) -> list[dict]:
    for name in ("results.csv", "results.json", "report.md"):
        assert (out / name).is_file(), name
    for name in bench.PLOTS:
        assert (out / name).is_file() == expect_plots, name
        if expect_plots:
            assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / "results.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames[: len(bench.COLUMNS)] == list(bench.COLUMNS)
        rows = list(reader)
    doc = json.loads((out / "results.json").read_text())
    assert len(doc["rows"]) == len(rows) > 0
    assert doc["meta"]["colour_space"] == bench.COLOUR_SPACE
    report = (out / "report.md").read_text()
    for heading in ("## Data size", "## Aliasing", "## Speed against accuracy", "## Recommended"):
        assert heading in report
    assert "sRGB-encoded" in report
    return rows


@pytest.mark.gpu
def test_bench_smoke_end_to_end(gl_available, tmp_path, capsys):
    from aniso3d import metrics

    out = tmp_path / "bench"
    assert cli.main(["bench", "--smoke", "-o", str(out), "-q"]) == 0
    rows = _check_outputs(out, expect_plots=bench.matplotlib_available())
    assert {r["renderer"] for r in rows} >= {"mesh-1spp", "mesh-2x2", "volume", "splat"}
    measured = [r for r in rows if r["status"] == "ok"]
    assert any(r["method"] == "mesh" for r in measured)
    for r in rows:
        assert r["status"] in ("ok", "skipped"), r["reason"]
        assert float(r["mesh_bytes"]) > 0 and int(r["n_triangles"]) > 0
        if r["method"] != "mesh":
            assert float(r["texture_bytes"]) > 0 and float(r["build_s"]) > 0
        if r["method"] == "splat" and str(r["lod"]).lower() != "true":
            # 12 float32 a point, 18 more a point with clip planes (PointCloud.nbytes)
            extra = float(r["points_bytes"]) - 48 * int(r["n_points"])
            assert 0 <= extra <= 72 * int(r["n_points"]) and extra % 72 == 0, (r["points_bytes"], r["n_points"])
        if str(r["lod"]).lower() == "true" and r["status"] == "ok":
            # What the renderer drew from the pyramid is recorded.
            key = "lod_points" if r["method"] == "splat" else "lod_level"
            assert r[key] != "" and float(r[key]) >= 0
    for r in measured:
        for key in (
            "frame_s",
            "frame_wall_s",
            "first_frame_s",
            "psnr",
            "ssim",
            "error",
            "coverage",
        ):
            assert math.isfinite(float(r[key])), (key, r)
        assert float(r["frame_s"]) > 0 and -1 <= float(r["ssim"]) <= 1
        if metrics.flip_available():
            assert 0 <= float(r["flip"]) <= 1
        assert float(r["frame_min_s"]) <= float(r["frame_s"]) <= float(r["frame_max_s"])
    # The run states which code, preset and machine load produced it.
    report = (out / "report.md").read_text()
    head = report.split("## ", 1)[0]
    assert "**Preset** `smoke`" in head and "**Code**" in head and "**Frame times**" in head
    assert "## Frame-time spread" in report
    meta = json.loads((out / "results.json").read_text())["meta"]
    assert meta["code"]["commit"] is None or meta["code"]["commit"] in head
    if hasattr(os, "getloadavg"):
        load = meta["load_average"]
        assert len(load["start_1_5_15"]) == 3 and len(load["end_1_5_15"]) == 3
        assert f"{load['start']:.2f} at the start" in head
        assert all(r["load_1min"] != "" for r in measured)
    assert "wrote" in capsys.readouterr().out


@pytest.mark.gpu
def test_unavailable_renderer_is_recorded_as_skipped(gl_available, tmp_path, monkeypatch):
    from aniso3d.rendering.renderer import Renderer

    real = Renderer.method_renderer

    def no_splat(self, method):
        if method == "splat":
            raise NotImplementedError("aniso3d.rendering.splat is switched off in this test")
        return real(self, method)

    monkeypatch.setattr(Renderer, "method_renderer", no_splat)
    monkeypatch.setattr(plots, "matplotlib_available", lambda: False)
    settings = replace(bench.PRESETS["smoke"], size=(64, 64), resolutions=(16,), mesh_ssaa=(1,))
    mesh = scenes.tree(levels=4, leaves_per_twig=20)
    result = bench.run_bench(mesh, settings, with_flip=False)
    splat = [r for r in result.rows if r["method"] == "splat"]
    assert splat and all(r["status"] == "skipped" and "rendering.splat" in r["reason"] for r in splat)
    assert all(r["status"] == "ok" for r in result.rows if r["method"] != "splat")
    # Built and counted even when not drawn (level-of-detail points are made by
    # the renderer, so they have no separate point set).
    assert all(r["points_bytes"] > 0 for r in splat if not r.get("lod"))
    out = tmp_path / "out"
    out.mkdir()
    bench.write_outputs(result, out)
    _check_outputs(out, expect_plots=False)
    report = (out / "report.md").read_text()
    assert "Plots skipped: matplotlib is not installed" in report
    assert "FLIP not computed" in report
    assert "skipped: renderer 'splat' not available yet" in report


def test_bench_refuses_a_file_as_output_folder(tmp_path, capsys):
    target = tmp_path / "mesh.obj"
    target.write_text("v 0 0 0\n")
    assert cli.main(["bench", str(target), "--smoke", "-o", str(target)]) == 2
    assert "is a file" in capsys.readouterr().err
    assert target.read_text() == "v 0 0 0\n"


def test_frame_filling_camera_matches_camera_frame():
    bounds = np.array([[-1.0, 0.0, -1.0], [1.0, 3.0, 1.0]])
    cams = bench.make_cameras(bounds, bench.PRESETS["quick"])
    ref = Camera.frame(bounds)
    assert cams[0].camera == ref


def test_write_between_markers_keeps_the_prose(tmp_path):
    from aniso3d.bench.outputs import markdown_table, write_between_markers

    block = "<!-- b -->\n" + markdown_table(["a", "b"], [["1", "2"]]) + "\n<!-- e -->"
    new = write_between_markers(tmp_path / "new.md", block, "<!-- b -->", "<!-- e -->", title="# T\n\n")
    assert new.read_text() == "# T\n\n" + block + "\n"
    page = tmp_path / "page.md"
    page.write_text("intro\n<!-- b -->\nold table\n<!-- e -->\noutro\n")
    write_between_markers(page, block, "<!-- b -->", "<!-- e -->")
    assert page.read_text() == "intro\n" + block + "\noutro\n"
    assert "| a | b |\n|---|---|\n| 1 | 2 |" in block
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_variant_demo_cells_and_summary():
    """The corpus demos' shared cells (aniso3d.bench.variants): scores as
    "PSNR / FLIP", changes signed, "as good" in both metrics, and the
    per-camera summary over scenes."""
    from aniso3d.bench.variants import as_good, corpus_summary, delta, ms, pair

    assert pair((30.123, 0.01234)) == "30.12 / 0.0123" == pair({"psnr": 30.123, "flip": 0.01234})
    assert delta((31.0, 0.010), (30.5, 0.012)) == ["+0.50", "-0.0020"]
    assert as_good((31.0, 0.010), (30.5, 0.012)) == "yes"
    assert as_good((31.0, 0.013), (30.5, 0.012)) == "no"  # better PSNR, worse FLIP
    assert ms([0.010, 0.030, 0.020]) == "20 [10-30]"
    rows = [
        {"camera": "close", "new": {"psnr": 31, "flip": 0.01, "times": [2, 2]},
         "old": {"psnr": 30, "flip": 0.02, "times": [1, 1]}},
        {"camera": "close", "new": {"psnr": 29, "flip": 0.04, "times": [3]},
         "old": {"psnr": 30, "flip": 0.02, "times": [1]}},
    ]  # fmt: skip
    (close,) = corpus_summary(rows, "new", "old")  # no minified rows: no minified line
    assert close == ["close", "+0.00", "-1.00", "+1.00", "+0.0050", "+0.0200", "2.50 [2.00-3.00]"]
