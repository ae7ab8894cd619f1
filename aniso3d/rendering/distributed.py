"""Batch frames on a Dask cluster: a camera path cut into contiguous batches,
one task per batch, each worker drawing with its own GL context.

What :func:`~aniso3d.rendering.renderer.render_frames` (and
``Renderer.render_path(..., client=)``) hands to this module is already
concrete: the thing to draw (a mesh for polygons; a texture or point cloud for
volume and splats, a mesh converted once, on the cluster), the build and draw
options, and the renderer class. Here:

- the thing is scattered once to every worker (``client.scatter(...,
  broadcast=True)``), never shipped with each task, so every batch on a worker
  sees the same object and the worker's renderer converts and uploads it once
  (its caches are keyed by the object);
- each worker makes its own GL context on first use, inside the worker
  process (Dask starts worker processes with 'spawn': none inherits a
  parent's context), one per worker thread (:func:`worker_context`), and
  keeps a renderer on it per (class, size, lighting) in a small registry
  (:func:`worker_renderer`);
- before that first context, ``LP_NUM_THREADS`` is set in the worker when the
  job asks for a number of llvmpipe threads (Mesa reads it once per process);
- a batch reports its start as a Dask event (topic :data:`TOPIC`), and
  returns its frames as arrays, or as PNG bytes that the client writes to
  numbered files atomically (no shared file system needed);
- a worker that dies takes its batch with it: Dask runs the batch again on
  another worker, and the frames are the same (every frame is a function of
  its camera alone).
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
import uuid
import weakref
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aniso3d.errors import InputError, ResourceError
from aniso3d.files import atomic_write
from aniso3d.rendering.camera import Camera
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.images import png_bytes
from aniso3d.rendering.lighting import Lighting

#: Dask event topic of the batches' start reports: ``{"first": i, "frames": n,
#: "pid": ..., "worker": address}``, logged on the worker.
TOPIC = "aniso3d.frames"
#: Batches per worker when no batch size is given: a few, so that a slow or
#: lost worker delays only a small share of the path.
BATCHES_PER_WORKER = 4
#: Renderers a worker thread keeps (the least recently used is released).
REGISTRY_SIZE = 4
INSTALL = "install it with: pip install 'aniso3d[cluster]'"


def missing_dask(what: str = "rendering frames on a Dask cluster") -> ResourceError:
    """The one error for a missing ``dask.distributed``."""
    return ResourceError(f"{what} needs dask.distributed, which is not installed; {INSTALL}")


@dataclass(frozen=True)
class FrameJob:
    """What every batch of one path draws with (small: pickled with each task).

    Attributes:
        renderer: the renderer class a worker makes (``Renderer`` or a subclass).
        size: (width, height) of the frames, pixels.
        lighting: the lighting model.
        backend: OpenGL backend of the workers' contexts ("auto", "egl", ...).
        method: "mesh", "volume" or "splat".
        ssaa: supersampling factor per axis.
        alpha: frames with an alpha channel (H, W, 4).
        build: the renderer's ``BuildOptions`` (resolution already a number).
        options: the method's draw options (a ``DrawOptions``).
        threads: llvmpipe threads per worker (``LP_NUM_THREADS``), set before a
            worker's first context; None leaves the worker's environment alone.
        png: return PNG bytes (frames written to files) instead of arrays.
    """

    renderer: type
    size: tuple[int, int]
    lighting: Lighting
    backend: str
    method: str
    ssaa: int
    alpha: bool
    build: Any
    options: Any
    threads: int | None = None
    png: bool = False


# ------------------------------------------------------------- worker side

_lock = threading.Lock()
#: (thread id, renderer key) -> renderer, in order of last use.
_registry: dict[tuple, Any] = {}
#: Thread id -> the one GL context that thread draws with, shared by its renderers.
_contexts: dict[int, GLContext] = {}
#: What this process has done, for :func:`worker_state`.
_counts = {"contexts": 0, "batches": 0, "frames": 0, "things": 0}
#: The things this process has drawn, held weakly: a thing received again
#: (not the same object) counts again in ``_counts["things"]``.
_things: list[weakref.ref] = []


def worker_context(backend: str = "auto", threads: int | None = None) -> GLContext:
    """This thread's GL context, made on first use. One per thread, shared by
    every renderer the thread keeps: contexts belong to the thread that made
    them, and several contexts drawn with in turn on one thread run many
    times slower on llvmpipe (measured: 12 frames at 64^2 took 70 s instead
    of 0.3 s). A later job asking for another backend than the context's
    replaces it."""
    tid = threading.get_ident()
    with _lock:
        gl = _contexts.get(tid)
    if gl is not None and gl.ctx is not None and backend in ("auto", gl.backend):
        return gl
    if gl is not None:
        release_workers(tid)
    if threads is not None and _counts["contexts"] == 0:
        # Mesa's llvmpipe reads this once, when the process's first context is made.
        os.environ["LP_NUM_THREADS"] = str(threads)
    gl = GLContext(backend)
    with _lock:
        _contexts[tid] = gl
        _counts["contexts"] += 1
    return gl


def worker_renderer(job: FrameJob):
    """This thread's renderer for ``job``: made on first use, on the thread's
    GL context (:func:`worker_context`), then kept, so that its conversions
    and uploads serve the next batches. Run workers with one thread each:
    every thread has its own context."""
    gl = worker_context(job.backend, job.threads)
    key = (threading.get_ident(), job.renderer, job.size, job.lighting)
    with _lock:
        r = _registry.pop(key, None)
        if r is not None and r.gl is gl:
            _registry[key] = r  # most recently used last
            return r
    r = job.renderer(job.size, job.lighting, gl=gl)
    with _lock:
        _registry[key] = r
        mine = [k for k in _registry if k[0] == key[0]]
        stale = [_registry.pop(k) for k in mine[: max(0, len(mine) - REGISTRY_SIZE)]]
    for old in stale:
        old.release()
    return r


def _note_thing(thing) -> None:
    with _lock:
        _things[:] = [ref for ref in _things if ref() is not None]
        if not any(ref() is thing for ref in _things):
            _things.append(weakref.ref(thing))
            _counts["things"] += 1


def _report_start(first: int, n: int) -> None:
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # not on a Dask worker
        return
    worker.log_event(TOPIC, {"first": first, "frames": n, "pid": os.getpid(), "worker": worker.address})


def render_batch(thing, cameras: Sequence[Camera], first: int, job: FrameJob) -> list:
    """Draw ``cameras`` (frames ``first``, ``first + 1``, ...) on this worker:
    (H, W, 3|4) uint8 arrays, or their PNG bytes with ``job.png``."""
    _report_start(first, len(cameras))
    r = worker_renderer(job)
    _note_thing(thing)
    out = []
    for cam in cameras:
        img = r.render(thing, cam, job.method, ssaa=job.ssaa, alpha=job.alpha, build=job.build, options=job.options)
        out.append(png_bytes(img) if job.png else img)
    with _lock:
        _counts["batches"] += 1
        _counts["frames"] += len(cameras)
    return out


def worker_state() -> dict:
    """This process's frame work so far: ``pid``, GL ``contexts`` made,
    ``batches`` and ``frames`` drawn, distinct ``things`` received (a thing
    scattered once counts once per worker however many batches use it),
    ``renderers`` kept, and ``LP_NUM_THREADS``. Run it on workers with
    ``client.run(worker_state)``."""
    with _lock:
        return {**_counts, "pid": os.getpid(), "renderers": len(_registry),
                "lp_num_threads": os.environ.get("LP_NUM_THREADS")}  # fmt: skip


def release_workers(thread: int | None = None) -> int:
    """Release the renderers and GL contexts this process keeps (of one
    thread, or all); how many renderers."""
    with _lock:
        keys = [k for k in _registry if thread is None or k[0] == thread]
        kept = [_registry.pop(k) for k in keys]
        gls = [_contexts.pop(t) for t in list(_contexts) if thread is None or t == thread]
    for r in kept:
        r.release()
    for gl in gls:
        gl.release()
    return len(kept)


# ------------------------------------------------------------- client side


def worker_count(client) -> int:
    """Workers of a Dask client's cluster (at least 1); a clear error for
    something that is not a client."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise missing_dask() from None
    try:
        return max(1, len(client.scheduler_info()["workers"]))
    except (AttributeError, KeyError, TypeError):
        raise InputError(f"client must be a dask.distributed.Client, got {type(client).__name__}") from None


def plan_batches(n_frames: int, n_workers: int, batch_size: int | None = None) -> list[tuple[int, int]]:
    """Contiguous ``[start, stop)`` ranges covering ``n_frames`` frames: of
    ``batch_size`` frames, or by default :data:`BATCHES_PER_WORKER` per worker."""
    if batch_size is None:
        batch_size = max(1, math.ceil(n_frames / (BATCHES_PER_WORKER * max(1, n_workers))))
    if isinstance(batch_size, bool) or int(batch_size) != batch_size or batch_size < 1:
        raise InputError(f"batch_size must be a whole number of frames >= 1, got {batch_size!r}")
    b = int(batch_size)
    return [(a, min(a + b, n_frames)) for a in range(0, n_frames, b)]


def local_threads(n_workers: int) -> int:
    """llvmpipe threads per worker of a local cluster: the cores shared out,
    at least one, so that the workers together do not oversubscribe them."""
    return max(1, (os.cpu_count() or 1) // max(1, n_workers))


@contextlib.contextmanager
def frame_client(client=None, workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """The Dask client to draw on: ``client`` as given; else a client of the
    cluster at ``scheduler`` (an address); else of a ``LocalCluster`` of
    ``workers`` processes of one thread each, made here and closed on exit."""
    if client is not None:
        yield client
        return
    try:
        from distributed import Client
    except ImportError:
        raise missing_dask() from None
    if scheduler is not None and scheduler != "local":
        try:
            c = Client(scheduler, timeout=30)
        except (ValueError, TypeError) as exc:
            raise InputError(f"'{scheduler}' is not a Dask scheduler address ({exc}); give one like "
                             "tcp://host:8786, or 'local'") from None  # fmt: skip
        except OSError as exc:
            raise ResourceError(f"cannot reach the Dask scheduler at '{scheduler}': {exc}") from None
        with c:
            yield c
        return
    from aniso3d.build.stream import local_cluster

    with local_cluster(max(1, workers or 1)) as cluster, Client(cluster) as c:
        yield c


#: Times :func:`run_batches` scatters its input again after the cluster lost
#: it with a worker, before giving up.
MAX_SCATTERS = 4


def run_batches(
    client,
    thing,
    cameras: Sequence[Camera],
    job: FrameJob,
    *,
    folder: str | os.PathLike | None = None,
    pattern: str = "frame_{:04d}.png",
    progress: Callable[[float, str], None] | None = None,
    batch_size: int | None = None,
    retries: int = 1,
) -> list:
    """Draw one frame per camera on ``client``'s workers, in contiguous
    batches; the frames in camera order, as arrays, or as the paths of the
    PNG files written into ``folder`` (atomically, as batches finish).

    ``retries``: times a batch that raised is run again (a batch lost with
    its worker is run again by Dask in any case)."""
    try:
        from distributed import as_completed
    except ImportError:
        raise missing_dask() from None
    cams = list(cameras)
    n = len(cams)
    ranges = plan_batches(n, worker_count(client), batch_size)
    if folder is not None:
        job = FrameJob(**{**job.__dict__, "png": True})
        folder = Path(folder)
    token = uuid.uuid4().hex[:8]
    data = client.scatter([thing], broadcast=True, hash=False)[0]
    scatters = 1

    def submit(a: int, b: int, attempt: int):
        return client.submit(render_batch, data, cams[a:b], a, job, key=f"aniso3d-frames-{token}-{a:06d}-{attempt}",
                             retries=retries, pure=False)  # fmt: skip

    pending = {submit(a, b, 0): (a, b, 0, data.key) for a, b in ranges}
    out: list = [None] * n
    done = 0
    try:
        queue = as_completed(list(pending))
        for f in queue:
            a, b, attempt, used = pending.pop(f)
            if f.cancelled():
                # Dask forgets scattered data when a worker holding it dies,
                # even when broadcast (dask/distributed#3149), and cancels the
                # batches that need it: scatter the thing again, redo them.
                if used == data.key:
                    if scatters > MAX_SCATTERS:
                        raise ResourceError(f"the cluster lost the scattered input {scatters} times (workers "
                                            "dying?); check the workers' logs and memory")  # fmt: skip
                    data.release()
                    data = client.scatter([thing], broadcast=True, hash=False)[0]
                    scatters += 1
                again = submit(a, b, attempt + 1)
                pending[again] = (a, b, attempt + 1, data.key)
                queue.add(again)
                continue
            frames = f.result()
            f.release()
            for i, frame in enumerate(frames, a):
                out[i] = atomic_write(folder / pattern.format(i), frame) if folder is not None else frame
            done += b - a
            if progress:
                progress(done / n, f"frame {done}/{n}")
    finally:
        if pending:  # an error: drop the batches not done
            client.cancel(list(pending))
        data.release()
    return out

