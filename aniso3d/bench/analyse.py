"""Reading the rows: the Pareto front, per-block selections, the recommended
value of each setting, the best renderer per distance and the spread of the
timed frames. Everything here works on plain row dicts (see
:data:`aniso3d.bench.run.COLUMNS`) and needs no GPU."""

from __future__ import annotations

import math

import numpy as np

from aniso3d.bench.settings import AXES, RENDERERS, SPLAT_AXES

MESH_RENDERERS = ("mesh-1spp", "mesh-2x2", "mesh-4x4")


def finite(x) -> bool:
    """A real, finite number (not None, not a bool, not NaN or inf)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def measured(rows: list[dict]) -> list[dict]:
    """The rows that were measured, with a finite error and frame time."""
    return [r for r in rows if r["status"] == "ok" and finite(r.get("error")) and finite(r.get("frame_s"))]


def in_block(row: dict, block: str) -> bool:
    return block in (row.get("blocks") or "").split(";")


def error_name(meta: dict) -> str:
    """The ranked error's name: FLIP when computed, else 1 - SSIM."""
    return "FLIP" if meta["error_metric"] == "flip" else "1 - SSIM"


def label(row: dict, verbose: bool = False) -> str:
    """Short human name of a row's configuration."""
    if row["method"] == "mesh":
        return row["renderer"]
    parts = [row["renderer"], f"{row['resolution']}^3", f"K={row['directions']}"]
    if row["method"] == "splat":
        parts += [row["placement"], row["splat"], row["quality"]]
        if verbose or row["per_entry"] != 1:
            parts.append(f"x{row['per_entry']}")
    if verbose or row["point_normal"] not in (None, "mean"):
        parts.append(f"n={row['point_normal']}")
    if row.get("lod"):
        parts.append("lod")
    return " ".join(str(p) for p in parts)


def cost(row: dict) -> float:
    """CPU seconds per frame where measured, else the frame's wall seconds."""
    return row["frame_cpu_s"] if finite(row.get("frame_cpu_s")) else row["frame_s"]


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (cost, error) that no other point beats on both
    (lower is better for both), sorted by cost."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def mark_pareto(rows: list[dict]) -> None:
    """Set ``row["pareto"]``: on the (frame time, error) front of its camera."""
    for r in rows:
        r["pareto"] = False
    for cam in {r["camera"] for r in rows}:
        group = [r for r in measured(rows) if r["camera"] == cam]
        for i in pareto_front([(r["frame_s"], r["error"]) for r in group]):
            group[i]["pareto"] = True


def grid_row(rows: list[dict], camera: str, renderer: str) -> dict | None:
    """The grid block's row of ``renderer`` at ``camera`` (any status)."""
    return next((r for r in rows if in_block(r, "grid") and r["camera"] == camera and r["renderer"] == renderer), None)


def recommend(rows: list[dict], tolerance: float = 0.01) -> list[dict]:
    """Per axis and renderer, the value to use, from the one-axis blocks.

    The most accurate value is the one with the lowest mean error over the
    near and far cameras. Among the values within ``tolerance`` (relative) of
    that error, the one with at least 5% fewer bytes wins (the smallest), else
    one no larger and at least 10% cheaper in CPU seconds per frame (CPU time
    counts the rasteriser's work and, unlike wall time, hardly depends on what
    else the machine runs), else the most accurate itself.

    Returns one dict per (axis, renderer): axis, renderer, value, best, why,
    and table {value: (error, frame seconds, bytes)}.
    """
    out = []
    ok = measured(rows)
    for axis, fieldname in AXES.items():
        for method in ("volume", "splat"):
            if method == "volume" and axis in SPLAT_AXES:
                continue
            block = [r for r in ok if in_block(r, axis) and r["method"] == method]
            if not block:
                continue
            table: dict = {}
            for v in dict.fromkeys(r[fieldname] for r in block):
                sel = [r for r in block if r[fieldname] == v]
                key = "points_bytes" if method == "splat" else "texture_bytes"
                nbytes = [r[key] for r in sel if finite(r.get(key))]
                table[v] = (
                    float(np.mean([r["error"] for r in sel])),
                    float(np.mean([cost(r) for r in sel])),
                    float(np.mean(nbytes)) if nbytes else math.nan,
                )
            best = min(table, key=lambda v: table[v][0])
            e0, t0, b0 = table[best]
            near = [v for v in table if table[v][0] <= e0 * (1 + tolerance)]  # with best
            smallest = min(near, key=lambda v: table[v][2] if finite(table[v][2]) else math.inf)
            # Only values about as large as the most accurate compete on time.
            same_size = [v for v in near if not table[v][2] > 1.05 * b0]
            cheapest = min(same_size, key=lambda v: table[v][1])
            if table[smallest][2] < 0.95 * b0:
                pick = smallest
                why = (
                    f"within {100 * tolerance:.0f}% of the most accurate ({best}) with "
                    f"{table[pick][2] / 2**20:.1f} instead of {b0 / 2**20:.1f} MiB"
                )
            elif table[cheapest][1] < 0.9 * t0:
                pick = cheapest
                why = (
                    f"within {100 * tolerance:.0f}% of the most accurate ({best}) and cheaper "
                    f"({1e3 * table[pick][1]:.0f} vs {1e3 * t0:.0f} CPU ms per frame)"
                )
            else:
                pick = best
                why = (
                    f"lowest mean error; no value within {100 * tolerance:.0f}% of it is 5% smaller "
                    "or 10% cheaper"
                )
            out.append(
                {"axis": axis, "renderer": method, "value": pick, "best": best, "why": why,
                 "table": table}
            )  # fmt: skip
    return out


def renderer_by_distance(rows: list[dict], tolerance: float = 0.1) -> list[dict]:
    """Per grid camera (nearest first), the most accurate renderer and the
    cheapest one (CPU seconds per frame) whose error is within ``tolerance``
    (relative) of it: what to draw at that distance.

    Also the cheapest renderer more accurate than one-sample polygons
    (``beats_1spp``, None when none is or they were not measured).

    Returns dicts: camera, voxel_px, best, pick, beats_1spp (rows).
    """
    grid = [r for r in measured(rows) if in_block(r, "grid")]
    out = []
    for cam in dict.fromkeys(r["camera"] for r in sorted(grid, key=lambda r: r["distance_scale"])):
        group = [r for r in grid if r["camera"] == cam]
        best = min(group, key=lambda r: r["error"])
        close = [r for r in group if r["error"] <= best["error"] * (1 + tolerance)]
        pick = min(close, key=cost)
        one = next((r for r in group if r["renderer"] == "mesh-1spp"), None)
        better = [r for r in group if one is not None and r["error"] < one["error"]]
        out.append({"camera": cam, "voxel_px": group[0]["camera_voxel_px"], "best": best, "pick": pick,
                    "beats_1spp": min(better, key=cost) if better else None})  # fmt: skip
    return out


def aliasing_means(rows: list[dict], cameras: list[str]) -> dict[str, dict[str, float]]:
    """Each grid renderer's metrics averaged over ``cameras`` (only renderers
    measured at all of them): renderer -> {psnr, ssim, flip, error, coverage,
    frame_s, frame_cpu_s} (keys with a non-finite value left out)."""
    means: dict[str, dict[str, float]] = {}
    if not cameras:
        return means
    for name in RENDERERS:
        sel = [r for r in measured(rows) if in_block(r, "grid") and r["renderer"] == name and r["camera"] in cameras]
        if len(sel) == len(cameras):
            means[name] = {
                k: float(np.mean([r[k] for r in sel]))
                for k in ("psnr", "ssim", "flip", "error", "coverage", "frame_s", "frame_cpu_s")
                if all(finite(r.get(k)) for r in sel)
            }
    return means


def frame_spread(row: dict) -> float:
    """(slowest - fastest) / median timed frame of a row: 0 when every frame
    took as long; NaN when not measured."""
    lo, mid, hi = row.get("frame_min_s"), row.get("frame_s"), row.get("frame_max_s")
    if not (finite(lo) and finite(mid) and finite(hi)) or mid <= 0:
        return math.nan
    return (hi - lo) / mid


def timing_summary(rows: list[dict]) -> dict:
    """How steady the timed frames were, over the measured rows: rows, frames
    per row (median, min), the relative spread of each row's frames
    (:func:`frame_spread`: median, 90th percentile, max) and the row with the
    largest spread; and per renderer the median spread and median frame ms."""
    ok = [r for r in measured(rows) if finite(frame_spread(r))]
    if not ok:
        return {}
    spreads = np.array([frame_spread(r) for r in ok])
    frames = np.array([r["frames"] for r in ok])
    worst = ok[int(np.argmax(spreads))]
    per_renderer = {}
    for name in dict.fromkeys(r["renderer"] for r in ok):
        sel = [r for r in ok if r["renderer"] == name]
        per_renderer[name] = {
            "rows": len(sel),
            "spread_median": float(np.median([frame_spread(r) for r in sel])),
            "frame_ms_median": 1e3 * float(np.median([r["frame_s"] for r in sel])),
        }
    return {
        "rows": len(ok),
        "frames_median": float(np.median(frames)),
        "frames_min": int(frames.min()),
        "spread_median": float(np.median(spreads)),
        "spread_p90": float(np.percentile(spreads, 90)),
        "spread_max": float(spreads.max()),
        "worst": worst,
        "per_renderer": per_renderer,
    }


def default_changes(recommendations: list[dict], baseline: dict, tolerance: float = 0.01) -> tuple[list, list]:
    """Split the recommendations that differ from the baseline (the code's
    defaults) into (change, keep).

    The baseline is the incumbent: the data says to change it only when the
    recommended value is more accurate by more than ``tolerance`` (relative),
    or as accurate (within ``tolerance``) and at least 5% smaller or 10%
    cheaper per frame. Otherwise the difference is within the noise of this
    rule and the baseline may stay (``keep``). A baseline value the block did
    not measure counts as a change.
    """
    change, keep = [], []
    for rec in recommendations:
        here = baseline.get(rec["axis"])
        if rec["value"] == here:
            continue
        if here not in rec["table"]:
            change.append(rec)
            continue
        e_p, t_p, b_p = rec["table"][rec["value"]]
        e_b, t_b, b_b = rec["table"][here]
        clearly_better = e_p * (1 + tolerance) < e_b
        as_good = e_p <= e_b * (1 + tolerance)
        smaller = finite(b_p) and finite(b_b) and b_p < 0.95 * b_b
        (change if clearly_better or (as_good and (smaller or t_p < 0.9 * t_b)) else keep).append(rec)
    return change, keep
