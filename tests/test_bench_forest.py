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
