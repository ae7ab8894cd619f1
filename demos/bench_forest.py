"""Frame time of a forest against its number of trees, per method, and the
error of splats and volume against 8x8-supersampled polygons: the same as
``aniso3d bench forest -o docs`` (:mod:`aniso3d.bench.forest`), kept as the
script docs/forest.md names. Writes forest.md and forest.png into --out.

    ./.venv/bin/python demos/bench_forest.py [--size 512] [--reps 3] [--counts 100 10000] [--out docs]
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from aniso3d.bench.forest import COUNTS, ForestSettings, run_forest, write_report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--error-size", type=int, default=256)
    ap.add_argument("--out", default="docs")
    ap.add_argument("--counts", type=int, nargs="+", default=list(COUNTS))
    ap.add_argument("--no-passes", action="store_true", help="leave out the volume drawn one pass per instance")
    args = ap.parse_args()
    settings = ForestSettings(size=args.size, reps=args.reps, error_size=args.error_size,
                              counts=tuple(args.counts), no_passes=args.no_passes)  # fmt: skip
    rows, errors, load = run_forest(settings, progress=lambda f, what: print(f"{f:4.0%} {what}", flush=True))
    command = "demos/bench_forest.py " + shlex.join(sys.argv[1:])
    print(f"wrote {write_report(rows, errors, load, settings, Path(args.out), command)}")


if __name__ == "__main__":
    main()
