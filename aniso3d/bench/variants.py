"""What the corpus demos share: each draws variants of one renderer (a rule on
or off, a parameter swept) on every corpus scene at the corpus bench's two
cameras and scores them as the bench does, beside the polygons at one sample
and at 2 x 2 (the targets' baselines), then writes one Markdown table between
markers of a file in ``docs/``.

The demo keeps what is its own (its variants, its columns, its caption); the
arguments, the truth and baselines, the scores, the per-camera line and the
block's frame come from here, so that every demo measures the same way.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from aniso3d import metrics
from aniso3d.bench.cameras import CameraSpec
from aniso3d.bench.corpus import corpus_cameras
from aniso3d.bench.outputs import write_between_markers
from aniso3d.bench.run import ScenesRun, run_scenes
from aniso3d.build.mesh import Mesh, load_mesh
from aniso3d.build.scenes import get_scene
from aniso3d.build.texture import build_texture
from aniso3d.rendering.renderer import Renderer

#: The polygon baselines every row carries: label -> samples per pixel side.
POLYGON_BASELINES = {"1 spp": 1, "2x2": 2}

Score = tuple[float, float]  # (PSNR dB, FLIP)


def corpus_parser(description: str, scenes: Iterable[str], frames: int | None = None) -> argparse.ArgumentParser:
    """The demos' common arguments: scenes, ``--size``, ``--gt-ssaa``,
    ``--resolution``, ``--directions``, ``--md`` (and ``--frames`` with its
    default when the demo times frames)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("scenes", nargs="*", default=list(scenes))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--gt-ssaa", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    if frames is not None:
        ap.add_argument("--frames", type=int, default=frames)
    ap.add_argument("--md", default="", help="Markdown file to write the table into (between its markers)")
    return ap


def run_corpus_demo(args: argparse.Namespace, run_scene: Callable) -> ScenesRun:
    """``run_scene(name, args, renderer)`` on every scene of ``args.scenes``."""
    return run_scenes(args.scenes, args.size, lambda name, renderer: run_scene(name, args, renderer))


def scored(truth: np.ndarray, img: np.ndarray, spec: CameraSpec) -> Score:
    """PSNR and FLIP of ``img`` against ``truth`` inside the object's box, as the corpus bench scores."""
    m = metrics.compare_in_box(truth, img, spec.crop, with_flip=True)
    return m["psnr"], m["flip"]


def scene_or_mesh(name: str) -> tuple[Mesh, str]:
    """A demo's scene argument: a mesh file (by its suffix) or a built-in
    scene's name; the mesh and the label its rows carry (the file's name)."""
    path = Path(name)
    if path.suffix:
        return load_mesh(name), path.name
    return get_scene(name), name


def scene_cameras(renderer: Renderer, mesh: Mesh, name: str, args: argparse.Namespace):
    """Per corpus camera of ``mesh``: ``(spec, truth, row)``, the truth the
    polygons at ``args.gt_ssaa`` squared samples, the row holding the scene,
    the camera's label and the :data:`POLYGON_BASELINES`' scores."""
    for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
        truth = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa)
        row: dict = {"scene": name, "camera": spec.label}
        for label, ssaa in POLYGON_BASELINES.items():
            row[label] = scored(truth, renderer.render(mesh, spec.camera, "mesh", ssaa=ssaa), spec)
        yield spec, truth, row


def volume_mode_rows(
    name: str, args: argparse.Namespace, renderer: Renderer, option: str, modes: tuple[str, str], what: str,
    region: Callable[[np.ndarray], np.ndarray], error: Callable[[np.ndarray, np.ndarray, np.ndarray], float],
    digits: int = 3,
) -> list[dict]:  # fmt: skip
    """Scene ``name`` at the default texture of ``args`` drawn by the volume
    renderer with ``option`` set to each of ``modes`` (the one measured
    against first), at the corpus cameras, scored against the polygons at
    ``args.gt_ssaa`` squared samples inside the object's box. Per camera a
    row: the scene, camera, ``voxel_px``, ``{what}_px`` (the pixels of the
    box ``region(truth)`` marks) and per mode ``psnr``, ``flip``,
    ``{what}_err`` (``error(image, truth, mask)``, both RGBA in the box) and
    the frame ``times`` of ``args.frames`` frames, the modes drawn in turn
    so that both see the same load."""
    mesh = get_scene(name)
    tex = build_texture(mesh, args.resolution, args.directions)
    rows = []
    for spec in corpus_cameras(mesh, (args.size, args.size), args.resolution):
        x0, y0, x1, y1 = spec.crop
        ref = renderer.render(mesh, spec.camera, "mesh", ssaa=args.gt_ssaa, alpha=True)[y0:y1, x0:x1]
        mask = region(ref)
        row = {"scene": name, "camera": spec.label, "voxel_px": spec.voxel_px, f"{what}_px": int(mask.sum())}
        for mode in modes:
            img = renderer.render(tex, spec.camera, "volume", alpha=True, **{option: mode})[y0:y1, x0:x1]
            m = metrics.compare(ref[..., :3], img[..., :3], with_flip=True)
            row[mode] = {"psnr": m["psnr"], "flip": m["flip"], f"{what}_err": error(img, ref, mask), "times": []}
        for _ in range(args.frames):
            for mode in modes:
                renderer.render(tex, spec.camera, "volume", **{option: mode})
                row[mode]["times"].append(renderer.last_frame_seconds)
        rows.append(row)
        o, n = row[modes[0]], row[modes[1]]
        e = f"{what}_err"
        print(f"  {spec.label}: PSNR {o['psnr']:.2f} -> {n['psnr']:.2f}, FLIP {o['flip']:.4f} -> "
              f"{n['flip']:.4f}, {what} err {o[e]:.{digits}f} -> {n[e]:.{digits}f}", flush=True)  # fmt: skip
    return rows


def print_scores(label: str, row: dict) -> None:
    """One camera's line: every score of the row, ``name psnr/flip``."""
    print(f"  {label}: " + ", ".join(f"{k} {v[0]:.2f}/{v[1]:.4f}" for k, v in row.items() if isinstance(v, tuple)),
          flush=True)  # fmt: skip


def _score(s: Score | dict) -> Score:
    return (s["psnr"], s["flip"]) if isinstance(s, dict) else s


def pair(score: Score | dict) -> str:
    """A table cell: ``PSNR / FLIP`` (a score, or a dict with those keys)."""
    psnr, flip = _score(score)
    return f"{psnr:.2f} / {flip:.4f}"


def delta(new: Score | dict, old: Score | dict) -> list[str]:
    """Two table cells: the change in PSNR and in FLIP."""
    (p1, f1), (p0, f0) = _score(new), _score(old)
    return [f"{p1 - p0:+.2f}", f"{f1 - f0:+.4f}"]


def as_good(score: Score, baseline: Score) -> str:
    """The cell "yes" where ``score`` is at least as good in PSNR and in FLIP, else "no"."""
    return "yes" if score[0] >= baseline[0] and score[1] <= baseline[1] else "no"


def ms(times: list[float]) -> str:
    """Frame times (s) as ``median [fastest-slowest]`` ms ("-": none timed)."""
    t = 1000 * np.asarray(times)
    return f"{np.median(t):.0f} [{t.min():.0f}-{t.max():.0f}]" if len(t) else "-"


def corpus_summary(rows: list[dict], new: str, old: str, cameras=("close", "minified")) -> list[list[str]]:
    """Per camera of ``cameras`` over the scenes, ``new`` against ``old``
    (their dicts hold ``psnr``, ``flip`` and frame ``times``): mean, worst
    and best change in PSNR, mean and worst in FLIP, and the frame time
    ratio's median [range] over the rows that were timed ("-": none)."""
    out = []
    for cam in cameras:
        at = [r for r in rows if r["camera"] == cam]
        if not at:
            continue
        d = [r[new]["psnr"] - r[old]["psnr"] for r in at]
        df = [r[new]["flip"] - r[old]["flip"] for r in at]
        tr = [np.median(r[new]["times"]) / np.median(r[old]["times"]) for r in at if r[new]["times"]]
        ratio = f"{np.median(tr):.2f} [{min(tr):.2f}-{max(tr):.2f}]" if tr else "-"
        out.append([cam, f"{np.mean(d):+.2f}", f"{min(d):+.2f}", f"{max(d):+.2f}", f"{np.mean(df):+.4f}",
                    f"{max(df):+.4f}", ratio])  # fmt: skip
    return out


#: The head of :func:`corpus_summary`'s table.
SUMMARY_HEAD = ["camera", "mean Δ PSNR", "worst", "best", "mean Δ FLIP", "worst Δ FLIP", "time ratio"]


def command(script: str, args: argparse.Namespace, *extra: str) -> str:
    """The command line a table states: the script, its scenes, its size and ``extra``."""
    return " ".join([script, *args.scenes, "--size", str(args.size), *extra])


def publish(parts: list[str], md: str, begin: str, end: str, title: str) -> None:
    """Print the block (``parts`` between the markers) and, with ``md``,
    write it between the markers of that file (created with ``title``)."""
    block = "\n".join([begin, *parts, end])
    print("\n" + block)
    if md:
        path = write_between_markers(md, block, begin, end, title=title)
        print(f"wrote {path}")
