"""One renderer interface: the three renderers implement the protocol, their
options are frozen dataclasses checked on construction, front ends build
them, and the splat shaders share one SplatData declaration."""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re

import numpy as np
import pytest

import aniso3d
from aniso3d import InputError
from aniso3d.rendering.base import DrawOptions, MethodRenderer
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.polygon import MeshOptions, MeshRenderer
from aniso3d.rendering.renderer import BuildOptions
from aniso3d.rendering.shader_source import preprocess, shader_dir
from aniso3d.rendering.splat import SplatOptions, SplatRenderer, default_size_factor
from aniso3d.rendering.volume import VolumeOptions, VolumeRenderer

RENDERERS = {"mesh": MeshRenderer, "volume": VolumeRenderer, "splat": SplatRenderer}
OPTIONS = {"mesh": MeshOptions, "volume": VolumeOptions, "splat": SplatOptions}


# -------------------------------------------------------------- no GPU


@pytest.mark.parametrize("method", sorted(RENDERERS))
def test_each_renderer_declares_its_options_as_a_frozen_dataclass(method):
    cls = RENDERERS[method]
    assert cls.method == method and cls.Options is OPTIONS[method]
    assert issubclass(cls.Options, DrawOptions) and dataclasses.is_dataclass(cls.Options)
    opts = cls.Options()
    names = cls.Options.names()
    if names:
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(opts, names[0], None)
    # ``options`` parses keywords and shows the fields as its parameters.
    assert cls.options() == opts
    assert tuple(inspect.signature(cls.options).parameters) == names
    with pytest.raises(InputError, match=rf"unknown {method} option\(s\) \['colour'\]"):
        cls.Options.parse(colour="red")


def test_option_names_are_what_front_ends_read():
    assert SplatOptions.names() == ("splat", "quality", "size_factor", "aspect", "push", "pixel_error")
    assert VolumeOptions.names() == (
        "step", "density", "normal", "shading", "opacity", "pixel_error", "march", "edges", "start", "back_hide"
    )
    assert MeshOptions.names() == ()
    assert "quality" in SplatOptions.names() and "quality" not in VolumeOptions.names()


@pytest.mark.parametrize(
    "cls, kwargs, text",
    [
        (SplatOptions, {"splat": "hexagon"}, "hexagon"),
        (SplatOptions, {"pixel_error": 0.0}, "pixel_error"),
        (SplatOptions, {"pixel_error": float("inf")}, "pixel_error"),
        (SplatOptions, {"push": "far"}, "push"),
        (VolumeOptions, {"opacity": "max"}, "'max'"),
        (VolumeOptions, {"density": 3}, "density"),
        (VolumeOptions, {"shading": "phong"}, "'phong'"),
        (VolumeOptions, {"pixel_error": -1.0}, "pixel_error"),
        (VolumeOptions, {"back_hide": 1.5}, "back_hide"),
        (VolumeOptions, {"back_hide": -0.1}, "back_hide"),
        (VolumeOptions, {"back_hide": "half"}, "back_hide"),
        (BuildOptions, {"resolution": 0}, "resolution"),
        (BuildOptions, {"resolution": 2.5}, "resolution"),
        (BuildOptions, {"directions": True}, "directions"),
        (BuildOptions, {"placement": "top"}, "placement"),
        (BuildOptions, {"per_entry": "some"}, "per_entry"),
        (BuildOptions, {"point_normal": "bent"}, "bent"),
        (BuildOptions, {"lod": "yes"}, "lod"),
    ],
)
def test_bad_options_are_one_clear_input_error(cls, kwargs, text):
    with pytest.raises(InputError, match=re.escape(text)):
        cls(**kwargs)


def test_options_fill_defaults_and_normalise():
    assert SplatOptions(splat="disc").size_factor == default_size_factor("disc")
    assert SplatOptions(splat="ellipse", aspect=3).aspect == 3.0
    b = BuildOptions(resolution=np.int64(32), per_entry=np.int32(2))
    assert type(b.resolution) is int and b.per_entry == 2 and b == BuildOptions(resolution=32, per_entry=2)
    assert BuildOptions.parse(resolution=None, lod=np.bool_(True)) == BuildOptions(lod=True)
    assert BuildOptions(per_entry="adaptive").per_entry == "adaptive"
    with pytest.raises(InputError, match="unknown build option"):
        BuildOptions.parse(quality="high")


def test_options_come_as_a_dataclass_or_as_keywords_not_both():
    assert SplatOptions.resolve(None, {"quality": "high"}) == SplatOptions(quality="high")
    opts = SplatOptions(quality="blend")
    assert SplatOptions.resolve(opts, {}) is opts
    with pytest.raises(InputError, match="not both"):
        SplatOptions.resolve(opts, {"splat": "disc"})
    with pytest.raises(InputError, match="takes SplatOptions, got VolumeOptions"):
        SplatOptions.resolve(VolumeOptions(), {})
    with pytest.raises(InputError, match="not both"):
        BuildOptions.resolve(BuildOptions(), {"lod": True})


def test_render_command_builds_the_options_dataclasses():
    from aniso3d.app.render_cmd import add_render_options, build_options, draw_options

    p = argparse.ArgumentParser()
    add_render_options(p)
    args = p.parse_args(["--splat", "square", "--quality", "fast", "-r", "24", "--lod", "--pixel-error", "3"])
    assert draw_options("splat", args) == SplatOptions(splat="square", quality="fast", pixel_error=3.0)
    assert draw_options("volume", args) == VolumeOptions(pixel_error=3.0)
    assert draw_options("mesh", args) == MeshOptions()
    assert build_options("splat", args) == BuildOptions(resolution=24, lod=True)
    assert build_options("mesh", args).lod is False  # no pyramid for polygons
    args = p.parse_args([])
    assert draw_options("volume", args).pixel_error is None and not build_options("volume", args).lod


def test_splat_data_is_declared_once_in_its_include():
    """The members of the SplatData block live in splat_data.glsl only; every
    splat stage declares the block through it."""
    folder = shader_dir()
    member = re.compile(r"flat\s+vec3\s+hu\b")
    users = []
    for path in sorted(folder.iterdir()):
        if path.suffix not in (".vert", ".geom", ".frag", ".glsl"):
            continue
        text = path.read_text()
        if path.name == "splat_data.glsl":
            assert len(member.findall(text)) == 1
            continue
        assert not member.search(text), f"{path.name} declares SplatData members itself"
        if "SplatData" in re.sub(r"//.*", "", text):
            assert '#include "splat_data.glsl"' in text, path.name
            users.append(path.name)
    assert users == ["splat.frag", "splat.geom", "splat.vert", "splat_floor.frag"]
    code = re.sub(r"//.*", "", preprocess("splat.geom", {"AA": 1, "PASS": 2, "GEOMETRY_PATH": 1}))
    assert code.count("#define SPLAT_DATA ") == 1 and code.count("SplatData SPLAT_DATA") == 2


# ----------------------------------------------------------------- GPU


@pytest.mark.gpu
def test_the_renderers_implement_the_protocol(r):
    for method in RENDERERS:
        impl = r.method_renderer(method)
        assert isinstance(impl, MethodRenderer) and isinstance(impl, RENDERERS[method])


@pytest.mark.gpu
def test_render_takes_options_dataclasses_as_it_takes_keywords(r):
    sphere = aniso3d.scenes.sphere(1.0, subdivisions=3)
    cam = Camera.fit(sphere.bounds)
    kw = r.render(sphere, cam, "splat", resolution=16, per_entry=2, splat="disc", quality="high")
    dc = r.render(sphere, cam, "splat", build=BuildOptions(resolution=16, per_entry=2),
                  options=SplatOptions(splat="disc", quality="high"))  # fmt: skip
    assert np.array_equal(kw, dc) and kw.std() > 0
    with pytest.raises(InputError, match="takes VolumeOptions"):
        r.render(sphere, cam, "volume", resolution=16, options=SplatOptions())
    with pytest.raises(InputError, match="lod=True"):
        r.render(sphere, cam, "volume", build=BuildOptions(resolution=16), options=VolumeOptions(pixel_error=2.0))
