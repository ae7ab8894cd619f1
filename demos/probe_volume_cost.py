"""Where the volume's frame goes: process CPU time of the default volume
frame against variants of volume.frag / lighting.glsl that leave out or
change one part (the images differ; only the time is read), interleaved.

The variants are text patches applied to the shader sources as they are
loaded (aniso3d.rendering.shader_source.preprocess's loader), so each one is
the committed shader minus that part:

- ``no_shading``: an entry's colour is its kd (no shade());
- ``no_pow``: the specular lobe's pow() replaced by 1 (shade() without it);
- ``exp2_pow``: pow(rv, s) written exp2(s log2 rv);
- ``no_entries``: composite() skips the loop over the voxel's entries;
- ``first_hit``: a ray stops at its first occupied voxel (set-up, misses
  and the walk to the first hit);
- ``set_up``: every ray stops after its set-up (box clip, neighbours());
- ``lazy_neighbours``: neighbours() called at a ray's first composite, not
  before its walk (rays that hit nothing skip it);
- ``t_min_0.01``, ``t_min_0.02``: rays stop at a higher transmittance (the
  image changes by up to that much).

Frames are drawn with start="box" (rays from the grid's box, one program at
every camera).

CPU time (time.process_time: this process, every llvmpipe thread) is steadier
than wall time on a shared machine. Prints a Markdown table: median
(min-max) ms over --frames frames, and the share of the default frame.

    .venv/bin/python demos/probe_volume_cost.py [--scene tree] [--size 1024]
        [--cameras fill,1px] [--frames 5]
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

import numpy as np

import aniso3d
from aniso3d.bench.cameras import make_cameras
from aniso3d.bench.settings import PRESETS
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.renderer import Renderer
from aniso3d.rendering.shader_source import preprocess, read_shader
from aniso3d.rendering.volume import VolumeOptions

#: name -> {shader file: [(text, replacement), ...], "defines": {name: value}}
PATCHES: dict[str, dict] = {
    "default": {},
    "no_shading": {
        "volume.frag": [
            (
                "vec3 c = clamp(shade(ns, view, vec3(kd_rg, kd_b_ks.x), kd_b_ks.y, shininess, length(n)), 0.0, 1.0);",
                "vec3 c = vec3(kd_rg, kd_b_ks.x);",
            )
        ]
    },
    "no_pow": {"lighting.glsl": [("(s > 0.0 ? pow(rv, s) : 1.0)", "1.0")]},
    "exp2_pow": {"lighting.glsl": [("(s > 0.0 ? pow(rv, s) : 1.0)", "(s > 0.0 ? exp2(s * log2(rv)) : 1.0)")]},
    "no_entries": {
        "volume.frag": [
            (
                "    for (uint e = e0; e < e1; ++e) {",
                "    col_a = vec3(0.5);\n    sum_a = 1.0;\n    for (uint e = e0; e < e0; ++e) {",
            )
        ]
    },
    "first_hit": {
        "volume.frag": [
            (
                "void composite(int v, vec3 x_in, float t0, float chord) {\n",
                "void composite(int v, vec3 x_in, float t0, float chord) {\n"
                "    g_color = vec3(0.5);\n    g_trans = 0.0;\n    return;\n",
            )
        ]
    },
    "set_up": {
        "volume.frag": [
            (
                "    neighbours(g_d);\n",
                "    neighbours(g_d);\n    f_color = vec4(g_nbw);\n    gl_FragDepth = 1.0;\n    return;\n",
            )
        ]
    },
    "lazy_neighbours": {
        "volume.frag": [
            ("    neighbours(g_d);\n    g_color = vec3(0.0);", "    bool nb_ready = false;\n    g_color = vec3(0.0);"),
            (
                "        if (v >= 0) composite(v, o + g_d * tv - vec3(vcell), tv, chord);",
                "        if (v >= 0) {\n            if (!nb_ready) {\n                neighbours(g_d);\n"
                "                nb_ready = true;\n            }\n"
                "            composite(v, o + g_d * tv - vec3(vcell), tv, chord);\n        }",
            ),
        ]
    },
    "t_min_0.01": {"defines": {"T_MIN": 0.01}},
    "t_min_0.02": {"defines": {"T_MIN": 0.02}},
}


def patched_loader(patches: dict):
    def load(name: str) -> str:
        src = read_shader(name)
        for old, new in patches.get(name, []):
            if old not in src:
                raise SystemExit(f"patch target not found in {name}: {old[:60]!r} (the shader changed)")
            src = src.replace(old, new)
        return src

    return load


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="tree")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--cameras", default="fill,1px")
    ap.add_argument("--frames", type=int, default=5)
    args = ap.parse_args()
    mesh = aniso3d.scenes.get_scene(args.scene)
    tex = aniso3d.build_texture(mesh)
    settings = replace(PRESETS["full"], size=(args.size, args.size))
    load0 = os.getloadavg()
    print(f"{args.scene} at {args.size}^2, load before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    with Renderer((args.size, args.size)) as r:
        impl = r.method_renderer("volume")
        # The default program without the start pass (the frames below draw
        # start="box", so that every camera draws this program).
        made = impl._program("skip", VolumeOptions())
        key = next(k for k, v in impl._variants.items() if v is made)
        base = {**impl._defines, **impl._mode_defines(VolumeOptions())}
        ctx = impl.gl.ctx
        progs = {}
        for name, patches in PATCHES.items():
            load = patched_loader(patches)
            defines = {**base, **patches.get("defines", {})}
            prog = ctx.program(
                vertex_shader=preprocess("volume.vert", defines, load),
                fragment_shader=preprocess("volume.frag", defines, load),
            )
            progs[name] = (prog, ctx.vertex_array(prog, []))
        # Uniforms a variant compiles out are then set leniently.
        strict = GLContext.set_uniforms
        GLContext.set_uniforms = staticmethod(lambda p, v, strict_=True, **kw: strict(p, v, strict=False))
        print("| camera | " + " | ".join(progs) + " |")
        print("|---|" + "---|" * len(progs))
        for spec in make_cameras(mesh.bounds, settings):
            if spec.label not in args.cameras.split(","):
                continue
            cpu: dict[str, list[float]] = {name: [] for name in progs}
            for name in progs:  # warm-up
                impl._variants[key] = progs[name]
                r.render(tex, spec.camera, "volume", start="box")
            for _ in range(args.frames):
                for name in progs:
                    impl._variants[key] = progs[name]
                    c0 = time.process_time()
                    r.render(tex, spec.camera, "volume", start="box")
                    cpu[name].append(1000 * (time.process_time() - c0))
            base = float(np.median(cpu["default"]))
            cells = [f"{np.median(v):.0f} ({min(v):.0f}-{max(v):.0f}), {np.median(v) / base:.2f}" for v in cpu.values()]
            print(f"| {spec.label} | " + " | ".join(cells) + " |", flush=True)
        GLContext.set_uniforms = strict
    load1 = os.getloadavg()
    print(f"load after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")


if __name__ == "__main__":
    main()
