"""``aniso3d bench forest``: frame time of forests of several sizes, per renderer, and the report."""

from __future__ import annotations

import re

import pytest

from aniso3d.app.cli import main
from aniso3d.bench.forest import ForestSettings, run_forest
from aniso3d.errors import InputError


def test_the_forest_bench_writes_its_table_and_plot(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = tmp_path / "out"
    code = main(["bench", "forest", "--counts", "1", "3", "--size", "48", "--reps", "2", "--error-size", "32",
                 "-o", str(out), "-q"])  # fmt: skip
    assert code == 0
    page = (out / "forest.md").read_text()
    assert (out / "forest.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "aniso3d bench forest --counts 1 3 --size 48" in page
    row = r"^\| (\d+) \| (splat|volume|volume passes|mesh) \| (\d+) \((\d+)-(\d+)\) \| (\d+) \|"
    rows = re.findall(row, page, re.M)
    # every method at both counts, each instance of the scene (trees + ground) visible
    assert {(n, m) for n, m, *_ in rows} == {(n, m) for n in ("1", "3") for m in ("splat", "volume", "volume passes",
                                                                                     "mesh")}  # fmt: skip
    for n, _, med, lo, hi, visible in rows:
        assert int(lo) <= int(med) <= int(hi) and int(visible) == int(n) + 1
    errors = re.findall(r"^\| (1|3) \| (splat fast|splat high|volume|volume passes) \| ([\d.]+) \|", page, re.M)
    assert len(errors) == 8 and all(10 < float(p) < 80 for *_, p in errors)  # PSNR, dB
    assert "wrote" in capsys.readouterr().out


def test_bad_forest_settings_are_one_clear_error():
    with pytest.raises(InputError, match="positive"):
        run_forest(ForestSettings(counts=(0,)))
    with pytest.raises(InputError, match="positive"):
        run_forest(ForestSettings(reps=0))


def test_a_bad_output_is_refused_before_the_run(tmp_path, capsys, monkeypatch):
    import aniso3d.bench.forest as forest

    monkeypatch.setattr(forest, "run_forest", lambda *a, **k: pytest.fail("the bench ran"))
    (tmp_path / "afile").write_text("x")
    code = main(["bench", "forest", "--counts", "1", "-o", str(tmp_path / "afile"), "-q"])
    assert code == 2 and "is a file" in capsys.readouterr().err


def test_counts_beyond_the_error_range_write_no_error_table(tmp_path):
    pytest.importorskip("matplotlib")
    from pathlib import Path

    from aniso3d.bench.forest import write_report

    rows = [{"n": 200, "method": "splat", "median_ms": 1.0, "min_ms": 1.0, "max_ms": 1.0, "visible": 201,
             "points": 10, "levels": [201], "selection_ms": 0.1, "calls": 1}]  # fmt: skip
    page = write_report(rows, [], [0.5], ForestSettings(counts=(200,)), Path(tmp_path), "test").read_text()
    assert "| 200 | splat | 1 (1-1) | 201 |" in page and "Error against" not in page
