"""The one interface of the three renderers: upload once, draw many frames.

A renderer (:class:`~aniso3d.rendering.polygon.MeshRenderer`,
:class:`~aniso3d.rendering.volume.VolumeRenderer`,
:class:`~aniso3d.rendering.splat.SplatRenderer`) is handed a
:class:`~aniso3d.rendering.context.GLContext` and

- ``upload(data)`` puts what it draws on the GPU once and returns a handle
  (:class:`Uploaded`: at least its world ``bounds`` and ``nbytes``);
- ``draw(handle, view, fbo, options)`` draws one frame of it into the bound
  framebuffer and returns :class:`~aniso3d.rendering.frame.DrawStats`;
- ``release(handle)`` frees an upload, ``release_all()`` the renderer's own
  GPU objects.

Each renderer declares its draw options as a frozen dataclass, its
``Options`` (a :class:`DrawOptions`), validated on construction. Front ends
build those (or read their fields, :meth:`DrawOptions.names`) instead of
inspecting method signatures; ``draw`` also takes the same options as
keywords, parsed by :meth:`DrawOptions.parse`.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import MISSING, dataclass, fields
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np

from aniso3d.errors import InputError
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import DrawStats, FrameView

O = TypeVar("O", bound="DrawOptions")  # noqa: E741


@dataclass(frozen=True)
class DrawOptions:
    """Base of the renderers' draw options. Subclasses are frozen dataclasses
    that check their fields in ``__post_init__`` and raise one
    :class:`~aniso3d.errors.InputError` naming the bad value."""

    #: What the options are called in messages ("splat", "volume", "mesh").
    what: ClassVar[str] = "draw"

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The option names, in declaration order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def parse(cls: type[O], **values: Any) -> O:
        """Options from keyword values; an unknown name is an InputError that
        lists the known ones."""
        unknown_names(values, cls.names(), cls.what)
        return cls(**values)

    @classmethod
    def resolve(cls: type[O], options: DrawOptions | None, values: dict[str, Any]) -> O:
        """``options`` if given (of this class), else :meth:`parse` of ``values``;
        not both."""
        if options is None:
            return cls.parse(**values)
        if values:
            raise InputError(
                f"pass {cls.what} options either as {cls.__name__} or as keywords, not both "
                f"(got {cls.__name__} and {sorted(values)})"
            )
        if not isinstance(options, cls):
            raise InputError(f"the {cls.what} renderer takes {cls.__name__}, got {type(options).__name__}")
        return options


def option_parser(cls: type[O]):
    """:meth:`DrawOptions.parse` of ``cls`` as a static method whose signature
    lists the fields of ``cls`` (keyword-only), so ``help()`` shows the
    options. A renderer sets ``options = option_parser(Options)``."""

    def options(**values: Any) -> O:
        return cls.parse(**values)

    params = []
    for f in fields(cls):
        default = f.default if f.default is not MISSING else inspect.Parameter.empty
        params.append(inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=default,
                                        annotation=f.type))  # fmt: skip
    options.__signature__ = inspect.Signature(params, return_annotation=cls.__name__)  # type: ignore[attr-defined]
    options.__doc__ = f"Validated {cls.what} options: :class:`{cls.__name__}` from keywords."
    return staticmethod(options)


def unknown_names(values: dict[str, Any], known: tuple[str, ...], what: str) -> None:
    """An InputError naming the keys of ``values`` not in ``known``, and the known ones."""
    unknown = set(values) - set(known)
    if unknown:
        raise InputError(f"unknown {what} option(s) {sorted(unknown)}; known: {', '.join(known) or 'none'}")


def choice(value: Any, choices: tuple[str, ...], what: str) -> str:
    """``value`` if it is one of ``choices``, else an InputError naming both."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")
    return value


def number(value: Any, what: str, minimum: float, strict: bool) -> float:
    """``value`` as a finite float ``>= minimum`` (``> minimum`` when ``strict``),
    else an InputError naming ``what`` and the value."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{what} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value < minimum or (strict and value == minimum):
        bound = f"{'>' if strict else '>='} {minimum:g}"
        raise InputError(f"{what} must be a finite number {bound}, got {value!r}")
    return value


class Uploaded(Protocol):
    """What ``upload`` returns: opaque to callers but for these two."""

    #: (2, 3) float64 world box of what was uploaded (the clip range is made from it).
    bounds: np.ndarray

    @property
    def nbytes(self) -> int:
        """Bytes uploaded to the GPU."""
        ...


@runtime_checkable
class MethodRenderer(Protocol):
    """One way of drawing (see the module docstring)."""

    #: "mesh", "volume" or "splat".
    method: ClassVar[str]
    #: The draw options dataclass.
    Options: ClassVar[type[DrawOptions]]

    def __init__(self, gl: GLContext) -> None: ...

    def upload(self, data: Any) -> Uploaded:
        """Put ``data`` on the GPU once."""
        ...

    def draw(
        self, handle: Any, view: FrameView, fbo: Any = None, options: DrawOptions | None = None,
        **values: Any,
    ) -> DrawStats:  # fmt: skip
        """Draw one frame of ``handle`` into ``fbo`` (bound, cleared to the
        background with alpha 0, viewport covering it)."""
        ...

    def release(self, handle: Any) -> None:
        """Free one upload."""
        ...

    def release_all(self) -> None:
        """Free the renderer's own GPU objects (uploads are freed with ``release``)."""
        ...
