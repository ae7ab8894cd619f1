"""The GPU context: owns the OpenGL context, the program cache and every GPU
object the renderers make, and releases them deterministically.

Headless by default: EGL first (Mesa's llvmpipe works without a GPU), then
OSMesa (libosmesa6 called through ctypes, for machines without EGL), then X11
where ``DISPLAY`` is set. Renderers never create a context; they are handed
one.

On a machine with several GPUs, the EGL device to draw on is chosen with
``GLContext(device=i)`` or the environment variable :data:`DEVICE_ENV`
(``ANISO3D_EGL_DEVICE=i``): the i-th device EGL enumerates
(``eglQueryDevicesEXT``), so that each worker of a cluster can be bound to
its own GPU (docs/cluster.md).
"""

from __future__ import annotations

import logging
import os
import weakref
from typing import Any

import moderngl

from aniso3d.errors import ResourceError
from aniso3d.rendering.shader_source import preprocess

log = logging.getLogger("aniso3d")

BACKENDS = ("egl", "osmesa", "x11")
REQUIRE = 330
#: Environment variable naming the EGL device (an index) a context is made on.
DEVICE_ENV = "ANISO3D_EGL_DEVICE"

INSTALL_HINT = (
    "aniso3d needs OpenGL 3.3 or newer. On Debian/Ubuntu install Mesa's software "
    "renderer: 'apt-get install libegl1 libgl1-mesa-dri' (EGL, headless), or "
    "'apt-get install libosmesa6' (OSMesa)"
)


class _OSMesaLoader:
    """Loader for ``moderngl.init_context`` over an OSMesa context made current.

    Talks to Debian's libOSMesa (package libosmesa6) through ctypes, so no
    extra Python package is needed.
    """

    # Constants from GL/osmesa.h.
    FORMAT, RGBA, DEPTH_BITS = 0x22, 0x1908, 0x30
    PROFILE, CORE_PROFILE, MAJOR, MINOR = 0x33, 0x34, 0x36, 0x37
    GL_UNSIGNED_BYTE = 0x1401

    def __init__(self, size=(16, 16)):
        import ctypes
        import ctypes.util

        name = ctypes.util.find_library("OSMesa") or "libOSMesa.so.8"
        try:
            lib = ctypes.CDLL(name)
        except OSError:
            raise RuntimeError("libOSMesa not found (Debian package libosmesa6)") from None
        self.lib = lib
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.restype = ctypes.c_ubyte
        lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint,
                                          ctypes.c_int, ctypes.c_int]  # fmt: skip
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        # Ask for the newest core profile first: the volume renderer needs 4.3.
        self.ctx = None
        for major, minor in ((4, 5), (4, 3), (3, 3)):
            attrs = [self.FORMAT, self.RGBA, self.DEPTH_BITS, 24, self.PROFILE, self.CORE_PROFILE,
                     self.MAJOR, major, self.MINOR, minor, 0]  # fmt: skip
            self.ctx = lib.OSMesaCreateContextAttribs((ctypes.c_int * len(attrs))(*attrs), None)
            if self.ctx:
                break
        if not self.ctx:
            raise RuntimeError("OSMesaCreateContextAttribs failed (no core profile 3.3)")
        self.buf = (ctypes.c_ubyte * (size[0] * size[1] * 4))()
        if not lib.OSMesaMakeCurrent(self.ctx, self.buf, self.GL_UNSIGNED_BYTE, size[0], size[1]):
            lib.OSMesaDestroyContext(self.ctx)
            raise RuntimeError("OSMesaMakeCurrent failed")

    def load_opengl_function(self, name: str) -> int:
        return self.lib.OSMesaGetProcAddress(name.encode()) or 0

    def release(self) -> None:
        if self.ctx:
            self.lib.OSMesaDestroyContext(self.ctx)
            self.ctx = None


def egl_device(device: int | str | None = None) -> int | None:
    """The EGL device index asked for: ``device``, else the environment's
    :data:`DEVICE_ENV`, else None (EGL's default device); checked."""
    if device is None:
        device = os.environ.get(DEVICE_ENV) or None
        if device is None:
            return None
        where = f"{DEVICE_ENV}={device!r}"
    else:
        where = f"device={device!r}"
    try:
        index = int(str(device).strip())
    except ValueError:
        index = -1
    if isinstance(device, bool) or index < 0:
        raise ResourceError(f"{where}: the EGL device must be a whole number >= 0 (0 is the first device)")
    return index


def _create(backend: str, device: int | None = None) -> tuple[moderngl.Context, Any]:
    if backend == "egl":
        if device is not None:
            return moderngl.create_standalone_context(backend="egl", require=REQUIRE, device_index=device), None
        return moderngl.create_standalone_context(backend="egl", require=REQUIRE), None
    if backend == "x11":
        if not os.environ.get("DISPLAY"):
            raise RuntimeError("DISPLAY is not set")
        return moderngl.create_standalone_context(require=REQUIRE), None
    if backend == "osmesa":
        loader = _OSMesaLoader()
        moderngl.init_context(loader=loader)
        ctx = moderngl.get_context()
        # get_context() keeps a module-level default; we own this one.
        import moderngl as _m

        _m._store.default_context = None
        if ctx.version_code < REQUIRE:
            raise RuntimeError(f"OSMesa gave OpenGL {ctx.version_code}, need {REQUIRE}")
        return ctx, loader
    raise ValueError(backend)


#: The contexts this process made and has not released, oldest first (weakly),
#: and the one it last made current. Every OpenGL call goes to the current
#: context, so a Renderer makes its own current before it draws, uploads or
#: frees (:meth:`GLContext.use`); destroying a context leaves none current, so
#: the one current before (else the newest left) is made current again.
_LIVE: list[weakref.ref] = []
_CURRENT: weakref.ref | None = None


def _current_again(previous: GLContext | None) -> None:
    """After a context was destroyed: make ``previous`` current again if it
    lives, else the newest live context of :data:`_LIVE`."""
    global _CURRENT
    _LIVE[:] = [w for w in _LIVE if (c := w()) is not None and c.ctx is not None]
    _CURRENT = None
    if previous is None or previous.ctx is None:
        previous = _LIVE[-1]() if _LIVE else None
    if previous is not None:
        previous.use()


class GLContext:
    """An OpenGL context with a program cache and an inventory of GPU objects.

    Use as a context manager, or call :meth:`release`. ``backend`` is "auto"
    (EGL, then OSMesa, then X11), or one of :data:`BACKENDS`. ``device``
    (default: the environment's :data:`DEVICE_ENV`) is the EGL device index;
    with one, "auto" means EGL only (no silent fall-back to another device).
    """

    def __init__(self, backend: str = "auto", device: int | None = None):
        if backend != "auto" and backend not in BACKENDS:
            raise ResourceError(f"unknown OpenGL backend '{backend}'; choose auto or one of {BACKENDS}")
        #: The EGL device index asked for (None: EGL's default).
        self.device = egl_device(device)
        if self.device is not None and backend not in ("auto", "egl"):
            raise ResourceError(f"an EGL device ({self.device}) was asked for, but backend '{backend}' is not EGL")
        order = ("egl",) if self.device is not None else BACKENDS if backend == "auto" else (backend,)
        errors = []
        self.ctx: moderngl.Context | None = None
        self._loader = None
        for name in order:
            try:
                self.ctx, self._loader = _create(name, self.device)
                self.backend = name
                break
            except Exception as exc:  # every backend fails in its own way
                errors.append(f"{name}: {type(exc).__name__}: {exc}")
        if self.ctx is None:
            hint = INSTALL_HINT if self.device is None else (
                f"EGL device {self.device} was asked for (device= or {DEVICE_ENV}); choose an index EGL lists"
            )
            raise ResourceError("no OpenGL 3.3+ context could be created (" + "; ".join(errors) + "). " + hint)
        info = self.ctx.info
        self.renderer = str(info.get("GL_RENDERER", "?"))
        self.version = str(info.get("GL_VERSION", "?"))
        self.software = any(s in self.renderer.lower() for s in ("llvmpipe", "softpipe", "swrast"))
        self.max_texture_size = int(info.get("GL_MAX_TEXTURE_SIZE", 8192))
        self.max_viewport = tuple(int(x) for x in info.get("GL_MAX_VIEWPORT_DIMS", (8192, 8192)))
        log.info(
            "OpenGL context: %s via %s (%s)%s",
            self.renderer, self.backend, self.version, " [software]" if self.software else "",
        )  # fmt: skip
        self._programs: dict[tuple, moderngl.Program] = {}
        self._objects: list[Any] = []
        global _CURRENT
        _LIVE.append(weakref.ref(self))
        _CURRENT = _LIVE[-1]  # a new context is current

    #: False for a context adopted with :meth:`wrap`: its owner releases it.
    _owns_ctx = True

    @classmethod
    def wrap(cls, ctx: moderngl.Context) -> GLContext:
        """Adopt a context made elsewhere (e.g. a window's). Objects and programs
        made through the result are tracked and released as usual; the context
        itself is left to its owner."""
        if ctx.version_code < REQUIRE:
            raise ResourceError(f"OpenGL {ctx.version_code} is too old; aniso3d needs {REQUIRE}+")
        self = cls.__new__(cls)
        self.ctx, self._loader, self.backend, self._owns_ctx = ctx, None, "external", False
        self.device = None
        info = ctx.info
        self.renderer = str(info.get("GL_RENDERER", "?"))
        self.version = str(info.get("GL_VERSION", "?"))
        self.software = any(s in self.renderer.lower() for s in ("llvmpipe", "softpipe", "swrast"))
        self.max_texture_size = int(info.get("GL_MAX_TEXTURE_SIZE", 8192))
        self.max_viewport = tuple(int(x) for x in info.get("GL_MAX_VIEWPORT_DIMS", (8192, 8192)))
        self._programs, self._objects = {}, []
        return self

    # ------------------------------------------------------------ resources

    def _check(self) -> moderngl.Context:
        if self.ctx is None:
            raise ResourceError("this GLContext was released; create a new one")
        return self.ctx

    def track(self, obj):
        """Register a GPU object to be released with the context; returns it."""
        self._objects.append(obj)
        return obj

    def free(self, *objs) -> None:
        """Release GPU objects now (and forget them)."""
        for obj in objs:
            if obj is None:
                continue
            try:
                obj.release()
            finally:
                if obj in self._objects:
                    self._objects.remove(obj)

    def program(
        self,
        vertex: str,
        fragment: str,
        geometry: str | None = None,
        defines: dict[str, object] | None = None,
    ) -> moderngl.Program:
        """A compiled program from shader files, cached by files and defines."""
        key = (vertex, fragment, geometry, tuple(sorted((defines or {}).items())))
        prog = self._programs.get(key)
        if prog is None:
            ctx = self._check()
            src = {
                "vertex_shader": preprocess(vertex, defines),
                "fragment_shader": preprocess(fragment, defines),
            }
            if geometry:
                src["geometry_shader"] = preprocess(geometry, defines)
            try:
                prog = ctx.program(**src)
            except moderngl.Error as exc:
                raise ResourceError(f"shader compile/link failed for {vertex}+{fragment}: {exc}") from None
            self._programs[key] = prog
        return prog

    def compute(self, name: str, defines: dict[str, object] | None = None):
        key = (name, "compute", None, tuple(sorted((defines or {}).items())))
        prog = self._programs.get(key)
        if prog is None:
            try:
                prog = self._check().compute_shader(preprocess(name, defines))
            except moderngl.Error as exc:
                raise ResourceError(f"compute shader {name} failed to compile: {exc}") from None
            self._programs[key] = prog
        return prog

    @staticmethod
    def set_uniforms(prog: moderngl.Program, values: dict[str, object], strict: bool = True) -> None:
        """Set uniforms by name; a name the program lacks is an error when
        ``strict`` (catches typos), unless the compiler optimised it away, which
        we cannot tell apart, so optional uniforms pass ``strict=False``."""
        for name, value in values.items():
            if name in prog:
                prog[name].value = value
            elif strict:
                raise ResourceError(f"shader program has no active uniform '{name}'")

    @property
    def n_objects(self) -> int:
        return len(self._objects)

    def use(self) -> None:
        """Make this context current, so that the OpenGL calls that follow
        reach it and not another live context's objects of the same names (a
        no-op when it already is, and for an adopted context, which its window
        keeps current)."""
        global _CURRENT
        if not self._owns_ctx or self.ctx is None or (_CURRENT is not None and _CURRENT() is self):
            return
        try:
            self.ctx.__enter__()
        except Exception:  # a context that cannot be made current here: left as it is
            return
        _CURRENT = weakref.ref(self)

    def release(self) -> None:
        """Release every tracked object, every program, then the context, with
        this context current (a release while another was current deleted
        that one's objects of the same names); the context current before is
        current again after."""
        if self.ctx is None:
            return
        previous = _CURRENT() if _CURRENT is not None else None
        self.use()
        for obj in reversed(self._objects):
            try:
                obj.release()
            except Exception:  # already released by its owner
                pass
        self._objects.clear()
        for prog in self._programs.values():
            prog.release()
        self._programs.clear()
        if self._owns_ctx:
            self.ctx.release()  # leaves no context current
            self.ctx = None
            _current_again(None if previous is self else previous)
        elif previous is not None and previous is not self:
            previous.use()
        self.ctx = None
        if self._loader is not None:
            self._loader.release()
            self._loader = None

    def __enter__(self) -> GLContext:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __del__(self) -> None:  # last resort; release() is the contract
        try:
            self.release()
        except Exception:
            pass
