"""Benchmark of the streaming build: the procedural tree at 7, 8 (and 9) levels
(1.05M, 4.2M, 16.8M triangles) -> a 128^3 texture, one pass against chunks.

    .venv/bin/python demos/bench_stream_build.py [--levels 7 8] [--budget 600M] [--repeat 1]

The tree is generated once per level in a subprocess and written to a binary
PLY (float32 vertices, face colours) in a scratch folder; every contender then
reads that file in a fresh subprocess:

- one pass: ``load_mesh`` (trimesh) + ``build_texture(mesh, chunk_size=all)``,
  the build as it was before streaming (whole mesh, one chunk);
- chunked, 1 or 2 local workers: ``build_texture(path, workers=w,
  memory_budget=--budget)`` (the file read in chunks; 2 workers: a 'spawn'
  process pool);
- Dask, 1 or 2 workers: the same on a ``LocalCluster`` of w worker processes
  of one thread (:func:`aniso3d.build.stream.local_cluster`) made in the
  subprocess (its start-up is timed apart, not in the build time).

Time is the wall time of the build call (load included for the one pass);
CPU is the user + system seconds of the contender's process and every child
process (pool workers, Dask nannies and workers; Dask's start-up included):
on a shared machine the wall time depends on the other jobs, the CPU time
much less.
Peak memory is the largest sum of the resident set sizes of the contender's
process and all its descendants (pool workers, Dask nanny and worker
processes), sampled every 20 ms with psutil: shared pages (the Python
runtime, numpy) count once per process, so it overstates a little. Every
contender's texture is checked equal, bit for bit, to the one-pass texture.
The machine's load average is printed: the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

CONTENDERS = ("one pass", "chunked, 1 worker", "chunked, 2 workers", "Dask, 1 worker", "Dask, 2 workers")


def write_tree(levels: int, path: Path) -> int:
    """Write scenes.tree(levels) as a binary PLY with face colours; its face count."""
    import numpy as np

    from aniso3d.build import scenes

    m = scenes.tree(levels=levels)
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(m.vertices)}\nproperty float x\n"
        f"property float y\nproperty float z\nelement face {m.n_faces}\nproperty list uchar int vertex_indices\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    ).encode()
    rec = np.zeros(m.n_faces, dtype=[("n", "u1"), ("i", "<i4", 3), ("rgb", "u1", 3)])
    rec["n"] = 3
    rec["i"] = m.faces
    rec["rgb"] = np.round(m.kd * 255)
    with open(path, "wb") as fh:
        fh.write(head)
        fh.write(m.vertices.astype("<f4").tobytes())
        fh.write(rec.tobytes())
    return m.n_faces


def contender(name: str, path: str, budget: int, out: str) -> dict:
    """Run one contender in this process; save its texture to ``out``."""
    import resource

    from aniso3d.build.mesh import load_mesh
    from aniso3d.build.texture import build_texture

    stats: dict = {}
    timings: dict = {}
    res: dict = {"name": name}
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    workers = 2 if "2 workers" in name else 1
    if name == "one pass":
        t0 = time.perf_counter()
        mesh = load_mesh(path)
        tex = build_texture(mesh, 128, 16, chunk_size=mesh.n_faces, timings=timings, stats=stats)
        res["seconds"] = time.perf_counter() - t0
        del mesh
    elif name.startswith("chunked"):
        t0 = time.perf_counter()
        tex = build_texture(path, 128, 16, workers=workers, memory_budget=budget, timings=timings, stats=stats)
        res["seconds"] = time.perf_counter() - t0
    else:
        from distributed import Client

        from aniso3d.build.stream import local_cluster

        t0 = time.perf_counter()
        with local_cluster(workers) as c:
            with Client(c) as client:
                res["cluster_start_s"] = time.perf_counter() - t0
                t0 = time.perf_counter()
                tex = build_texture(path, 128, 16, client=client, memory_budget=budget, timings=timings, stats=stats)
                res["seconds"] = time.perf_counter() - t0
    # CPU seconds of this process and every child it waited for (pool
    # workers, Dask nannies and their workers), start-up included
    cpu = [resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)]
    res["cpu_s"] = sum(r.ru_utime + r.ru_stime for r in cpu) - cpu0.ru_utime - cpu0.ru_stime
    res.update(chunks=stats["chunks"], chunk_size=stats["chunk_size"], triangles=tex.meta["n_triangles"],
               entries=tex.n_entries, timings={k: round(v, 2) for k, v in timings.items()})  # fmt: skip
    tex.save(out)
    return res


def tree_rss(pid: int) -> int:
    import psutil

    try:
        p = psutil.Process(pid)
        procs = [p] + p.children(recursive=True)
    except psutil.NoSuchProcess:
        return 0
    total = 0
    for q in procs:
        try:
            total += q.memory_info().rss
        except psutil.NoSuchProcess:
            pass
    return total


def measure(argv: list[str]) -> tuple[dict, float]:
    """Run a contender subprocess; (its result, peak RSS of its process tree in bytes)."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True)
    peak = [0]
    done = threading.Event()

    def sample():
        while not done.is_set():
            peak[0] = max(peak[0], tree_rss(proc.pid))
            done.wait(0.02)

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    out, _ = proc.communicate()
    done.set()
    t.join()
    if proc.returncode != 0:
        raise RuntimeError(f"{argv} failed with status {proc.returncode}")
    return json.loads(out.strip().splitlines()[-1]), peak[0]


def same(a: str, b: str) -> bool:
    import numpy as np

    from aniso3d.build.texture import AnisoTexture

    x, y = AnisoTexture.load(a), AnisoTexture.load(b)
    return all(np.array_equal(getattr(x, n), getattr(y, n)) for n in AnisoTexture._ARRAYS) and x.meta == y.meta


def parse_size(text: str) -> int:
    scale = {"K": 2**10, "M": 2**20, "G": 2**30}.get(text[-1:].upper(), 1)
    return int(float(text[:-1] if scale > 1 else text) * scale)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[7, 8])
    ap.add_argument("--budget", default="600M", help="memory budget of the chunked and Dask builds")
    ap.add_argument("--contenders", nargs="+", default=list(CONTENDERS))
    ap.add_argument("--repeat", type=int, default=1, help="runs per contender (median time, max peak)")
    ap.add_argument("--no-check", dest="check", action="store_false",
                    help="do not compare the textures (when the one-pass build is not among the contenders)")
    ap.add_argument("--scratch", default=None, help="folder for the tree files (default: a temporary one)")
    ap.add_argument("--contender", nargs=4, metavar=("NAME", "PATH", "BUDGET", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.contender:
        name, path, budget, out = args.contender
        print(json.dumps(contender(name, path, int(budget), out)))
        return
    import statistics

    budget = parse_size(args.budget)
    scratch = Path(args.scratch or tempfile.mkdtemp(prefix="aniso3d-bench-"))
    scratch.mkdir(parents=True, exist_ok=True)
    print(f"# load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} cores")
    print(f"# memory budget of the chunked builds: {budget / 2**20:.0f} MiB")
    rows = []
    for levels in args.levels:
        path = scratch / f"tree{levels}.ply"
        if not path.exists():
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
                            f"import bench_stream_build as b; b.write_tree({levels}, {str(path)!r})"], check=True)
            print(f"# wrote {path} ({path.stat().st_size / 2**20:.0f} MiB) in {time.perf_counter() - t0:.1f} s")
        reference = None
        for name in args.contenders:
            times, peaks = [], []
            for _ in range(args.repeat):
                out = scratch / f"tree{levels}-{name.replace(' ', '_').replace(',', '')}.a3d"
                res, peak = measure([sys.executable, __file__, "--contender", name, str(path), str(budget), str(out)])
                times.append(res["seconds"])
                peaks.append(peak)
            reference = reference or out
            ok = same(reference, out) if args.check else None
            row = dict(res, levels=levels, seconds=statistics.median(times), peak_mib=max(peaks) / 2**20, equal=ok,
                       load=os.getloadavg()[0])  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print()
    print("| tree | triangles | contender | chunks | wall (s) | CPU (s) | peak RSS (MiB) | equal to one pass "
          "| load (1 min) |")
    print("|---|---:|---|---:|---:|---:|---:|---|---:|")
    for r in rows:
        equal = {True: "yes", False: "NO", None: "-"}[r["equal"]]
        print(f"| levels={r['levels']} | {r['triangles']:,} | {r['name']} | {r['chunks']} | {r['seconds']:.1f} | "
              f"{r['cpu_s']:.0f} | {r['peak_mib']:.0f} | {equal} | {r['load']:.1f} |")


if __name__ == "__main__":
    main()
