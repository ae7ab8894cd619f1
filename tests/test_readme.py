"""The README's Python example runs as written (in a scratch folder)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_the_readme_has_a_python_example():
    blocks = python_blocks()
    assert blocks and "import aniso3d" in blocks[0]


@pytest.mark.gpu
def test_the_readme_python_example_runs_as_written(tmp_path, r):
    """``r`` (the shared renderer fixture) skips this where no OpenGL exists."""
    code = python_blocks()[0]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    assert re.search(r"volume: \d+ ms, \d+ voxels", out.stdout), out.stdout
    assert len(sorted((tmp_path / "frames").glob("*.png"))) == 8
