"""Several Renderers, each with its own OpenGL context, in one process: every
OpenGL call goes to the current context, so a Renderer makes its own current
before it draws, uploads or frees, and releasing (or dropping) one leaves the
others drawing what they drew before (a released context used to delete the
current one's objects of the same names: a later turntable came out as noise)."""

from __future__ import annotations

import gc

import numpy as np
import pytest

from aniso3d import ResourceError, scenes
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.renderer import Renderer

SIZE = (64, 64)


@pytest.fixture
def blob_view():
    blob = scenes.get_scene("blob", subdivisions=2)
    return blob, Camera.fit(blob.bounds, direction=(0.3, 0.4, 1.0))


def renderer() -> Renderer:
    try:
        return Renderer(SIZE)
    except ResourceError as exc:  # no OpenGL on this machine
        pytest.skip(str(exc))


@pytest.mark.gpu
@pytest.mark.parametrize("how", ["release", "drop"])
def test_releasing_or_dropping_one_renderer_leaves_another_drawing(blob_view, how):
    blob, cam = blob_view
    first = renderer()
    first.render(blob, cam, "volume")  # objects of its own to release
    with renderer() as second:  # made after the first: its context is current
        before = second.render(blob, cam, "mesh")
        if how == "release":
            first.release()
        else:  # a Renderer nobody released: its context goes with the garbage
            del first
            gc.collect()
        after = second.render(blob, cam, "mesh")
    assert before.mean() < 250  # the blob is there
    assert np.array_equal(before, after)


@pytest.mark.gpu
def test_two_renderers_used_in_turn_draw_as_each_alone(blob_view):
    blob, cam = blob_view
    with renderer() as a:
        alone = a.render(blob, cam, "mesh")
        with renderer() as b:
            b.render(blob, cam, "volume")  # the newer context, current after it is made
            again = a.render(blob, cam, "mesh")
            b_again = b.render(blob, cam, "mesh")
    assert np.array_equal(alone, again) and np.array_equal(alone, b_again)
