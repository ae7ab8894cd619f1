"""The shader preprocessor, on plain strings (no GPU)."""

import pytest

from aniso3d.rendering.shader_source import ShaderSourceError, preprocess, read_shader, shader_dir


def loader_from(files):
    def load(name):
        if name not in files:
            raise ShaderSourceError(f"shader file '{name}' not found")
        return files[name]

    return load


def test_include_is_expanded_once_with_line_markers():
    files = {
        "main.frag": '#version 330\n#include "a.glsl"\n#include "a.glsl"\nvoid main() {}\n',
        "a.glsl": "float a() { return 1.0; }\n",
    }
    out = preprocess("main.frag", loader=loader_from(files))
    assert out.startswith("#version 330\n")
    assert out.count("float a()") == 1
    assert "#line 1 1" in out  # entering a.glsl (file 1)
    assert "#line 3 0" in out  # back in main.frag after the include on line 2
    assert "void main() {}" in out


def test_defines_follow_version():
    files = {"m.vert": "#version 330\nvoid main() {}\n"}
    out = preprocess("m.vert", {"SHAPE": 2, "SCALE": 1.5, "HQ": True}, loader=loader_from(files))
    lines = out.splitlines()
    assert lines[0] == "#version 330"
    assert "#define SHAPE 2" in lines
    assert "#define SCALE 1.5" in lines
    assert "#define HQ 1" in lines


def test_circular_include_is_refused():
    files = {
        "m.frag": '#version 330\n#include "a.glsl"\n',
        "a.glsl": '#include "b.glsl"\n',
        "b.glsl": '#include "a.glsl"\n',
    }
    with pytest.raises(ShaderSourceError, match="circular"):
        preprocess("m.frag", loader=loader_from(files))


def test_missing_file_and_missing_version_are_clear():
    with pytest.raises(ShaderSourceError, match="not found"):
        preprocess("m.frag", loader=loader_from({"m.frag": '#version 330\n#include "x.glsl"\n'}))
    with pytest.raises(ShaderSourceError, match="#version"):
        preprocess("m.frag", loader=loader_from({"m.frag": "void main() {}\n"}))
    with pytest.raises(ShaderSourceError, match="define"):
        preprocess("m.frag", {"bad name": 1}, loader=loader_from({"m.frag": "#version 330\n"}))


def test_shipped_shaders_are_found_and_expand():
    assert (shader_dir() / "lighting.glsl").exists()
    out = preprocess("mesh.frag")
    assert "vec3 shade(" in out and "#include" not in out
    assert "MAX_LIGHTS" in read_shader("lighting.glsl")
