"""One background thread for the viewer's slow conversions (mesh -> texture
-> pyramid -> points), so the window keeps answering while they run.

GL work stays on the main thread: the window polls :meth:`Builder.poll` once
per frame and uploads a finished result on the next frame.
"""

from __future__ import annotations

import atexit
import threading
import time
from collections.abc import Callable

#: A job: called with a ``progress(fraction, stage)`` callable, returns {data key: value}.
Job = Callable[[Callable[..., None]], dict]


#: The build thread's name; :func:`builds_running` looks for it.
THREAD_NAME = "aniso3d-build"


def builds_running() -> bool:
    """A viewer build thread is still working in this process.

    A process must not finalise the interpreter under one: CPython stops a
    daemon thread that wants the GIL back during finalisation by unwinding
    its stack, and an unwind through compiled library frames can abort the
    whole process ("terminate called without an active exception", seen as
    an exit status of -6 on quit mid-build). The CLI therefore ends its
    process with :func:`os._exit` when this is true.
    """
    return any(t.name == THREAD_NAME and t.is_alive() for t in threading.enumerate())


#: How long the exit of a program waits for a cancelled build to stop.
STOP_SECONDS = 30.0


@atexit.register
def _stop_builds() -> None:
    """At interpreter exit (a program that called :func:`run_viewer`), wait
    for cancelled builds to reach their next progress report and stop, so
    finalisation never meets one (see :func:`builds_running`)."""
    for t in threading.enumerate():
        if t.name == THREAD_NAME and t.is_alive():
            t.join(STOP_SECONDS)



class Cancelled(Exception):
    """Raised inside a build whose result is no longer wanted."""


class Builder:
    """One job at a time on a daemon thread; :meth:`poll` hands its result (or
    exception) to the main thread.

    A job is called with a ``progress(fraction, stage)`` callable (the one
    :func:`~aniso3d.build.texture.build_texture` takes); it records the
    progress and raises :class:`Cancelled` once :meth:`cancel` was called,
    which is how a build the user has moved on from stops early.
    """

    def __init__(self):
        self._thread: threading.Thread | None = None
        self._result: tuple | None = None
        self._cancel = threading.Event()
        self.key: tuple | None = None
        self.label = ""
        self.started = 0.0
        self.fraction = 0.0

    @property
    def busy(self) -> bool:
        """A job was started and its result not yet collected by :meth:`poll`."""
        return self._thread is not None

    def start(self, key: tuple, label: str, job: Job) -> None:
        if self.busy:
            raise RuntimeError("a build is already running")
        cancel = self._cancel = threading.Event()

        def progress(fraction: float, stage: str = "") -> None:
            self.fraction = float(fraction)
            if cancel.is_set():
                raise Cancelled()

        def work():
            try:
                result = (job(progress), None)
            except BaseException as exc:  # reported in the window, never raised in a thread
                result = (None, exc)
            self._result = result

        self.key, self.label, self.started, self._result = key, label, time.perf_counter(), None
        self.fraction = 0.0
        # A daemon: quitting mid-build must not wait for the build.
        self._thread = threading.Thread(target=work, name=THREAD_NAME, daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        """The job's thread is still working (finished or not collected: False)."""
        return self._thread is not None and self._thread.is_alive()

    def cancel(self) -> None:
        """Ask the running job to stop at its next progress report."""
        self._cancel.set()

    @property
    def cancelling(self) -> bool:
        return self.busy and self._cancel.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the running job has finished (not collected); False on timeout."""
        thread = self._thread
        if thread is None:
            return True
        thread.join(timeout)
        return not thread.is_alive()

    def poll(self) -> tuple[dict | None, BaseException | None, float] | None:
        """(results, exception, seconds) once the job has finished, else None."""
        if self._thread is None or self._thread.is_alive():
            return None
        self._thread.join()
        self._thread = None
        results, exc = self._result or (None, RuntimeError("the build ended without a result"))
        return results, exc, time.perf_counter() - self.started

    def elapsed(self) -> float:
        """Seconds since the running job started; 0 when idle."""
        return time.perf_counter() - self.started if self.busy else 0.0

    def describe(self) -> str:
        """The overlay's building line, e.g. "building texture 64³ (K=16)… 40% 1.2 s"."""
        return f"building {self.label}… {100 * self.fraction:.0f}% {self.elapsed():.1f} s"
