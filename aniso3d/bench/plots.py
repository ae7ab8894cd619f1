"""The report's figures as PNG bytes (matplotlib, optional: ``aniso3d[plots]``).

Each ``plot_*`` takes a :class:`~aniso3d.bench.run.BenchResult` and draws on a
figure of its own (the Agg canvas, no display, no global pyplot state).
"""

from __future__ import annotations

import io
import math

from aniso3d.bench.analyse import error_name, finite, in_block, label, measured
from aniso3d.bench.run import BenchResult
from aniso3d.bench.settings import RENDERERS

COLOURS = {
    "mesh-1spp": "#d62728",
    "mesh-2x2": "#ff7f0e",
    "mesh-4x4": "#8c564b",
    "volume": "#1f77b4",
    "splat": "#2ca02c",
}
PLOTS = ("pareto.png", "distance.png", "bytes.png", "montage.png")


def matplotlib_available() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _figure(w: float, h: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _plain_log_ticks(axis) -> None:
    """Log-scale ticks labelled 20, 50, 100 rather than 2x10^1."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def plot_pareto(result: BenchResult) -> bytes:
    """Error vs frame time at the near and far cameras, Pareto front joined."""
    cams = [c for c in result.meta["cameras"] if c["role"]]
    fig = _figure(6.5 * len(cams), 5.0)
    axes = fig.subplots(1, len(cams), squeeze=False)[0]
    for ax, cam in zip(axes, cams, strict=True):
        group = [r for r in measured(result.rows) if r["camera"] == cam["label"]]
        for name in RENDERERS:
            sel = [r for r in group if r["renderer"] == name]
            if sel:
                ax.scatter([1e3 * r["frame_s"] for r in sel], [r["error"] for r in sel], s=22,
                           color=COLOURS.get(name), label=name, alpha=0.8)  # fmt: skip
        front = sorted((r for r in group if r["pareto"]), key=lambda r: r["frame_s"])
        if front:
            ax.step([1e3 * r["frame_s"] for r in front], [r["error"] for r in front], where="post",
                    color="k", lw=1, label="Pareto front")  # fmt: skip
            for i, r in enumerate(front):
                ax.annotate(label(r), (1e3 * r["frame_s"], r["error"]), fontsize=6,
                            xytext=(3, 3 if i % 2 == 0 else -8), textcoords="offset points")  # fmt: skip
        ax.set_xscale("log")
        _plain_log_ticks(ax.xaxis)
        ax.set_xlabel("frame time, ms (draw + read back)")
        ax.set_ylabel(f"error: {error_name(result.meta)} (lower is better)")
        ax.set_title(f"{cam['role']} camera ({cam['label']}: baseline voxel {cam['voxel_px']:.2g} px)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return _png(fig)


def plot_distance(result: BenchResult) -> bytes:
    """Grid block: each metric and the frame time vs camera distance, per renderer."""
    grid = [r for r in measured(result.rows) if in_block(r, "grid")]
    panels = [("psnr", "PSNR, dB (higher is better)"), ("ssim", "SSIM (higher is better)")]
    if result.meta["flip"]:
        panels.append(("flip", "FLIP (lower is better)"))
    panels.append(("frame_s", "frame time, ms"))
    fig = _figure(4.2 * len(panels), 4.2)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (key, title) in zip(axes, panels, strict=True):
        for name in RENDERERS:
            sel = sorted((r for r in grid if r["renderer"] == name and finite(r.get(key))),
                         key=lambda r: r["distance_scale"])  # fmt: skip
            if sel:
                scale = 1e3 if key == "frame_s" else 1.0
                ax.plot([r["camera_voxel_px"] for r in sel], [scale * r[key] for r in sel], "o-",
                        color=COLOURS.get(name), label=name, ms=4)  # fmt: skip
        ax.set_xscale("log")
        ticks = sorted({r["camera_voxel_px"] for r in grid})
        ax.set_xticks(ticks, [f"{t:.2g}" for t in ticks])
        ax.minorticks_off()
        ax.invert_xaxis()
        if key == "frame_s":
            ax.set_yscale("log")
            _plain_log_ticks(ax.yaxis)
        ax.axvline(1.0, color="grey", ls=":", lw=1)
        ax.set_xlabel("baseline voxel width, pixels (farther ->)")
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    return _png(fig)


def plot_bytes(result: BenchResult) -> bytes:
    """Texture and point bytes vs resolution, against the mesh's bytes."""
    rows = [r for r in result.rows if in_block(r, "resolution") and finite(r.get("texture_bytes"))]
    base = result.meta["settings"]["baseline"]
    fig = _figure(6.5, 4.5)
    ax = fig.subplots()
    res = sorted({r["resolution"] for r in rows})

    def series(key, method=None, **match):
        out = []
        for v in res:
            vals = [r[key] for r in rows if r["resolution"] == v and finite(r.get(key))
                    and (method is None or r["method"] == method)
                    and all(r.get(k) == x for k, x in match.items())]  # fmt: skip
            out.append(vals[0] if vals else math.nan)
        return out

    ax.axhline(result.meta["mesh_bytes"], color="k", ls="--", label=f"mesh ({result.meta['triangles']:,} triangles)")
    ax.plot(res, series("texture_bytes", directions=base["directions"]), "o-", color=COLOURS["volume"],
            label=f"texture, K={base['directions']}")  # fmt: skip
    ax.plot(res, series("points_bytes", "splat", per_entry=1), "s-", color=COLOURS["splat"],
            label="points, 1 per entry")  # fmt: skip
    krows = [r for r in result.rows if in_block(r, "directions") and finite(r.get("texture_bytes"))]
    for k in sorted({r["directions"] for r in krows} - {base["directions"]}):
        b = next(r["texture_bytes"] for r in krows if r["directions"] == k)
        ax.plot([base["resolution"]], [b], "^", color=COLOURS["volume"], alpha=0.6)
        ax.annotate(f"K={k}", (base["resolution"], b), fontsize=7, xytext=(4, 0), textcoords="offset points")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(res, [f"{v}^3" for v in res])
    ax.set_xlabel("resolution (voxels along the longest axis)")
    ax.set_ylabel("bytes")
    ax.set_title(f"data size: {result.meta['scene']}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def plot_montage(result: BenchResult) -> bytes:
    """The grid block's images at each camera, cropped, ground truth first."""
    cams = [c["label"] for c in result.meta["cameras"]]
    cols = ["ground truth"] + [n for n in RENDERERS if any(n in result.images[c] for c in cams)]
    fig = _figure(2.2 * len(cols), 2.3 * len(cams))
    axes = fig.subplots(len(cams), len(cols), squeeze=False)
    for i, cam in enumerate(cams):
        for j, name in enumerate(cols):
            ax = axes[i][j]
            ax.set_xticks([])
            ax.set_yticks([])
            img = result.images[cam].get(name)
            if img is not None:
                ax.imshow(img, interpolation="nearest")
            else:
                ax.text(0.5, 0.5, "skipped", ha="center", va="center", transform=ax.transAxes)
            if i == 0:
                ax.set_title(name, fontsize=9)
            if j == 0:
                ax.set_ylabel(cam, fontsize=9)
    return _png(fig)


#: Each figure's file name and the function drawing it.
PLOTTERS = {
    "pareto.png": plot_pareto,
    "distance.png": plot_distance,
    "bytes.png": plot_bytes,
    "montage.png": plot_montage,
}
