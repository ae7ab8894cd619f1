"""Fixtures shared by the GPU test modules."""

import pytest

from aniso3d import ResourceError
from aniso3d.rendering.renderer import Renderer

#: Image size of the shared renderer: small enough for llvmpipe, large enough
#: that test objects span many pixels.
SIZE = (128, 128)


@pytest.fixture(scope="module")
def r():
    """One headless 128 x 128 Renderer per test module (EGL first), released at
    the module's end; the module is skipped where no OpenGL context exists."""
    try:
        renderer = Renderer(SIZE)
    except ResourceError as exc:  # no OpenGL on this machine
        pytest.skip(str(exc))
    yield renderer
    renderer.release()


def pytest_addoption(parser):
    parser.addoption(
        "--regen-references",
        action="store_true",
        help="rewrite the reference images in tests/reference/ from the current renderers "
        "(check the new PNGs by eye before committing them)",
    )


@pytest.fixture
def regen_references(request) -> bool:
    return bool(request.config.getoption("--regen-references"))
