"""Errors aniso3d raises for bad input: each says what was wrong and what to do."""

from __future__ import annotations


class Aniso3DError(Exception):
    """Base class of every error aniso3d raises on purpose.

    The CLI prints the message of these (and only these) without a traceback and
    exits with status 2.
    """


class InputError(Aniso3DError, ValueError):
    """A file, an array or an option given by the user cannot be used."""


class FormatError(InputError):
    """A file is not an aniso3d file, is damaged, or has an unsupported version."""


class ResourceError(Aniso3DError, RuntimeError):
    """The machine cannot do what was asked (no OpenGL, not enough memory)."""


class InputWarning(UserWarning):
    """A file was read, but not all of it: a material library or texture it
    names could not be found or decoded. The CLI prints these as one line."""
