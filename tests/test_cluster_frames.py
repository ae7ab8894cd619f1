"""Frames on a Dask cluster (``render_frames``, ``Renderer.render_path(client=)``,
``aniso3d frames --workers``): the same pixels as the serial renderer for every
method, the thing scattered once and one GL context per worker, a worker
killed mid-batch changing nothing, and one clear message without dask.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from dataclasses import dataclass

import numpy as np
import pytest

from aniso3d import Camera, InputError, Renderer, ResourceError, render_frames, scenes, turntable
from aniso3d.app.cli import main
from aniso3d.build import stream
from aniso3d.rendering import distributed as dist
from aniso3d.rendering.context import DEVICE_ENV, GLContext
from aniso3d.rendering.images import load_png

SIZE = (64, 64)
RES = 16
METHODS = ("mesh", "volume", "splat")


@pytest.fixture(scope="module")
def mesh():
    return scenes.lattice()


@pytest.fixture(scope="module")
def cams(mesh):
    return turntable(Camera.fit(mesh.bounds, direction=(0.6, 0.4, 0.7)), 6, 300.0)


@pytest.fixture(scope="module")
def serial(mesh, cams):
    """The frames of the serial renderer, per method."""
    try:
        out = {m: render_frames(mesh, cams, None, m, size=SIZE, resolution=RES) for m in METHODS}
    except ResourceError as exc:  # no OpenGL on this machine
        pytest.skip(str(exc))
    return out


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    with stream.local_cluster(2) as c, distributed.Client(c) as cl:
        assert c.workers and all(w.process.is_alive() for w in c.workers.values())  # processes, not threads
        yield cl


def on_cluster(mesh, cams, method, client, **kw):
    # One llvmpipe thread per worker (set before each worker's first context).
    return render_frames(mesh, cams, kw.pop("folder", None), method, client=client, size=SIZE, resolution=RES,
                         threads=1, **kw)  # fmt: skip


def test_plan_batches_cover_the_path_in_order():
    assert dist.plan_batches(10, 2) == [(0, 2), (2, 4), (4, 6), (6, 8), (8, 10)]
    assert dist.plan_batches(3, 2, batch_size=2) == [(0, 2), (2, 3)]
    assert dist.plan_batches(1, 8) == [(0, 1)]
    with pytest.raises(InputError, match="batch_size"):
        dist.plan_batches(4, 2, batch_size=0)


def test_the_serial_frames_are_pictures(serial):
    for method, frames in serial.items():
        assert len(frames) == 6 and all(f.shape == (*SIZE[::-1], 3) and f.dtype == np.uint8 for f in frames)
        drawn = [(f < 250).any(axis=2).mean() for f in frames]
        assert min(drawn) > 0.05, (method, drawn)  # the object covers part of every frame
        assert not np.array_equal(frames[0], frames[3]), method  # the turntable turns


@pytest.mark.parametrize("method", METHODS)
def test_cluster_frames_equal_the_serial_frames(mesh, cams, serial, client, method):
    got = on_cluster(mesh, cams, method, client, batch_size=2)
    assert len(got) == len(cams)
    for i, (a, b) in enumerate(zip(serial[method], got, strict=True)):
        assert np.array_equal(a, b), f"{method}: frame {i} differs in {int((a != b).any(axis=2).sum())} pixels"


def test_pngs_and_render_path_on_the_cluster(mesh, cams, serial, client, tmp_path):
    paths = on_cluster(mesh, cams, "splat", client, folder=tmp_path / "a", pattern="f{:02d}.png")
    assert [p.name for p in paths] == [f"f{i:02d}.png" for i in range(6)]
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == [p.name for p in paths]  # no temporary left
    assert all(np.array_equal(load_png(p), f) for p, f in zip(paths, serial["splat"], strict=True))
    with Renderer(SIZE) as r:
        paths = r.render_path(mesh, cams, tmp_path / "b", "volume", client=client, resolution=RES)
    assert all(np.array_equal(load_png(p), f) for p, f in zip(paths, serial["volume"], strict=True))


def test_the_thing_is_scattered_once_and_each_worker_keeps_its_context(mesh, cams, client):
    on_cluster(mesh, cams[:2], "mesh", client)  # every worker has its renderer by now, or makes it here
    before = client.run(dist.worker_state)
    on_cluster(mesh, cams + cams, "mesh", client, batch_size=1)  # 12 batches on 2 workers
    after = client.run(dist.worker_state)
    batches = {w: after[w]["batches"] - before[w]["batches"] for w in after}
    assert sum(batches.values()) == 12
    for w, n in batches.items():
        if n:
            # one received object however many batches (shipped per task it would be n)
            assert after[w]["things"] - before[w]["things"] == 1, (w, n)
            assert after[w]["contexts"] == before[w]["contexts"] or before[w]["batches"] == 0  # kept
            assert after[w]["lp_num_threads"] == "1"


@dataclass(frozen=True)
class StallingCamera(Camera):
    """A camera that waits, wherever it is drawn, until its process is
    killed; once the killer has left its marker file, a plain camera."""

    marker: str = ""

    def clip_range(self, bounds):
        if not os.path.exists(self.marker):
            threading.Event().wait(120)  # killed before this returns
            raise RuntimeError("the worker drawing this batch was not killed")
        return super().clip_range(bounds)


def test_a_worker_killed_mid_batch_changes_nothing(mesh, cams, serial, client, tmp_path):
    import cloudpickle

    c = cams[3]
    marker = tmp_path / "killed"
    stalling = StallingCamera(c.position, c.target, c.up, c.fov, marker=str(marker))
    path = cams[:3] + [stalling] + cams[4:]
    pids = set(client.run(os.getpid).values())
    starts, killed = [], []

    def on_start(event) -> None:  # runs in the client's event loop as each batch reports its start
        msg = event[1]
        starts.append((msg["first"], msg["pid"]))
        if msg["first"] == 2 and not killed:  # the batch of frames 2 and 3, which cannot finish
            killed.append(msg["pid"])
            marker.write_text(str(msg["pid"]))  # a batch drawn again passes
            os.kill(msg["pid"], signal.SIGKILL)

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import this module
    client.subscribe_topic(dist.TOPIC, on_start)
    try:
        got = on_cluster(mesh, path, "splat", client, batch_size=2, retries=0)
    finally:
        client.unsubscribe_topic(dist.TOPIC)
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert killed and killed[0] in pids  # a worker of the cluster died in the middle of its batch
    assert [pid for first, pid in starts if first == 2][0] == killed[0]
    assert len([1 for first, _ in starts if first == 2]) == 2  # and the batch was drawn again elsewhere
    assert all(np.array_equal(a, b) for a, b in zip(serial["splat"], got, strict=True))


def test_cli_frames_on_a_local_cluster(tmp_path, capsys):
    pytest.importorskip("distributed")
    args = ["frames", "scene:lattice", "--frames", "3", "--size", "48", "--method", "volume", "-r", "16", "-q"]
    assert main(args + ["-o", str(tmp_path / "serial")]) == 0
    assert main(args + ["-o", str(tmp_path / "dask"), "--workers", "2"]) == 0
    out = capsys.readouterr().out
    t = dist.local_threads(2)  # the cores shared out: 1 each on 2 cores
    assert f"drawn on a local Dask cluster of 2 workers, {t} llvmpipe thread{'s' if t > 1 else ''} each" in out
    for i in range(3):
        name = f"frame_{i:04d}.png"
        assert np.array_equal(load_png(tmp_path / "serial" / name), load_png(tmp_path / "dask" / name))


def test_cli_video_from_a_local_cluster(tmp_path, capsys):
    """Frames drawn on the cluster come back as arrays and go into one video, the same as drawn here."""
    pytest.importorskip("distributed")
    from PIL import Image

    args = ["frames", "scene:lattice", "--frames", "3", "--size", "48", "--method", "splat", "-r", "16", "-q"]
    assert main(args + ["-o", str(tmp_path / "serial.gif")]) == 0
    assert main(args + ["-o", str(tmp_path / "dask.gif"), "--workers", "2"]) == 0
    assert "drawn on a local Dask cluster of 2 workers" in capsys.readouterr().out
    with Image.open(tmp_path / "serial.gif") as a, Image.open(tmp_path / "dask.gif") as b:
        assert a.n_frames == b.n_frames == 3
        for i in range(3):
            a.seek(i)
            b.seek(i)
            assert np.array_equal(np.asarray(a.convert("RGB")), np.asarray(b.convert("RGB")))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dask.gif", "serial.gif"]  # no temporary left


def test_missing_dask_is_one_clear_message(mesh, cams, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    for kw in ({"workers": 2}, {"client": object()}):
        with pytest.raises(ResourceError, match=r"pip install 'aniso3d\[cluster\]'"):
            render_frames(mesh, cams, None, "mesh", size=SIZE, **kw)
    code = main(["frames", "scene:lattice", "--frames", "2", "--size", "32", "-o", str(tmp_path / "f"),
                 "--workers", "2", "-q"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "pip install 'aniso3d[cluster]'" in err


def test_a_malformed_scheduler_address_is_one_clear_message(tmp_path, capsys):
    pytest.importorskip("distributed")
    code = main(["frames", "scene:lattice", "--frames", "2", "--size", "32", "-o", str(tmp_path / "f"),
                 "--scheduler", "foo", "-q"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "tcp://host:8786" in err


def test_a_scene_on_a_local_cluster_takes_the_scene_resolution(tmp_path, capsys):
    pytest.importorskip("distributed")
    args = ["frames", "--scene", "forest", "--trees", "2", "--frames", "2", "--size", "32", "-q", "--method", "splat"]
    assert main(args + ["-o", str(tmp_path / "serial")]) == 0
    assert main(args + ["-o", str(tmp_path / "dask"), "--workers", "2"]) == 0
    assert "texture 64³ per asset" in capsys.readouterr().out
    for i in range(2):
        name = f"frame_{i:04d}.png"
        assert np.array_equal(load_png(tmp_path / "serial" / name), load_png(tmp_path / "dask" / name))


def test_egl_device_option_and_environment(monkeypatch):
    try:
        with GLContext(device=0) as gl:
            assert gl.backend == "egl" and gl.device == 0
    except ResourceError as exc:
        pytest.skip(f"no EGL device 0: {exc}")
    with pytest.raises(ResourceError, match=r"EGL device 999 was asked for .*ANISO3D_EGL_DEVICE"):
        GLContext(device=999)
    monkeypatch.setenv(DEVICE_ENV, "999")
    with pytest.raises(ResourceError, match="EGL device 999"):
        GLContext()
    monkeypatch.setenv(DEVICE_ENV, "first")
    with pytest.raises(ResourceError, match=r"ANISO3D_EGL_DEVICE='first': the EGL device must be a whole number"):
        GLContext()
    with pytest.raises(ResourceError, match="backend 'osmesa' is not EGL"):
        GLContext("osmesa", device=0)
