"""Writing a run: results.csv, results.json, the figures and report.md, each
atomically and never over an input."""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

import numpy as np

from aniso3d.bench import plots
from aniso3d.bench.report import make_report
from aniso3d.bench.run import COLUMNS, BenchResult
from aniso3d.files import atomic_write, refuse_overwriting_input
from aniso3d.metrics import FLIP_MISSING


def cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:.6g}"
    if isinstance(v, np.generic):
        return cell(v.item())
    return str(v)


def columns_of(rows: list[dict]) -> list[str]:
    """:data:`COLUMNS`, then every further key some row has, sorted."""
    extra = sorted({k for r in rows for k in r} - set(COLUMNS))
    return list(COLUMNS) + extra


def to_csv(rows: list[dict]) -> bytes:
    """Every row; empty cells for unmeasured values, ``inf`` for infinite PSNR."""
    cols = columns_of(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([cell(r.get(c)) for c in cols])
    return buf.getvalue().encode("utf-8")


def jsonable(v):
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def to_json(result: BenchResult) -> bytes:
    """``{"meta": ..., "columns": [...], "rows": [...]}``; unmeasured and
    infinite values (PSNR of an identical image) are null."""
    doc = {"meta": result.meta, "columns": columns_of(result.rows), "rows": result.rows}
    return (json.dumps(jsonable(doc), indent=1, allow_nan=False) + "\n").encode("utf-8")


def write_outputs(
    result: BenchResult, outdir: Path, inputs: tuple = (), with_plots: bool = True
) -> tuple[list[Path], list[str]]:
    """Write CSV, JSON, plots and report.md into ``outdir`` (atomically, never
    over one of ``inputs``); returns the paths written and notes for the user."""
    notes: list[str] = []
    written: list[Path] = []

    def put(name: str, data: bytes) -> None:
        path = Path(outdir) / name
        refuse_overwriting_input(path, *inputs)
        written.append(atomic_write(path, data))

    if not result.meta["flip"]:
        notes.append(FLIP_MISSING + "; errors are ranked by 1 - SSIM instead.")
    put("results.csv", to_csv(result.rows))
    put("results.json", to_json(result))
    made: list[str] = []
    if not with_plots:
        notes.append("Plots were not requested (--no-plots).")
    elif not plots.matplotlib_available():
        notes.append("Plots skipped: matplotlib is not installed; install it with: pip install 'aniso3d[plots]'")
    else:
        for name, draw in plots.PLOTTERS.items():
            put(name, draw(result))
            made.append(name)
    put("report.md", make_report(result, made, notes).encode("utf-8"))
    return written, notes


def markdown_table(head: list[str], rows: list[list[str]]) -> str:
    """A Markdown table of the already formatted cells ``rows`` under ``head``."""
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def write_between_markers(path: str | os.PathLike, block: str, begin: str, end: str, title: str = "") -> Path:
    """Put ``block`` (which starts with ``begin`` and ends with ``end``) into
    the Markdown file ``path`` in place of the text between those markers, so
    the prose around a generated table is kept; a file without them gets the
    block appended, a missing file ``title`` and the block. Written atomically."""
    p = Path(path)
    text = p.read_text() if p.exists() else title
    if begin in text and end in text:
        text = text[: text.index(begin)] + block + text[text.index(end) + len(end):]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    return atomic_write(p, text.encode())
