"""How spread the scenes' mean normals are: what version 5's coarser steps for spread normals apply to.

Per scene, built at ``--resolution`` with K = ``--directions``: the share of
entries whose normal-length code (6 bits of ``sqrt(1 - c)``,
``aniso3d.build.encoding._encode_spread``) is 2 exactly, at least 2 and at
least 9, the mean number of bits the file's direction and depth codes drop
(``normal_shifts``, ``depth_shifts``, as the encoder writes them), the
layouts it keeps, and how many distinct kd colours the mesh has. Scenes are
names of ``aniso3d.build.scenes.SCENES`` or ``tree8`` (``scenes.tree(levels=8)``).

    .venv/bin/python demos/spread_codes.py [tree tree8 shell ...] [--resolution 128]
"""

from __future__ import annotations

import argparse

import numpy as np

from aniso3d.build import scenes
from aniso3d.build.encoding import ARRAYS, DEFAULT_BITS, _encode_spread, encode
from aniso3d.build.texture import build_texture

DEFAULT_SCENES = ("tree", "tree8", "bush", "grass", "lattice", "fur", "shell", "blob", "room", "mixed", "sphere")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(DEFAULT_SCENES))
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--directions", type=int, default=16)
    args = ap.parse_args()
    print("| scene | entries | code 2 | code >= 2 | code >= 9 | direction bits dropped | depth bits dropped "
          "| centroid layout | area order | mesh kd colours |")
    print("|---|---:|---:|---:|---:|---:|---:|---|---|---:|")
    for name in args.scenes:
        mesh = scenes.tree(levels=8) if name == "tree8" else scenes.SCENES[name]()
        tex = build_texture(mesh, args.resolution, args.directions)
        length = np.linalg.norm(np.asarray(tex.entry_normal, dtype=np.float64), axis=1)
        q = _encode_spread(np.minimum(length, 1.0), DEFAULT_BITS.coherence)[0]
        _, params = encode({n: getattr(tex, n) for n in ARRAYS}, tex.voxel_size)
        shift = np.asarray(params["normal_shifts"])[q]
        dshift = np.asarray(params["depth_shifts"])[q]
        colours = len(np.unique(np.asarray(mesh.kd).reshape(-1, 3), axis=0))
        print(f"| {name} | {tex.n_entries:,} | {np.mean(q == 2):.1%} | {np.mean(q >= 2):.1%} | {np.mean(q >= 9):.1%} "
              f"| {shift.mean():.2f} | {dshift.mean():.2f} | {params['centroid_layout']} | {params['area_order']} "
              f"| {colours:,} |", flush=True)


if __name__ == "__main__":
    main()
