"""Writing a corpus run: corpus_bench.md (tables, one row per scene),
corpus_bench.csv (one row per scene, every number) and corpus_bench.json
(the run, the scene summaries and every row), each atomically."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

from aniso3d.bench.analyse import finite
from aniso3d.bench.corpus import AUTO_CAMERA, AUTO_RENDERERS, CAMERAS, RENDERERS, TARGETS, CorpusResult
from aniso3d.bench.outputs import cell, jsonable
from aniso3d.files import atomic_write

#: Short headers of the targets' columns.
TARGET_HEADERS = {
    "minified_vs_2x2": "minified >= 2x2",
    "volume_faster": "volume faster than 1 spp (minified)",
    "volume_2x": "volume within 2x 1 spp",
    "never_worse_1spp": "never worse than 1 spp",
    "never_worse_1spp_auto": "never worse than 1 spp (auto)",
    "less_flicker": "less flicker than 1 spp",
    "bytes_fifth": "bytes <= mesh / 5",
}
#: Per-scene summary columns of the CSV, before the per-renderer ones.
SCENE_COLUMNS = (
    "scene", "triangles", "vertices", "mesh_ply_bytes", "texture_bytes", "texture_ratio", "points_bytes",
    "points_ratio", "n_voxels", "n_points", "build_s", "close_voxel_px", "minified_scale", "minified_voxel_px",
    "turntable_size", "auto_resolution", "auto_voxel_px", "auto_texture_bytes", "auto_points_bytes", "auto_build_s",
    "seconds",
)  # fmt: skip
STILL_VALUES = ("psnr", "ssim", "flip", "coverage", "frame_s", "frame_min_s", "frame_max_s", "frames")
SPIN_VALUES = ("flicker", "flicker_error", "psnr")
FILES = ("corpus_bench.md", "corpus_bench.csv", "corpus_bench.json")


def _row(result: CorpusResult, scene: str, camera: str, renderer: str) -> dict | None:
    return next((r for r in result.rows if (r["scene"], r["camera"], r["renderer"]) == (scene, camera, renderer)),
                None)  # fmt: skip


def scene_table(result: CorpusResult) -> tuple[list[str], list[dict]]:
    """The columns and one flat dict per scene: the summary, then
    ``<camera>_<renderer>_<value>`` for the two cameras and
    ``turntable_<renderer>_<value>``, then ``target_<name>``."""
    cols = list(SCENE_COLUMNS)
    cols += [f"{c}_{r}_{v}" for c in CAMERAS for r in RENDERERS for v in STILL_VALUES]
    cols += [f"{AUTO_CAMERA}_{r}_{v}" for r in AUTO_RENDERERS for v in STILL_VALUES]
    cols += [f"turntable_{r}_{v}" for r in RENDERERS for v in SPIN_VALUES]
    cols += [f"target_{t}" for t in TARGETS]
    out = []
    for s in result.scenes:
        flat = {k: s.get(k) for k in SCENE_COLUMNS}
        for c, values in [*((c, STILL_VALUES) for c in (*CAMERAS, AUTO_CAMERA)), ("turntable", SPIN_VALUES)]:
            for r in AUTO_RENDERERS if c == AUTO_CAMERA else RENDERERS:
                row = _row(result, s["scene"], c, r) or {}
                ok = row.get("status") == "ok"
                flat.update({f"{c}_{r}_{v}": row.get(v) if ok else None for v in values})
        flat.update({f"target_{t}": s["targets"].get(t) for t in TARGETS})
        out.append(flat)
    return cols, out


def corpus_csv(result: CorpusResult) -> bytes:
    """One row per scene (:func:`scene_table`); empty cells for unmeasured
    values, ``inf`` for infinite PSNR, targets as true/false."""
    cols, table = scene_table(result)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for flat in table:
        w.writerow([cell(flat.get(c)) for c in cols])
    return buf.getvalue().encode("utf-8")


def corpus_json(result: CorpusResult) -> bytes:
    """``{"meta", "scenes", "rows"}``; unmeasured and infinite values are null."""
    doc = {"meta": result.meta, "scenes": result.scenes, "rows": result.rows}
    return (json.dumps(jsonable(doc), indent=1, allow_nan=False) + "\n").encode("utf-8")


# ------------------------------------------------------------------ markdown


def _num(v, spec: str, scale: float = 1.0) -> str:
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return format(v * scale, spec) if finite(v) else "-"


def _bytes(n) -> str:
    if not finite(n):
        return "-"
    for unit, div in (("MB", 1e6), ("kB", 1e3)):
        if n >= div:
            return f"{n / div:.1f} {unit}"
    return f"{n:.0f} B"


def _verdict(v: bool | None) -> str:
    return "n/a" if v is None else "pass" if v else "**fail**"


def _table(header: list[str], body: list[list[str]], right_from: int = 1) -> list[str]:
    align = ["---" if i < right_from else "---:" for i in range(len(header))]
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    return out + ["| " + " | ".join(row) + " |" for row in body] + [""]


def _cell(row: dict | None, what: str) -> str:
    if row is None:
        return "-"
    if row.get("status") != "ok":
        return row.get("status") or "-"
    if what == "quality":
        flip = _num(row.get("flip"), ".3f")
        return _num(row.get("psnr"), ".1f") + ("" if flip == "-" else f" / {flip}")
    if what == "time":
        lo, hi = _num(row.get("frame_min_s"), ".0f", 1e3), _num(row.get("frame_max_s"), ".0f", 1e3)
        return f"{_num(row.get('frame_s'), '.0f', 1e3)} [{lo}-{hi}]"
    return f"{_num(row.get('flicker'), '.2f')} ({_num(row.get('flicker_error'), '.2f')})"


def _renderer_table(result: CorpusResult, camera: str, what: str) -> list[str]:
    body = [[s["scene"], *(_cell(_row(result, s["scene"], camera, r), what) for r in RENDERERS)]
            for s in result.scenes]  # fmt: skip
    return _table(["scene", *RENDERERS], body)


def _auto_tables(result: CorpusResult, quality: str) -> list[str]:
    """The close camera again, the texture renderers at the resolution
    ``--resolution auto`` picks there, beside the close camera's polygons."""
    scenes = [s for s in result.scenes if s.get("auto_resolution")]
    if not scenes:
        return []
    lines = [f"## Close up at the resolution `--resolution auto` picks: {quality}", "",
             "The close camera again; the texture built as finely as that view needs (a voxel about a pixel "
             "where the object is nearest, a power of two, at most 256^3): what `aniso3d render` and the viewer "
             "draw by default. Polygons as in the close-up table. Voxel px: a voxel's width in pixels at the "
             "target; texture: `AnisoTexture.nbytes` of that build.", ""]  # fmt: skip
    cols = ["mesh-1spp", "mesh-2x2", *AUTO_RENDERERS]
    body = []
    for s in scenes:
        name = s["scene"]
        cells = [_cell(_row(result, name, "close", r) if r.startswith("mesh") else _row(result, name, AUTO_CAMERA, r),
                       "quality") for r in cols]  # fmt: skip
        body.append([name, f"{s['auto_resolution']}^3", _num(s.get("auto_voxel_px"), ".2f"),
                     _bytes(s.get("auto_texture_bytes")), _num(s.get("auto_build_s"), ".1f"), *cells])  # fmt: skip
    lines += _table(["scene", "texture", "voxel px", "bytes", "build s", *cols], body)
    lines += ["Frame time: ms, median [fastest-slowest]", ""]
    body = [[s["scene"], _cell(_row(result, s["scene"], "close", "mesh-1spp"), "time"),
             *(_cell(_row(result, s["scene"], AUTO_CAMERA, r), "time") for r in AUTO_RENDERERS)] for s in scenes]
    return lines + _table(["scene", "mesh-1spp", *AUTO_RENDERERS], body)


def _load(meta: dict) -> str:
    load = meta.get("load_average") or {}
    start, end = load.get("start"), load.get("end")
    if not start or not end:
        return "load average not reported by this system"
    return (f"load average (1, 5, 15 min) {', '.join(f'{x:.2f}' for x in start)} at the start, "
            f"{', '.join(f'{x:.2f}' for x in end)} at the end, on {meta.get('cpus')} CPUs")  # fmt: skip


def corpus_markdown(result: CorpusResult, command: str) -> str:
    """The report: how it was made, then one table per question, a row per scene."""
    m, st = result.meta, result.meta["settings"]
    code = m.get("code") or {}
    commit = f"`{code['commit']}`" + (" (with uncommitted changes)" if code.get("dirty") else "") \
        if code.get("commit") else "unknown"  # fmt: skip
    w, h = m["size"]
    gl = m.get("opengl") or {}
    lines = [
        "# Corpus bench",
        "",
        f"Made by `{command}` (run it again to regenerate this page, the CSV and the JSON beside it).",
        "",
        f"- preset **{m['preset']}**: {w}x{h} images; polygon truth at {m['gt_ssaa']}x{m['gt_ssaa']} samples per "
        f"pixel; texture {st['resolution']}^3, K = {st['directions']}; {st['splat']} splats; frame times are the "
        f"median [fastest-slowest] of {st['frames']} frames after {st['warmup']} warm-up, through "
        f"`Renderer.last_frame_seconds` (draw and read back); turntable of {st['turntable']} frames.",
        f"- code: git commit {commit}; {m['date']}; {m['seconds'] / 60:.1f} min.",
        f"- machine: {m.get('cpu_model') or m.get('machine')}, {gl.get('renderer', '?')} "
        f"({gl.get('backend', '?')}); {_load(m)}. Frame times on a loaded machine are slower and noisier "
        "than on an idle one; the ratios between renderers measured together hold better.",
        "- cameras: `aniso3d render`'s view (azimuth 30, elevation 15, fov 40). *close*: its framing, the object "
        "fills the image. *minified*: moved back until a texture voxel spans about one pixel. Errors against the "
        "truth inside the box the object's bounds project to (plus 8 pixels).",
        "- errors: " + ("PSNR (dB, higher is better) / FLIP (lower is better)" if m["flip"] else
                        "PSNR (dB, higher is better); FLIP not installed (pip install 'aniso3d[metrics]'), "
                        "targets judged on PSNR alone") + ".",  # fmt: skip
        "",
        "## Targets",
        "",
    ]
    lines += [f"- **{TARGET_HEADERS[t]}**: {text}." for t, text in TARGETS.items()]
    lines.append("")
    body = [[s["scene"], *(_verdict(s["targets"].get(t)) for t in TARGETS)] for s in result.scenes]
    passes = [f"{sum(s['targets'].get(t) is True for s in result.scenes)}/{len(result.scenes)}" for t in TARGETS]
    body.append(["**scenes passing**", *passes])
    lines += _table(["scene", *TARGET_HEADERS.values()], body)
    lines += ["## Bytes", "",
              "Mesh as binary PLY (12 bytes a vertex, 13 a triangle); texture as `AnisoTexture.nbytes`; points as "
              "`PointCloud.nbytes` (as uploaded). Voxel px: a voxel's width in pixels at the close camera; the "
              "minified camera is that many times farther.", ""]  # fmt: skip
    body = [[s["scene"], f"{s['triangles']:,}", _bytes(s["mesh_ply_bytes"]), _bytes(s["texture_bytes"]),
             _num(s["texture_ratio"], ".2f"), _bytes(s["points_bytes"]), _num(s["points_ratio"], ".2f"),
             _num(s["close_voxel_px"], ".2f"), _num(s["build_s"], ".1f")] for s in result.scenes]  # fmt: skip
    lines += _table(["scene", "triangles", "mesh", "texture", "texture / mesh", "points", "points / mesh",
                     "voxel px (close)", "build s"], body)  # fmt: skip
    quality = "PSNR dB / FLIP" if m["flip"] else "PSNR dB"
    lines += ["## Close up: " + quality, ""] + _renderer_table(result, "close", "quality")
    lines += ["## Minified: " + quality, ""] + _renderer_table(result, "minified", "quality")
    lines += ["## Frame time, close up: ms, median [fastest-slowest]", ""] + _renderer_table(result, "close", "time")
    lines += ["## Frame time, minified: ms, median [fastest-slowest]", ""]
    lines += _renderer_table(result, "minified", "time")
    lines += [
        "## Flicker on a turntable at the minified distance",
        "",
        f"{st['turntable']} frames over a full turn. Flicker: the mean absolute frame-to-frame change over the "
        "truth's own (1.0 = changes as much as the truth; above 1 = flickers). In parentheses the temporal "
        "error: the mean absolute difference between the rendering's frame-to-frame change and the truth's, over "
        "the truth's mean change (0 = every change is the truth's; a blurred rendering can flicker less than the "
        "truth and still have a large temporal error).",
        "",
    ]
    lines += _renderer_table(result, "turntable", "flicker")
    lines += _auto_tables(result, quality)
    bad = [r for r in result.rows if r.get("status") != "ok"]
    if bad:
        lines += ["## Not measured", ""]
        lines += [f"- {r['scene']}, {r['camera']}, {r['renderer']}: {r['status']}: {r['reason']}" for r in bad]
        lines.append("")
    return "\n".join(lines)


def write_corpus(result: CorpusResult, outdir: Path, command: str) -> list[Path]:
    """Write :data:`FILES` into ``outdir`` (made if missing); returns their paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    data = (corpus_markdown(result, command).encode("utf-8"), corpus_csv(result), corpus_json(result))
    return [atomic_write(outdir / name, blob) for name, blob in zip(FILES, data, strict=True)]
