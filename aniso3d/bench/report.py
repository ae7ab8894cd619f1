"""The Markdown report: the run (preset, code, machine, load), the setup,
figures, tables, and a reading generated from the numbers, one function per
section. Every sentence that states a finding is computed from the rows, so a
rerun cannot leave text that disagrees with its own tables."""

from __future__ import annotations

import math
from dataclasses import dataclass

from aniso3d.bench.analyse import (
    MESH_RENDERERS,
    aliasing_means,
    cost,
    default_changes,
    error_name,
    finite,
    grid_row,
    in_block,
    label,
    measured,
    recommend,
    renderer_by_distance,
    timing_summary,
)
from aniso3d.bench.run import BenchResult
from aniso3d.bench.settings import AXES, BASELINE, RENDERERS


@dataclass(frozen=True)
class _View:
    """What every section reads: the result, the error's name, the cameras
    (dicts of ``meta["cameras"]``), the near and far ones, the figures written."""

    result: BenchResult
    err: str
    cams: list[dict]
    near: dict
    far: dict
    plots: tuple[str, ...]

    @property
    def meta(self) -> dict:
        return self.result.meta

    @property
    def rows(self) -> list[dict]:
        return self.result.rows


# ------------------------------------------------------------------ formatting


def _fmt(v, spec: str = ".3g", scale: float = 1.0) -> str:
    if not finite(v):
        return "inf" if isinstance(v, float) and math.isinf(v) else "-"
    return format(v * scale, spec)


def _mib(v) -> str:
    return "-" if not finite(v) else f"{v / 2**20:.1f} MiB"


def _pct(v) -> str:
    return "-" if not finite(v) else f"{100 * v:.0f}%"


def _metrics_cells(r: dict) -> list[str]:
    if r["status"] != "ok":
        return [r["status"]] * 5
    return [
        _fmt(r["psnr"], ".2f"),
        _fmt(r["ssim"], ".4f"),
        _fmt(r["flip"], ".4f"),
        _fmt(r.get("coverage"), ".2f"),
        _fmt(r["frame_s"], ".1f", 1e3),
    ]


def _table(header: list[str], body: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(row) + " |" for row in body]
    return out + [""]


def _compare(a: float, b: float) -> str:
    """'x% lower' / 'x% higher' of error a relative to b."""
    if not (finite(a) and finite(b)) or b == 0:
        return "n/a"
    d = (a - b) / b
    return f"{abs(100 * d):.0f}% {'lower' if d < 0 else 'higher'}"


def _ms(r: dict) -> str:
    return f"{_fmt(r['frame_s'], '.1f', 1e3)} ms"


# --------------------------------------------------------------------- the run


def _machine_busy(meta: dict) -> bool:
    """Other work competed for the CPUs: the load was above half the CPUs
    before the run began, or above the CPUs (plus a margin) while it ran. The
    run's own rasteriser threads add about one per CPU while it runs."""
    load = meta.get("load_average") or {}
    cpus = meta.get("cpus") or 1
    during = load.get("during_median")
    if during is None:
        during = load.get("end")
    return (load.get("start") or 0.0) > 0.5 * cpus or (during or 0.0) > cpus + 0.5


def _load_line(meta: dict) -> str:
    load = meta.get("load_average") or {}
    if load.get("start") is None:
        return "load average not reported by this system."
    triplet = load.get("start_1_5_15")
    text = f"1-minute load average {load['start']:.2f} at the start"
    if triplet:
        text += f" (5 and 15 minutes: {triplet[1]:.2f}, {triplet[2]:.2f})"
    text += f", {_fmt(load.get('end'), '.2f')} at the end"
    if load.get("during_median") is not None:
        text += (
            f"; sampled after each row: median {load['during_median']:.2f}, "
            f"range {load['during_min']:.2f} to {load['during_max']:.2f}"
        )
    return text + f", on {meta.get('cpus')} CPUs."


def _code_line(meta: dict) -> str:
    code = meta.get("code") or {}
    if not code.get("commit"):
        return "not a git checkout (commit unknown)."
    state = "with uncommitted changes to tracked files" if code.get("dirty") else "clean checkout"
    return f"git commit `{code['commit']}` ({state})."


def section_run(v: _View) -> list[str]:
    """Title and the facts that decide how far the numbers can be trusted:
    preset, code version, machine, load, and how steady the frame times were."""
    meta, s = v.meta, v.meta["settings"]
    t = timing_summary(v.rows)
    gl = meta["opengl"]
    L = [
        f"# aniso3d bench: {meta['scene']}",
        "",
        f"- **Preset** `{meta['preset']}`: {s['size'][0]}x{s['size'][1]} images, run {meta['date']} "
        f"in {meta['seconds'] / 60:.1f} min.",
        f"- **Code**: {_code_line(meta)}",
        f"- **Machine**: {meta.get('cpus')} CPUs ({meta.get('cpu_model') or meta.get('machine')}), "
        f"{gl['renderer']} ({gl['backend']}), Python {meta.get('python')}.",
        f"- **Load**: {_load_line(meta)}",
    ]
    if t:
        L.append(
            f"- **Frame times**: median of up to {s['frames']} timed frames per configuration after "
            f"{s['warmup']} warm-up frame(s) (median {t['frames_median']:.0f} timed, at least "
            f"{t['frames_min']}; a configuration stops after {s['frame_budget']:g} s). Their spread, "
            f"(slowest - fastest) / median, is {_pct(t['spread_median'])} in the median row, "
            f"{_pct(t['spread_p90'])} at the 90th percentile and {_pct(t['spread_max'])} at most "
            f"({label(t['worst'])} at `{t['worst']['camera']}`)."
        )
    if _machine_busy(meta):
        L.append(
            "- **The machine was busy with other work during this run: compare frame times with "
            "care; differences under about 2x may be noise.**"
        )
    return L + [""]


def _baseline_origin(base: dict) -> str:
    """Whether the run's baseline is what ``aniso3d render`` draws by default."""
    differs = [f"{k} {base.get(k)} instead of {x}" for k, x in BASELINE.items() if base.get(k) != x]
    if not differs:
        return "what `aniso3d render` draws by default."
    return "`aniso3d render`'s defaults except " + ", ".join(differs) + " (set by the preset)."


def section_setup(v: _View) -> list[str]:
    """Ground truth, frame timing, metrics, cameras and the baseline."""
    meta, s, err = v.meta, v.meta["settings"], v.err
    base = s["baseline"]
    return [
        f"Scene: {meta['triangles']:,} triangles. Ground truth: the polygon model at "
        f"{meta['gt_ssaa']}x{meta['gt_ssaa']} samples per pixel, same camera, lights and image size. "
        "Frame time: draw plus read-back as `Renderer.last_frame_seconds` reports it (supersampled "
        "rows: their down-filtering on the CPU is in `frame_wall_s` only). Frame times are "
        "wall-clock and include any contention from other processes. Less affected, in the CSV: "
        "`frame_min_s` (the fastest frame) and `frame_cpu_s` (this process's CPU seconds per frame "
        "over all rasteriser threads, counting work rather than waiting, less the host-side "
        "down-filtering of supersampled rows, `downfilter_cpu_s`); `frame_max_s` is the slowest "
        "frame and `load_1min` the load average after each row.",
        "",
        f"**Colour space and metrics.** {meta['colour_space']} The error plotted and ranked is "
        f"**{err}**. `coverage` is the rendering's covered area (the sum of its alpha) over the "
        "ground truth's, in the same box: above 1, it hides more background than the polygons do.",
        "",
        "**Cameras.** "
        + "; ".join(
            f"`{c['label']}`: distance x{c['distance_scale']:.2f}, baseline voxel {c['voxel_px']:.2f} px"
            + (f" ({c['role']})" if c["role"] else "")
            for c in v.cams
        )
        + ". "
        f"The baseline is {base['resolution']}^3, K = {base['directions']}, {base['placement']} "
        f"placement, {base['per_entry']} point(s) per entry, {base['point_normal']} normal, "
        f"{base['splat']} splats, {base['quality']} quality: " + _baseline_origin(base),
        "",
    ]


# ------------------------------------------------------------------- findings


def _data_size_rows(v: _View) -> list[list[str]]:
    res_rows = [r for r in v.rows if in_block(r, "resolution") and r["camera"] == v.near["label"]]
    mb = v.meta["mesh_bytes"]
    body = []
    for res in sorted({r["resolution"] for r in res_rows}):
        tex = next((r for r in res_rows if r["resolution"] == res and finite(r.get("texture_bytes"))), None)
        pts = next((r for r in res_rows if r["resolution"] == res and finite(r.get("points_bytes"))), None)
        if tex is None:
            continue
        body.append([
            f"{res}^3", f"{tex['n_voxels']:,}", f"{tex['n_entries']:,}", _mib(mb), _mib(tex["texture_bytes"]),
            f"{tex['texture_bytes'] / mb:.2f}", _mib(pts["points_bytes"]) if pts else "-",
            f"{pts['points_bytes'] / mb:.2f}" if pts else "-", _fmt(tex["build_s"], ".1f"),
        ])  # fmt: skip
    return body


def _upload_sentences(rows: list[dict], camera: str, res: int) -> list[str]:
    """What each renderer holds on the GPU, and where the texture's bytes go."""

    def first(**match):
        return next((r for r in rows if r["camera"] == camera and finite(r.get("upload_bytes"))
                     and all(r.get(k) == x for k, x in match.items())), None)  # fmt: skip

    out = []
    mesh, vol, spl = first(method="mesh", ssaa=1), first(method="volume", resolution=res), first(
        method="splat", resolution=res)  # fmt: skip
    parts = [f"{name} {_mib(r['upload_bytes'])}" for name, r in (("polygons", mesh), ("volume", vol),
             ("splats", spl)) if r]  # fmt: skip
    if parts:
        out.append(f"As uploaded to the GPU at {res}^3: " + ", ".join(parts) + ".")
    tex = vol or spl
    if tex and finite(tex.get("density_bytes")):
        t = tex["texture_bytes"]
        d, c, n = tex["density_bytes"], tex["centroid_bytes"], tex["mean_normal_bytes"]
        out.append(
            f"Of the {_mib(t)} texture, the density spheres (float64, voxels x K) are {_mib(d)} "
            f"({100 * d / t:.0f}%), the entries' centroids {_mib(c)} and mean normals {_mib(n)} "
            f"(the cost of centroid placement and mean normals), the rest {_mib(t - d - c - n)}."
        )
    return out + ([""] if out else [])


def section_data_size(v: _View) -> list[str]:
    """Texture and point bytes by resolution against the mesh's."""
    L = ["## Data size", ""]
    if "bytes.png" in v.plots:
        L += ["![bytes vs resolution](bytes.png)", ""]
    body = _data_size_rows(v)
    L += _table(["resolution", "voxels", "entries (points)", "mesh", "texture", "texture/mesh", "points",
                 "points/mesh", "build s"], body)  # fmt: skip
    base_res = v.meta["settings"]["baseline"]["resolution"]
    b = next((x for x in body if x[0] == f"{base_res}^3"), None)
    if b:
        ratio_t, ratio_p = float(b[5]), float(b[7]) if b[7] != "-" else math.nan
        if ratio_t >= 1 and not (ratio_p < 1):
            verdict = "The paper's data-reduction claim does not hold for this scene at this resolution."
        elif ratio_p < 1 <= ratio_t:
            verdict = "The data reduction holds for the points."
        else:
            verdict = "The data reduction holds."
        L += [
            f"At {base_res}^3 the texture is {ratio_t:.2f}x the mesh ({'smaller' if ratio_t < 1 else 'larger'}); "
            f"the points are {_fmt(ratio_p, '.2f')}x the mesh. Texture bytes count every stored array as "
            "held in memory (float64 density and area, the float64 centroid and float32 mean normal per "
            "entry); point bytes are 12 float32 per point as uploaded, 18 with clip planes. " + verdict,
            "",
        ]
    L += _upload_sentences(v.rows, v.near["label"], base_res)
    krows = [r for r in v.rows if in_block(r, "directions") and r["camera"] == v.near["label"]
             and r["method"] == "volume" and finite(r.get("texture_bytes"))]  # fmt: skip
    if krows:
        L += [
            "Texture bytes at the baseline resolution by K: "
            + ", ".join(f"K={r['directions']}: {_mib(r['texture_bytes'])}"
                        for r in sorted(krows, key=lambda r: r["directions"]))  # fmt: skip
            + ".",
            "",
        ]
    return L


def section_distance(v: _View) -> list[str]:
    """Every renderer at every camera (the grid), and a line per camera."""
    L = ["## Error and frame time vs camera distance", ""]
    if "distance.png" in v.plots:
        L += ["![error vs distance](distance.png)", ""]
    if "montage.png" in v.plots:
        L += ["![images](montage.png)", ""]
    body = []
    for c in v.cams:
        for name in RENDERERS:
            r = grid_row(v.rows, c["label"], name)
            if r is not None:
                body.append([c["label"], name] + _metrics_cells(r))
    L += _table(["camera", "renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "frame ms"], body)
    for c in v.cams:
        grid = [r for r in measured(v.rows) if in_block(r, "grid") and r["camera"] == c["label"]]
        if not grid:
            continue
        best = min(grid, key=lambda r: r["error"])
        fast = min(grid, key=lambda r: r["frame_s"])
        one = next((r for r in grid if r["renderer"] == "mesh-1spp"), None)
        beat1 = sorted((r for r in grid if one and r["error"] < one["error"] and r is not one),
                       key=lambda r: r["frame_s"])  # fmt: skip
        line = (
            f"- `{c['label']}` (voxel {c['voxel_px']:.2f} px): most accurate **{best['renderer']}** "
            f"({v.err} {_fmt(best['error'], '.4f')}, {_ms(best)}); fastest {fast['renderer']} ({_ms(fast)})"
        )
        if beat1:
            line += f"; cheapest that beats 1-spp polygons: {beat1[0]['renderer']} ({_ms(beat1[0])})"
        L.append(line + ".")
    return L + [""]


def _aliasing_summary(v: _View, cameras: list[str]) -> list[str]:
    """Each grid renderer averaged over ``cameras``, and the texture renderers'
    mean error relative to the polygon renderings."""
    means = aliasing_means(v.rows, cameras)
    if not means:
        return []
    n = len(cameras)
    out = [f"Mean over the {n} camera{'s' if n != 1 else ''} where a baseline voxel is a pixel or less:", ""]
    body = [
        [name, _fmt(m.get("psnr"), ".2f"), _fmt(m.get("ssim"), ".4f"), _fmt(m.get("flip"), ".4f"),
         _fmt(m.get("coverage"), ".2f"), _fmt(m.get("frame_s"), ".0f", 1e3), _fmt(m.get("frame_cpu_s"), ".0f", 1e3)]
        for name, m in means.items()
    ]  # fmt: skip
    out += _table(["renderer", "PSNR dB", "SSIM", "FLIP", "coverage", "frame ms", "CPU ms"], body)
    for name in ("volume", "splat"):
        if name not in means:
            continue
        cmp_ = ", ".join(f"{_compare(means[name]['error'], means[m]['error'])} than {m}"
                         for m in MESH_RENDERERS if m in means)  # fmt: skip
        out.append(f"- {name}: mean {v.err} {_fmt(means[name]['error'], '.4f')}, {cmp_}.")
    return out + [""]


def section_aliasing(v: _View) -> list[str]:
    """The texture renderers against the polygons where a voxel is a pixel or less."""
    L = ["## Aliasing: voxels of a pixel or less", ""]
    far_cams = [c for c in v.cams if c["voxel_px"] <= 1.0 + 1e-6]
    if not far_cams:
        L += ["No camera of this run puts a baseline voxel at a pixel or less.", ""]
    for c in far_cams:
        parts = []
        for name in ("volume", "splat"):
            r = grid_row(v.rows, c["label"], name)
            if r is None:
                continue
            if r["status"] != "ok":
                parts.append(f"{name}: not measured ({r['status']}: {r['reason']})")
                continue
            refs = [(n, grid_row(v.rows, c["label"], n)) for n in MESH_RENDERERS]
            cmp_ = ", ".join(f"{_compare(r['error'], m['error'])} than {n} ({_fmt(m['error'], '.4f')}, {_ms(m)})"
                             for n, m in refs if m is not None and m["status"] == "ok")  # fmt: skip
            parts.append(f"{name}: {v.err} {_fmt(r['error'], '.4f')} at {_ms(r)}, {cmp_}")
        L.append(f"- `{c['label']}` (voxel {c['voxel_px']:.2f} px): " + "; ".join(parts) + ".")
    L.append("")
    return L + _aliasing_summary(v, [c["label"] for c in far_cams])


def section_pareto(v: _View) -> list[str]:
    """The (frame time, error) front at the near and far cameras."""
    L = ["## Speed against accuracy", ""]
    if "pareto.png" in v.plots:
        L += ["![error vs frame time](pareto.png)", ""]
    for c in (v.near, v.far) if v.far is not v.near else (v.near,):
        front = sorted((r for r in v.rows if r["camera"] == c["label"] and r["pareto"]), key=lambda r: r["frame_s"])
        L += [
            f"Pareto front at the {c['role']} camera (`{c['label']}`), fastest first: "
            + "; ".join(f"{label(r)} ({_ms(r)}, {_fmt(r['error'], '.4f')})" for r in front)
            + ".",
            "",
        ]
    return L


def _axis_reading(rows: list[dict], fieldname: str, err: str) -> list[str]:
    """One generated line per renderer and camera: best and worst value and the spread."""
    out = []
    ok = measured(rows)
    for method in ("volume", "splat"):
        for cam in dict.fromkeys(r["camera"] for r in ok):
            sel = sorted((r for r in ok if r["method"] == method and r["camera"] == cam), key=lambda r: r["error"])
            if len(sel) < 2:
                continue
            best, worst = sel[0], sel[-1]
            fast = min(sel, key=lambda r: r["frame_s"])
            out.append(
                f"- {method} at `{cam}`: best {best[fieldname]} ({err} {_fmt(best['error'], '.4f')}, {_ms(best)}), "
                f"worst {worst[fieldname]} ({_fmt(worst['error'], '.4f')}): error spread "
                f"{_compare(worst['error'], best['error'])}; fastest {fast[fieldname]} ({_ms(fast)})."
            )
    return out


def section_axes(v: _View) -> list[str]:
    """One table per one-axis block, with a generated reading."""
    L = [
        "## One setting at a time",
        "",
        f"Each setting varied alone around the baseline, at the near (`{v.near['label']}`) and far "
        f"(`{v.far['label']}`) cameras. Bytes: the texture for volume rows, the points for splat rows.",
        "",
    ]
    for axis, fieldname in AXES.items():
        sel = [r for r in v.rows if in_block(r, axis)]
        if not sel:
            continue
        body = []
        for r in sorted(sel, key=lambda r: (r["method"], r["camera"] != v.near["label"], str(r[fieldname]))):
            nbytes = r.get("points_bytes") if r["method"] == "splat" else r.get("texture_bytes")
            body.append([str(r[fieldname]), r["method"], r["camera"]] + _metrics_cells(r)
                        + [_mib(nbytes), _fmt(r.get("build_s"), ".1f")])  # fmt: skip
        L += [f"### {axis}", ""]
        L += _table([axis, "renderer", "camera", "PSNR dB", "SSIM", "FLIP", "coverage", "frame ms", "bytes",
                     "build s"], body)  # fmt: skip
        L += _axis_reading(sel, fieldname, v.err) + [""]
    return L


def section_lod(v: _View) -> list[str]:
    """The level-of-detail block against the single finest level."""
    lod_rows = [r for r in v.rows if in_block(r, "lod")]
    if not lod_rows:
        return []
    L = [
        "## Level of detail",
        "",
        "The baseline volume and splats drawn from the texture's exact pyramid (`lod=True`, one voxel "
        "per pixel): splats take, per region, the coarsest level whose voxels cover at most a pixel, "
        "and skip what is outside the view; the volume marches the one level fine enough at the "
        "object's nearest depth. Each against the same renderer on the single finest level.",
        "",
    ]
    body = []
    for cam in v.cams:
        for method in ("splat", "volume"):
            single = grid_row(v.rows, cam["label"], method)
            lod = next((r for r in lod_rows if r["camera"] == cam["label"] and r["method"] == method), None)
            if single is None or lod is None:
                continue
            if method == "splat":
                drawn = f"{_fmt(lod.get('lod_points'), ',.0f')} of {_fmt(single.get('n_points'), ',.0f')} points"
            else:
                drawn = f"level {lod.get('lod_level', '?')}"
            pairs = zip(_metrics_cells(single), _metrics_cells(lod), strict=True)
            body.append([cam["label"], method, drawn] + [f"{a} / {b}" for a, b in pairs])
    L += _table(["camera", "renderer", "LOD draws", "PSNR dB", "SSIM", "FLIP", "coverage", "frame ms"], body)
    return L + ["Cells read *single level / LOD*.", ""]


def section_timing(v: _View) -> list[str]:
    """How steady the frame times were, per renderer, and the load while measuring."""
    t = timing_summary(v.rows)
    if not t:
        return []
    L = [
        "## Frame-time spread",
        "",
        "Per configuration the frame time reported is the median of its timed frames; the spread "
        "is (slowest - fastest) / median of those frames (`frame_min_s`, `frame_max_s` in the CSV). "
        f"Over {t['rows']} measured rows: median spread {_pct(t['spread_median'])}, 90th percentile "
        f"{_pct(t['spread_p90'])}, largest {_pct(t['spread_max'])}.",
        "",
    ]
    body = [[name, str(p["rows"]), _fmt(p["frame_ms_median"], ".1f"), _pct(p["spread_median"])]
            for name, p in t["per_renderer"].items()]  # fmt: skip
    return L + _table(["renderer", "rows", "median frame ms", "median spread"], body)


def _recommend_renderers(v: _View) -> list[str]:
    """Per grid camera: the most accurate renderer, the one for accuracy and the one for speed."""
    by_distance = renderer_by_distance(v.rows)
    if not by_distance:
        return []

    def cell(r: dict | None, bold: bool = False) -> str:
        if r is None:
            return "-"
        name = f"**{r['renderer']}**" if bold else r["renderer"]
        return f"{name} ({_fmt(r['error'], '.4f')}, {_fmt(cost(r), '.0f', 1e3)} ms)"

    body = [[f"`{d['camera']}`", f"{d['voxel_px']:.2f}", cell(d["best"]), cell(d["pick"], True),
             cell(d["beats_1spp"], True)] for d in by_distance]  # fmt: skip
    return [
        f"**Renderer by distance** (grid block, CPU milliseconds per frame): per camera, the most accurate "
        f"renderer; the cheapest whose {v.err} is within 10% of it (the recommendation for accuracy); and "
        "the cheapest that is more accurate than one-sample polygons (for speed).",
        "",
    ] + _table(["camera", "voxel px", f"most accurate ({v.err}, CPU)", "for accuracy", "for speed"], body)


def _best_per_camera(v: _View, rec: dict) -> str:
    """' (best at `fill`: 256, at `1px`: 128)' when the cameras disagree, else ''."""
    field = AXES[rec["axis"]]
    sel = [r for r in measured(v.rows) if in_block(r, rec["axis"]) and r["method"] == rec["renderer"]]
    best = {}
    for cam in dict.fromkeys(r["camera"] for r in sel):
        best[cam] = min((r for r in sel if r["camera"] == cam), key=lambda r: r["error"])[field]
    if len(set(best.values())) < 2:
        return ""
    return " (best at " + ", at ".join(f"`{c}`: {x}" for c, x in best.items()) + ")"


def _recommend_settings(v: _View) -> list[str]:
    """Each setting's recommended value, and how that compares with the baseline."""
    err, base = v.err, v.meta["settings"]["baseline"]
    rec = recommend(v.rows)
    if not rec:
        return []
    body = []
    for r in rec:
        values = "; ".join(f"{k}: {_fmt(e, '.4f')}, {_fmt(t, '.0f', 1e3)} ms" for k, (e, t, _) in r["table"].items())
        body.append([r["axis"], r["renderer"], f"**{r['value']}**", str(r["best"]), values, r["why"]])
    L = [
        f"**Settings**, per renderer from the one-axis blocks: the value with the lowest mean {err} over the "
        "near and far cameras, unless a value within 1% of that error needs at least 5% fewer bytes or 10% "
        "less CPU time per frame (CPU time rather than wall time, as it hardly depends on other load).",
        "",
    ] + _table(["setting", "renderer", "recommended", "most accurate", f"mean {err}, CPU per frame", "why"], body)

    def entry(r: dict) -> str:
        e_p, e_b = r["table"][r["value"]][0], r["table"].get(base[r["axis"]], (math.nan,))[0]
        return (f"{r['axis']} for {r['renderer']}: {base[r['axis']]} -> {r['value']} "
                f"(mean {err} {_fmt(e_b, '.4f')} -> {_fmt(e_p, '.4f')}){_best_per_camera(v, r)}")  # fmt: skip

    change, keep = default_changes(rec, base)
    if change:
        L += ["Against this run's baseline, the data says to change: " + "; ".join(entry(r) for r in change)
              + ". The bench does not change defaults by itself.", ""]  # fmt: skip
    if keep:
        L += ["Recommended values that differ from the baseline but do not beat it by more than 1% in "
              "error, 5% in bytes or 10% in CPU time, so the baseline may stay: "
              + "; ".join(entry(r) for r in keep) + ".", ""]  # fmt: skip
    if not change:
        L += ["The data gives no reason to change any of this run's baseline settings.", ""]
    return L


def section_recommendation(v: _View) -> list[str]:
    """The renderer per distance and each setting's value, both computed from
    the rows, and which of the baseline's values the data would change."""
    return ["## Recommended configuration", ""] + _recommend_renderers(v) + _recommend_settings(v)


def section_not_measured(v: _View) -> list[str]:
    bad = [r for r in v.rows if r["status"] != "ok"]
    L: list[str] = []
    if bad:
        L += ["## Not measured", ""]
        reasons: dict[tuple[str, str], int] = {}
        for r in bad:
            reasons[(r["status"], r["reason"])] = reasons.get((r["status"], r["reason"]), 0) + 1
        L += [f"- {n} row(s) {status}: {reason}" for (status, reason), n in reasons.items()] + [""]
    return L + ["Every row is in `results.csv` and `results.json`.", ""]


SECTIONS = (
    section_run,
    section_setup,
    section_data_size,
    section_distance,
    section_aliasing,
    section_pareto,
    section_axes,
    section_lod,
    section_timing,
    section_recommendation,
    section_not_measured,
)


def make_report(result: BenchResult, plots: list[str], notes: list[str]) -> str:
    """The Markdown report: the run, setup, figures, tables and a reading
    generated from the numbers; ``plots`` are the figure files written beside
    it, ``notes`` go in a quote block after the setup."""
    cams = result.meta["cameras"]
    near = next(c for c in cams if c["role"] == "near")
    far = next((c for c in cams if c["role"] == "far"), near)
    view = _View(result, error_name(result.meta), cams, near, far, tuple(plots))
    L: list[str] = []
    for section in SECTIONS:
        L += section(view)
        if section is section_setup and notes:
            L += [f"> {n}" for n in notes] + [""]
    return "\n".join(L)
