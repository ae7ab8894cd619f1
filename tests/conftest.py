"""Fixtures shared by the GPU test modules."""

import pytest
from hypothesis import settings

from aniso3d import ResourceError
from aniso3d.rendering.renderer import Renderer

# Property tests draw the same examples on every run (no example database):
# a run passes or fails for the code, not for the examples it happened to draw.
settings.register_profile("aniso3d", derandomize=True, database=None)
settings.load_profile("aniso3d")

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


def build_open(mesh, *args, **kwargs):
    """``build_texture`` with every face taken as open: the registration's
    exact sums (areas and densities conserved), which tests of accounting
    (points, levels of detail) check. A closed skin's hidden backs, which
    take those sums apart on purpose, are tests/test_thin_solids.py's."""
    import numpy as np

    import aniso3d.build.mesh_stream as mesh_stream
    from aniso3d import build_texture

    with pytest.MonkeyPatch.context() as mp:
        none = lambda f: np.zeros(len(f), bool)  # noqa: E731
        mp.setattr(mesh_stream, "face_topology", lambda v, f: (np.zeros(len(f), np.int8), none(f), none(f)))
        return build_texture(mesh, *args, **kwargs)


def module_renderer(size, backend: str = "egl"):
    """A module-scoped fixture ``r``: one headless Renderer of ``size`` on
    ``backend``, released at the module's end; the module is skipped where
    that OpenGL context cannot be made. In a module: ``r = module_renderer(SIZE)``."""

    @pytest.fixture(scope="module")
    def r():
        try:
            renderer = Renderer(size, backend=backend)
        except ResourceError as exc:  # no OpenGL through this backend on this machine
            pytest.skip(str(exc))
        yield renderer
        renderer.release()

    return r
